"""Long engine work against a real server: it never holds the event loop, it stops when its
request is cancelled, its connection closes or its CPU budget is spent, and a connection doing
it keeps reading (pings, cancel).

PQ-Matching with a 6-phoneme window over one phoneme repeated is the long work: on the test
model it searches for more than 20 s, far beyond every budget set here, so each request below
is ended by the mechanism under test, never by finishing.
"""

from __future__ import annotations

import functools
import re
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from contextlib import ExitStack
from pathlib import Path

import httpx
import pytest

from lipstream.config import ServerSettings
from lipstream.engines.base import Model
from lipstream.server.lanes import FairLane
from lipstream_client import (
    Cancel,
    Done,
    End,
    ErrorMessage,
    Frames,
    Message,
    PhonemeItem,
    Phonemes,
    Ready,
    Start,
    Text,
)
from lipstream_client.messages import JsonValue
from tests.helpers import eventually, return_frames
from tests.lipstream.server.harness import Client, Served, client, serving
from tests.live_server import save_models

ANSWER_BOUND_S = 5.0  # whether the server answers at all, not how fast
WORK_BOUND_S = 60.0  # a budget of CPU seconds takes longer on a busy machine
# The whole corpus: a request naming no emotion searches only its default emotion's recordings.
PQ: dict[str, JsonValue] = {"search": "pq", "pq_window": 6, "match_emotion": False}
PQ_PHONEMES = 42  # 6 × 42 = 252, within the cap of 256
SEARCHES = 5
FLOOD = 8
ITEMS = tuple(PhonemeItem("AA1", 0.08 * i, 0.08 * (i + 1)) for i in range(PQ_PHONEMES))
REST_BODY = {
    "engine": "viseme-lerp",
    "character": "demo",
    "fps": 50,
    "items": [
        {"phoneme": "HH", "start": 0.0, "end": 0.1},
        {"phoneme": "AY1", "start": 0.1, "end": 0.3},
    ],
}
SHORT = tuple(
    PhonemeItem(label, 0.1 * i, 0.1 * (i + 1)) for i, label in enumerate("M AA1 sil".split())
)


def final(ws: Client, identifier: str) -> list[Message]:
    """Messages of ``identifier`` up to its done or fatal error, each within WORK_BOUND_S."""
    collected: list[Message] = []
    while True:
        message = ws.recv(timeout=WORK_BOUND_S)
        if getattr(message, "id", None) == identifier:
            collected.append(message)
            if isinstance(message, Done) or (isinstance(message, ErrorMessage) and message.fatal):
                return collected


def metric(served: Served, name: str) -> float:
    text = httpx.get(f"{served.http}/metrics", timeout=ANSWER_BOUND_S).text
    found = re.search(rf"^{name} ([0-9.e+]+)$", text, flags=re.MULTILINE)
    return float(found.group(1)) if found else 0.0


def short_request_completes(served: Served, identifier: str, options: dict[str, JsonValue]) -> None:
    """A short request on a new connection gets its done."""
    with client(served.ws) as ws:
        ws.send(Start(identifier, "anime-graph", "demo", options=options))
        ws.send(Phonemes(identifier, SHORT), End(identifier))
        answers = ws.until_done(identifier)
    assert isinstance(answers[0], Ready) and isinstance(answers[-1], Done)


def test_health_answers_while_pq_runs_and_the_cpu_budget_ends_it(all_models_dir: Path) -> None:
    settings = ServerSettings(request_cpu_s=1.0)
    outcome: list[Message] = []
    with serving(all_models_dir, settings) as served:

        def stream() -> None:
            with client(served.ws) as ws:
                ws.send(Start("pq", "anime-graph", "demo", options=PQ))
                for item in ITEMS:  # one phoneme per message, as a TTS sends them
                    ws.send(Phonemes("pq", (item,)))
                ws.send(End("pq"))
                outcome.extend(final(ws, "pq"))

        worker = threading.Thread(target=stream)
        worker.start()
        answers = 0
        with httpx.Client(timeout=ANSWER_BOUND_S) as http:
            while worker.is_alive():
                assert http.get(f"{served.http}/healthz").status_code == 200
                answers += 1
                time.sleep(0.05)
        worker.join()
    assert answers >= 1
    last = outcome[-1]
    assert isinstance(last, ErrorMessage)
    assert (last.code, last.id, last.fatal) == ("cpu_budget_exceeded", "pq", True)


