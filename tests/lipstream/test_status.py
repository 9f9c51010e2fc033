"""Status lines: ``phase`` and the ``Heartbeat`` that fills silences, on an injected clock."""

from __future__ import annotations

import io

from lipstream.status import Heartbeat, TouchingStream, phase


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_phase_reports_the_step_and_its_duration() -> None:
    lines: list[str] = []
    with phase("training dam", lines.append):
        pass
    assert lines[0] == "training dam ..."
    assert lines[1].startswith("training dam: done in ") and lines[1].endswith(" s")


def test_the_heartbeat_repeats_the_open_step_every_interval_of_silence() -> None:
    clock, lines = Clock(), []
    heartbeat = Heartbeat(lines.append, interval_s=2.0, clock=clock)
    assert not heartbeat.beat()  # no step open
    heartbeat.report("training dam ...")
    clock.now += 1.9
    assert not heartbeat.beat()  # 1.9 s since the last line
    clock.now += 0.1
    assert heartbeat.beat()
    assert lines[-1] == "training dam ...: 2 s"
    clock.now += 1.0
    assert not heartbeat.beat()  # the beat itself was output
    clock.now += 1.0
    assert heartbeat.beat() and lines[-1] == "training dam ...: 4 s"
    heartbeat.report("training dam: done in 4.0 s")
    clock.now += 10.0
    assert not heartbeat.beat()  # nothing open any more
    assert len(lines) == 4


def test_every_open_step_is_named_and_output_elsewhere_keeps_it_quiet() -> None:
    clock, lines = Clock(), []
    heartbeat = Heartbeat(lines.append, interval_s=2.0, clock=clock)
    heartbeat.report("training 2 engines ...")
    heartbeat.report("training dam ...")
    clock.now += 1.0
    heartbeat.report("training hmm ...")
    stream = io.StringIO()
    bar = TouchingStream(stream, heartbeat.touch)
    clock.now += 1.5
    bar.write("\rhmm: 50%")  # a progress bar drawing counts as output
    clock.now += 1.5
    assert not heartbeat.beat()
    clock.now += 0.5
    assert heartbeat.beat()
    assert lines[-1] == (
        "training 2 engines ...: 5 s; training dam ...: 5 s; training hmm ...: 4 s"
    )
    assert stream.getvalue() == "\rhmm: 50%"


def test_the_heartbeat_thread_beats_until_stopped() -> None:
    clock, lines = Clock(), []
    heartbeat = Heartbeat(lines.append, interval_s=0.01, clock=clock)
    heartbeat.report("calibrating hmm ...")
    clock.now += 3.0
    heartbeat.start()
    while len(lines) < 2:
        pass
    heartbeat.stop()
    assert lines[1] == "calibrating hmm ...: 3 s"
    count = len(lines)
    clock.now += 3.0
    assert heartbeat._thread is not None and not heartbeat._thread.is_alive()
    assert len(lines) == count
