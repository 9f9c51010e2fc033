"""A server started in the background listens before its models are ready.

The start-up's ``prepare`` step (where ``lipstream serve`` builds the demo) is held on an
event, so the test sees the server in the phase ``building`` for as long as it needs, then
lets it go and sees it turn ready; a start-up that fails reports ``failed`` and calls
``on_failure``. A real uvicorn server on loopback, the real WebSocket client.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx

from lipstream.config import ServerSettings
from lipstream.corpus import Corpus
from lipstream.corpus.writer import write_corpus
from lipstream.engines import engine_names
from lipstream.errors import LipstreamError
from lipstream.server.app import create_app
from lipstream.status import Report
from lipstream.training import train_in_parallel, training_pool
from lipstream_client import ErrorMessage
from tests.helpers import eventually, return_frames
from tests.lipstream.server.harness import client, serving
from tests.live_server import READY_POLLS

WAIT_S = 120.0
BODY = {
    "engine": "viseme-lerp",
    "character": "demo",
    "fps": 50,
    "items": [{"phoneme": "HH", "start": 0.0, "end": 0.1}],
}


@contextmanager
def starting(
    models: Path, prepare: Callable[[Report], None], on_failure: Callable[[], None]
) -> Iterator[str]:
    """Serve ``models`` with a background start-up that runs ``prepare`` first."""
    settings = ServerSettings(log_level="warning")
    app = create_app(models, settings, prepare=prepare, background=True, on_failure=on_failure)
    with serving(models, settings, app) as served:
        yield served.http.removeprefix("http://")


def test_a_starting_server_answers_health_names_its_phase_and_refuses_synthesis(
    lerp_dir: Path,
) -> None:
    entered, release = threading.Event(), threading.Event()

    def prepare(report: Report) -> None:
        report("building the test character ...")
        entered.set()
        release.wait(WAIT_S)

    failures: list[int] = []
    with starting(lerp_dir, prepare, lambda: failures.append(1)) as address:
        base = f"http://{address}"
        assert entered.wait(WAIT_S)
        health = httpx.get(f"{base}/healthz")
        assert (health.status_code, health.json()) == (200, {"status": "ok"})
        ready = httpx.get(f"{base}/readyz")
        assert ready.status_code == 503
        assert ready.json()["ready"] is False
        assert ready.json()["phase"] == "building"
        assert ready.json()["status"] == "building the test character ..."

        refused = httpx.post(f"{base}/v1/synthesize", json=BODY)
        assert refused.status_code == 503 and refused.headers["retry-after"] == "2"
        assert refused.json()["error"]["code"] == "starting"
        assert refused.json()["error"]["details"] == {"phase": "building"}
        characters = httpx.get(f"{base}/v1/characters")
        assert (characters.status_code, characters.json()["error"]["code"]) == (503, "starting")

        with client(f"ws://{address}/v1/stream", "json") as connection:
            messages, code, reason = connection.closed()
        [error] = messages
        assert isinstance(error, ErrorMessage)
        assert (error.code, error.fatal, error.details) == ("starting", True, {"phase": "building"})
        assert (code, reason) == (1013, "starting")

        release.set()
        eventually(lambda: httpx.get(f"{base}/readyz").status_code == 200, "ready", READY_POLLS)
        assert httpx.get(f"{base}/readyz").json() == {
            "ready": True,
            "phase": "ready",
            "failed_models": [],
        }
        answer = httpx.post(f"{base}/v1/synthesize", json=BODY)
        assert answer.status_code == 200 and answer.json()["n_frames"] == 6 + return_frames(
            50
        )  # frames 0..5 of 0.1 s at 50 fps
    assert failures == []


def test_a_failed_start_up_says_why_and_calls_on_failure(lerp_dir: Path) -> None:
    def prepare(report: Report) -> None:
        raise LipstreamError("no espeak-ng", where="demo", code="speech_failed")

    failed = threading.Event()
    with starting(lerp_dir, prepare, failed.set) as address:
        assert failed.wait(WAIT_S)
        answer = httpx.get(f"http://{address}/readyz")
        assert answer.status_code == 503
        assert answer.json()["phase"] == "failed"
        assert answer.json()["status"] == "error [speech_failed]: demo: no espeak-ng"
        assert httpx.get(f"http://{address}/healthz").status_code == 200


def test_a_server_training_its_engines_answers_health_then_serves_every_engine(
    small_demo_corpus: Corpus, tmp_path: Path
) -> None:
    """The real parallel training (``train_in_parallel``, two processes) as the start-up's
    ``prepare``; its report holds at the first engine done, so the probes see the phase
    ``building`` while training is under way."""
    models, corpus_dir = tmp_path / "models", tmp_path / "corpus"
    write_corpus(small_demo_corpus, corpus_dir)
    at_first_done, release = threading.Event(), threading.Event()

    def prepare(report: Report) -> None:
        def holding(line: str) -> None:
            report(line)
            if ": done in " in line and not at_first_done.is_set():
                at_first_done.set()
                release.wait(WAIT_S)

        with training_pool(2) as pool:
            train_in_parallel(pool, 2, corpus_dir, engine_names(), models, holding)

    failures: list[int] = []
    with starting(models, prepare, lambda: failures.append(1)) as address:
        base = f"http://{address}"
        assert at_first_done.wait(WAIT_S * 5)
        health = httpx.get(f"{base}/healthz")
        assert (health.status_code, health.json()) == (200, {"status": "ok"})
        ready = httpx.get(f"{base}/readyz")
        assert (ready.status_code, ready.json()["phase"]) == (503, "building")
        assert ready.json()["status"].startswith("training ")
        assert " and compiling its kernels: done in " in ready.json()["status"]
        release.set()
        eventually(lambda: httpx.get(f"{base}/readyz").status_code == 200, "ready", READY_POLLS)
        listed = httpx.get(f"{base}/v1/engines").json()["engines"]
        assert {row["name"] for row in listed if row["loaded"]} == set(engine_names())
        for engine in engine_names():
            body = dict(BODY, engine=engine)
            answer = httpx.post(f"{base}/v1/synthesize", json=body, timeout=WAIT_S)
            assert answer.status_code == 200, (engine, answer.text)
            assert answer.json()["n_frames"] == 6 + return_frames(50)
    assert failures == []
