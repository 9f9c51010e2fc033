"""``dam`` and ``cohen-massaro`` served over ``/v1/stream``: a real server on loopback, the
real client, frames equal to the offline synthesis of the rung the server reports."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from lipstream.config import ServerSettings
from lipstream.server.catalog import Catalog
from lipstream_client import End, PhonemeItem, Phonemes, Ready, Start
from tests.helpers import return_frames
from tests.lipstream.server.harness import Served, client, frame_rows, serving

SPANS = [("sil", 0.0, 0.05), ("HH", 0.05, 0.12), ("AY1", 0.12, 0.31), ("M", 0.31, 0.4)]


@pytest.fixture(scope="module")
def served(all_models_dir: Path) -> Iterator[Served]:
    with serving(all_models_dir, ServerSettings()) as running:
        yield running


@pytest.mark.parametrize("engine", ["dam", "cohen-massaro"])
@pytest.mark.parametrize("emotion", [None, "happy"])
def test_streamed_frames_are_the_offline_frames_of_the_reported_rung(
    served: Served, catalog: Catalog, engine: str, emotion: str | None
) -> None:
    start = Start("r", engine, "demo", fps=60.0, emotion=emotion)
    with client(served.ws, "json") as ws:
        ws.send(start, *(Phonemes("r", (PhonemeItem(*span),)) for span in SPANS), End("r"))
        messages = ws.until_done("r")
    ready = messages[0]
    assert isinstance(ready, Ready)
    model = catalog.model(engine, "demo")
    rung = next(r for r in model.fidelity_ladder() if r.name == ready.fidelity)
    rows = frame_rows([m for m in messages if getattr(m, "id", None) == "r"])
    assert sorted(rows) == list(range(int(0.4 * 60) + 1 + return_frames(60.0)))
    streamed = np.array([rows[i] for i in range(int(0.4 * 60) + 1)], dtype=np.float32)
    offline = model.synthesize(SPANS, fps=60.0, emotion=emotion, **rung.options).frames
    assert streamed.tobytes() == offline.tobytes()