def test_pq_beyond_its_cap_is_refused_and_rest_has_the_cpu_budget(all_models_dir: Path) -> None:
    with serving(all_models_dir, ServerSettings(request_cpu_s=1.0)) as served:
        with client(served.ws) as ws:
            ws.send(Start("big", "anime-graph", "demo", options=PQ))
            over = tuple(PhonemeItem("AA1", 0.08 * i, 0.08 * (i + 1)) for i in range(43))
            ws.send(Phonemes("big", over))
            error = ws.until_done("big")[-1]
            assert isinstance(error, ErrorMessage)
            assert (error.code, error.id, error.fatal) == ("search_too_large", "big", True)
            assert "256" in error.message
        body = {
            "engine": "anime-graph",
            "character": "demo",
            "options": PQ,
            "items": [{"phoneme": i.phoneme, "start": i.start, "end": i.end} for i in ITEMS],
        }
        answer = httpx.post(f"{served.http}/v1/synthesize", json=body, timeout=WORK_BOUND_S)
        assert answer.status_code == 422
        assert answer.json()["error"]["code"] == "cpu_budget_exceeded"


def test_cancel_stops_the_running_work_and_ends_the_request(all_models_dir: Path) -> None:
    settings = ServerSettings(request_cpu_s=600.0, synth_threads=1)
    with serving(all_models_dir, settings) as served:
        with client(served.ws) as ws:
            ws.send(Start("pq", "anime-graph", "demo", options=PQ))
            ws.send(Phonemes("pq", ITEMS))  # one long job in the pool
            ws.send(Cancel("pq"))
            answers = final(ws, "pq")
            done = answers[-1]
            # The connection handles messages in order, so the cancel's done comes only
            # after the job in the pool returned: stopped, not finished (600 s budget).
            assert isinstance(done, Done) and done.reason == "cancel"
            assert not any(isinstance(answer, Frames) for answer in answers)
            assert metric(served, "lipstream_work_stopped_total") == 1.0
        # The pool's only thread is free again.
        short_request_completes(served, "after", {"max_tile": 3})


def test_closing_the_connection_stops_its_work(all_models_dir: Path) -> None:
    settings = ServerSettings(request_cpu_s=600.0, synth_threads=1)
    with serving(all_models_dir, settings) as served:
        with client(served.ws) as ws:
            ws.send(Start("pq", "anime-graph", "demo", options=PQ))
            assert isinstance(ws.recv(), Ready)
            ws.send(Phonemes("pq", ITEMS))
        eventually(
            lambda: metric(served, "lipstream_work_stopped_total") == 1.0,
            "the closed connection's work stopped",
        )
        short_request_completes(served, "after", {"max_tile": 3})


def test_a_connection_doing_long_work_keeps_answering_pings(all_models_dir: Path) -> None:
    settings = ServerSettings(request_cpu_s=1.5, ping_interval_s=0.2, ping_timeout_s=1.0)
    with serving(all_models_dir, settings) as served:
        with client(served.ws) as ws:
            ws.send(Start("pq", "anime-graph", "demo", options=PQ))
            ws.send(Phonemes("pq", ITEMS))  # 1.5 s of CPU in the pool: many pings
            error = final(ws, "pq")[-1]
            assert isinstance(error, ErrorMessage) and error.code == "cpu_budget_exceeded"
            # Still the same connection: a next request is served on it.
            ws.send(Start("next", "anime-graph", "demo"))
            ws.send(Phonemes("next", SHORT), End("next"))
            assert isinstance(ws.until_done("next")[-1], Done)


