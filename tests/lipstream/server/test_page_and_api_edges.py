"""What a new user meets first besides the face: the API document names each route in
words, ``/favicon.ico`` is served, and a text request's lag counts from when its speech
was ready, the synthesis time reported apart."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from lipstream.config import ServerSettings
from lipstream.models import ModelRegistry
from lipstream.server.app import create_app
from lipstream.server.catalog import Catalog
from lipstream.server.request import RequestLimits
from lipstream.server.session import Session, SessionLimits
from lipstream_client import Done, End, Frames, Start, Text

OPERATIONS = {
    ("/healthz", "get"): "healthz",
    ("/readyz", "get"): "readyz",
    ("/v1/engines", "get"): "list_engines",
    ("/v1/characters", "get"): "list_characters",
    ("/v1/languages", "get"): "list_languages",
    ("/v1/synthesize", "post"): "synthesize",
    ("/metrics", "get"): "metrics",
    ("/v1/characters/{character}/phoneme-maps", "get"): "list_phoneme_maps",
    ("/v1/characters/{character}/nodes/{node}", "get"): "get_motion_node",
    ("/v1/characters/{character}/phoneme-maps/utterance", "post"): "phoneme_map_utterance",
    ("/v1/characters/{character}/phoneme-maps/{phoneme}", "get"): "get_phoneme_map",
    ("/v1/characters/{character}/phoneme-maps/{phoneme}/pick", "post"): "pick_phoneme_map_point",
    (
        "/v1/characters/{character}/phoneme-maps/candidates",
        "post",
    ): "phoneme_constraint_candidates",
    ("/v1/characters/{character}/contamination", "get"): "get_contamination",
    ("/v1/characters/{character}/contamination", "post"): "change_contamination",
    ("/v1/recordings", "post"): "create_recording",
    ("/v1/recordings/{session}/takes/{index}", "put"): "upload_take",
    ("/v1/recordings/{session}/train", "post"): "train_recording",
    ("/v1/recordings/{session}", "get"): "get_recording",
}


def test_every_route_has_a_written_summary_and_operation_id(lerp_dir: Path) -> None:
    document = create_app(lerp_dir, ServerSettings()).openapi()
    operations = {
        (path, method): operation
        for path, item in document["paths"].items()
        for method, operation in item.items()
    }
    assert {key: op["operationId"] for key, op in operations.items()} == OPERATIONS
    for operation in operations.values():
        summary = operation["summary"]
        # FastAPI's generated summary is the handler's name in title case ("Synthesize Route").
        assert not summary.endswith("Route") and summary[0].isupper() and " " in summary, summary


def test_the_favicon_is_served(lerp_dir: Path) -> None:
    client = TestClient(create_app(lerp_dir, ServerSettings()))  # no lifespan: static only
    icon = client.get("/favicon.ico")
    assert icon.status_code == 200
    assert icon.headers["content-type"] == "image/svg+xml"
    assert icon.text.startswith("<svg") and len(icon.content) < 4096
    page = client.get("/")
    assert '<link rel="icon" href="/demo/favicon.svg"' in page.text
    assert client.get("/demo/favicon.svg").content == icon.content


class SteppingTimer:
    """A clock that advances ``step`` seconds at every reading after the first."""

    def __init__(self, step: float) -> None:
        self.step = step
        self.now = 0.0
        self.readings = 0

    def __call__(self) -> float:
        if self.readings:
            self.now += self.step
        self.readings += 1
        return self.now


@pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing")
def test_a_text_requests_lag_counts_from_when_its_speech_was_ready(lerp_dir: Path) -> None:
    catalog = Catalog.build(ModelRegistry.load(lerp_dir), ServerSettings())
    limits = SessionLimits(3, RequestLimits(2000, 100_000, 100.0))
    timer = SteppingTimer(0.3)  # espeak-ng takes 300 ms by this clock
    session = Session(catalog, limits, timer=timer)
    start = Start("a", "viseme-lerp", "demo", fps=60, latency_budget_ms=100)
    stamped = [item.stamp(0.0).message for item in session.handle(start, 0.0)]
    # The text arrives at 1.0 s; its frames leave at 1.35 s: 50 ms after the speech was ready.
    answers = session.handle(Text("a", "Hello there."), 1.0)
    stamped += [item.stamp(1.35).message for item in answers]
    stamped += [item.stamp(1.35).message for item in session.handle(End("a"), 1.35)]
    assert any(isinstance(message, Frames) for message in stamped)
    done = stamped[-1]
    assert isinstance(done, Done)
    assert done.stats.max_lag_ms == pytest.approx(50.0)
    assert done.stats.budget_met is True
    assert done.stats.speech_synthesis_ms == pytest.approx(300.0)
    assert done.stats.first_frame_latency_ms == pytest.approx(1350.0)
