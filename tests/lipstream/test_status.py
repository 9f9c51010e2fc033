"""Status lines: ``phase`` and the ``Heartbeat`` that fills silences, on an injected clock."""

from __future__ import annotations

import threading

from lipstream.status import HEARTBEAT_S, Heartbeat, phase


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
    clock = Clock()
    lines: list[str] = []
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


def test_every_open_step_is_named_with_its_whole_seconds() -> None:
    clock = Clock()
    lines: list[str] = []
    heartbeat = Heartbeat(lines.append, interval_s=2.0, clock=clock)
    heartbeat.report("training 2 engines ...")
    heartbeat.report("training dam ...")
    clock.now += 1.0
    heartbeat.report("training hmm ...")
    clock.now += 1.5
    heartbeat.report("training dam: done in 2.5 s (training 2.0 s, compiling 0.5 s)")
    clock.now += 1.5
    assert not heartbeat.beat()
    clock.now += 0.9
    assert heartbeat.beat()
    assert lines[-1] == "training 2 engines ...: 4 s; training hmm ...: 3 s"


def test_a_start_up_watched_second_by_second_never_waits_longer_than_the_interval() -> None:
    """A whole start-up replayed on the clock: steps open and close at the times a slow
    machine took (the long silences are the ones the issue measured: dam's 28 s of
    training, anime-graph's 27 s on one bar stage), and the thread's own check runs
    every 0.1 s of the clock; no two lines are further apart than the interval."""
    clock, stamped = Clock(), []
    heartbeat = Heartbeat(lambda line: stamped.append((clock.now, line)), clock=clock)
    script = [
        (0.0, "importing the server ..."),
        (9.0, "importing the server: done in 9.0 s"),
        (9.0, "training dam ..."),
        (37.0, "training dam: done in 28.0 s"),
        (37.0, "training anime-graph ..."),
        (64.0, "training anime-graph: done in 27.0 s"),
    ]
    began = clock.now
    for at, line in script:
        while clock.now < began + at:
            clock.now = round(clock.now + 0.1, 6)
            heartbeat.beat()
        heartbeat.report(line)
    times = [at for at, _line in stamped]
    gaps = [later - earlier for earlier, later in zip(times, times[1:], strict=False)]
    assert max(gaps) <= HEARTBEAT_S + 1e-9
    assert len(stamped) > len(script) + 64 / 2  # beats filled the silences
    assert ("training dam ...: 27 s") in [line for _at, line in stamped]


def test_the_heartbeat_thread_beats_until_stopped() -> None:
    clock = Clock()
    lines: list[str] = []
    beaten = threading.Event()

    def report(line: str) -> None:
        lines.append(line)
        if len(lines) >= 2:
            beaten.set()

    heartbeat = Heartbeat(report, interval_s=0.01, clock=clock)
    heartbeat.report("calibrating hmm ...")
    clock.now += 3.0
    heartbeat.start()
    assert beaten.wait(60)
    heartbeat.stop()
    assert lines[1] == "calibrating hmm ...: 3 s"
    count = len(lines)
    clock.now += 3.0
    assert heartbeat._thread is not None and not heartbeat._thread.is_alive()
    assert len(lines) == count


def test_the_thread_waits_for_the_next_due_beat_and_idles_with_no_step_open() -> None:
    clock = Clock()
    heartbeat = Heartbeat(lambda line: None, interval_s=2.0, clock=clock)
    heartbeat.report("training dam ...")
    clock.now += 0.5
    assert heartbeat.until_due() == 1.5
    clock.now += 5.0
    assert heartbeat.until_due() == 0.0  # overdue: beat now
    heartbeat.report("training dam: done in 5.5 s")
    clock.now += 100.0  # long silent, but nothing is under way
    assert heartbeat.until_due() == 2.0