def test_a_large_json_answer_does_not_stall_other_connections(all_models_dir: Path) -> None:
    """90 s at 1000 fps in JSON: about 2.5 million numbers to encode."""
    with serving(all_models_dir, ServerSettings()) as served:
        received: list[Message] = []
        stop = threading.Event()

        def large() -> None:
            with client(served.ws, "json") as ws:
                ws.send(Start("big", "viseme-lerp", "demo", fps=1000))
                ws.send(Phonemes("big", (PhonemeItem("AA1", 0.0, 90.0),)), End("big"))
                while not stop.is_set():
                    try:
                        received.append(ws.recv(timeout=0.2))
                    except TimeoutError:
                        continue

        worker = threading.Thread(target=large)
        worker.start()
        try:
            eventually(lambda: len(received) >= 1, "ready of the large request")
            time.sleep(0.5)  # its answer is being produced now
            with client(served.ws) as other:
                other.send(Start("small", "viseme-lerp", "demo"))
                other.send(Phonemes("small", SHORT), End("small"))
                answers = other.until_done("small")
            assert isinstance(answers[-1], Done)
            health = httpx.get(f"{served.http}/healthz", timeout=ANSWER_BOUND_S)
            assert health.status_code == 200
            # The large request was still being encoded: its done had not come.
            assert not any(isinstance(message, Done) for message in received)
        finally:
            stop.set()
            worker.join()


def test_ordinary_work_does_not_queue_behind_a_costly_request(all_models_dir: Path) -> None:
    # One thread in each pool, and every costed message off the loop: were there one pool,
    # the short request's work would wait behind the search (600 s of budget).
    settings = ServerSettings(
        request_cpu_s=600.0, synth_threads=1, heavy_threads=1, inline_work_ms=0.0
    )
    with serving(all_models_dir, settings) as served:
        with client(served.ws) as costly:
            costly.send(Start("pq", "anime-graph", "demo", options=PQ))
            assert isinstance(costly.recv(timeout=WORK_BOUND_S), Ready)
            before = _pool_threads()
            costly.send(Phonemes("pq", ITEMS))  # unbounded cost: the heavy lane
            # A pool starts its thread when its first job is submitted: the search runs.
            eventually(lambda: len(_pool_threads() - before) == 1, "the search in a pool")
            short_request_completes(served, "short", {})
            costly.send(Cancel("pq"))
            done = final(costly, "pq")[-1]
        # The search was still running when the short request finished: it was stopped.
        assert isinstance(done, Done) and done.reason == "cancel"
        assert metric(served, "lipstream_work_stopped_total") == 1.0


@pytest.fixture(scope="module")
def graph_and_lerp_dir(
    trained_models: dict[str, Model], tmp_path_factory: pytest.TempPathFactory
) -> Path:
    """The anime-graph (the search) and viseme-lerp (speech, REST) demo models."""
    return save_models(
        {name: trained_models[name] for name in ("anime-graph", "viseme-lerp")},
        tmp_path_factory.mktemp("graph-and-lerp"),
    )


def test_speech_and_rest_do_not_wait_behind_other_connections_searches(
    graph_and_lerp_dir: Path,
) -> None:
    # Five connections each queue a search in the heavy lane (one thread: one runs, four
    # wait, each ended only by its CPU budget or a cancel); a sixth connection's text
    # request and a REST call must be answered while all five are still there, with no job
    # run ahead of either. In one FIFO pool they waited behind every search (53.6 s), and
    # each search then ended on its CPU budget first.
    settings = ServerSettings(request_cpu_s=10.0, heavy_threads=1)
    with serving(graph_and_lerp_dir, settings) as served, ExitStack() as stack:
        costly = [stack.enter_context(client(served.ws)) for _ in range(SEARCHES)]
        for ws in costly:
            ws.send(Start("pq", "anime-graph", "demo", options=PQ))
            assert isinstance(ws.recv(timeout=WORK_BOUND_S), Ready)
        for ws in costly:
            ws.send(Phonemes("pq", ITEMS))
        eventually(
            lambda: (
                labelled_metric(served, "lipstream_messages_received_total", 'type="phonemes"')
                == SEARCHES
            ),
            "the searches handed to the heavy lane",
        )
        with client(served.ws) as other:
            other.send(Start("t", "viseme-lerp", "demo", fps=60.0))
            other.send(Text("t", "Hello there."), End("t"))
            spoken = final(other, "t")
        answer = httpx.post(f"{served.http}/v1/synthesize", json=REST_BODY, timeout=WORK_BOUND_S)
        for ws in costly:
            ws.send(Cancel("pq"))
        ends = [final(ws, "pq")[-1] for ws in costly]
        speech_waits = {
            source: jobs_ahead(served, "speech", source, "0.0") for source in ("stream", "rest")
        }
    assert isinstance(spoken[-1], Done) and spoken[-1].reason == "end"
    assert any(isinstance(message, Frames) for message in spoken)
    assert answer.status_code == 200 and answer.json()["n_frames"] == 16 + return_frames(50)
    # No search had ended: each was stopped by its cancel, after both answers.
    assert [(type(end), getattr(end, "reason", None)) for end in ends] == [(Done, "cancel")] * 5
    # (jobs, of them with no job started ahead): the text request and the REST call.
    assert speech_waits == {"stream": (1.0, 1.0), "rest": (1.0, 1.0)}


def test_a_flood_of_rest_calls_delays_a_text_request_by_one_call(
    graph_and_lerp_dir: Path,
) -> None:
    # The speech lane's one thread is held while one REST client queues FLOOD calls and then
    # a WebSocket connection its text request: taking turns, the text request starts after
    # one call of the flood (first come, first served: after all of them).
    settings = ServerSettings(speech_threads=1)
    with serving(graph_and_lerp_dir, settings) as served, ThreadPoolExecutor(FLOOD) as callers:
        lane: FairLane = served.state.speech
        gate, started = threading.Event(), threading.Event()
        try:
            holder = lane.submit_as(("test",), held, gate, started)
            assert started.wait(WORK_BOUND_S)
            post = functools.partial(
                httpx.post, f"{served.http}/v1/synthesize", json=REST_BODY, timeout=WORK_BOUND_S
            )
            calls = [callers.submit(post) for _ in range(FLOOD)]
            eventually(lambda: lane.queued == FLOOD, "the flood queued")
            with client(served.ws) as other:
                other.send(Start("t", "viseme-lerp", "demo", fps=60.0))
                other.send(Text("t", "Hello there."), End("t"))
                eventually(lambda: lane.queued == FLOOD + 1, "the text queued")
                gate.set()
                spoken = final(other, "t")
        finally:
            gate.set()
        assert holder.result(timeout=WORK_BOUND_S)
        answers = [call.result(timeout=WORK_BOUND_S) for call in calls]
        text_waits = jobs_ahead(served, "speech", "stream", "1.0")
        rest_waits = jobs_ahead(served, "speech", "rest", "0.0")
        rest_waits_below = jobs_ahead(served, "speech", "rest", f"{float(FLOOD - 1)}")
    assert isinstance(spoken[-1], Done) and spoken[-1].reason == "end"
    assert [answer.status_code for answer in answers] == [200] * FLOOD
    assert text_waits == (1.0, 1.0)  # one job, with at most one job started ahead of it
    # The flood's first call had none ahead (the held job had started); the rest one more
    # each, and one for the text request's turn: 0, 2, 3, ..., FLOOD.
    assert rest_waits == (FLOOD, 1.0)
    assert rest_waits_below == (FLOOD, FLOOD - 1)


def held(gate: threading.Event, started: threading.Event) -> bool:
    started.set()
    return gate.wait(WORK_BOUND_S)


def jobs_ahead(served: Served, lane: str, source: str, bound: str) -> tuple[float, float]:
    """(jobs of ``source`` started in ``lane``, of them with at most ``bound`` jobs started
    ahead of them): ``lipstream_lane_jobs_ahead``."""
    name = "lipstream_lane_jobs_ahead_bucket"
    return (
        labelled_metric(served, name, f'lane="{lane}",le="+Inf",source="{source}"'),
        labelled_metric(served, name, f'lane="{lane}",le="{bound}",source="{source}"'),
    )


def labelled_metric(served: Served, name: str, labels: str) -> float:
    text = httpx.get(f"{served.http}/metrics", timeout=ANSWER_BOUND_S).text
    found = re.search(rf"^{name}{{{re.escape(labels)}}} ([0-9.e+]+)$", text, flags=re.MULTILINE)
    return float(found.group(1)) if found else 0.0


def _pool_threads() -> set[int]:
    """The live threads of every server pool in this process (the test server runs here)."""
    return {t.ident or 0 for t in threading.enumerate() if t.name.startswith("lipstream-")}
