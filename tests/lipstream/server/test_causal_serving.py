"""The causal floor and the default emotion, on a real catalog and over a live server."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from lipstream.config import ServerSettings
from lipstream.engines.base import Model, frame_count
from lipstream.server.budget import choose_rung
from lipstream.server.catalog import Catalog
from lipstream.timeline import PhonemeSpan
from lipstream_client import End, Frames, Message, PhonemeItem, Phonemes, Ready, Start
from tests.helpers import return_frames
from tests.lipstream.server.harness import (
    FIXED_COMPUTE_MS,
    Served,
    client,
    frame_rows,
    serving,
)

ENGINES = ("viseme-lerp", "anime-graph")
SPANS = [
    ("sil", 0.0, 0.05),
    ("B", 0.05, 0.11),
    ("AA1", 0.11, 0.3),
    ("M", 0.3, 0.38),
    ("sil", 0.38, 0.5),
]
ITEMS = tuple(PhonemeItem(label, start, end) for label, start, end in SPANS)


MARGIN_MS = ServerSettings().compute_margin_ms


@pytest.fixture(scope="module")
def catalog(fixed_cost_catalog: Catalog) -> Catalog:
    return fixed_cost_catalog


@pytest.fixture(scope="module")
def served(all_models_dir: Path) -> Iterator[Served]:
    with serving(all_models_dir, ServerSettings()) as running:  # at the fixed calibration
        yield running


@pytest.fixture(scope="module")
def happy_presets(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("presets") / "profiles.json"
    path.write_text(json.dumps({"demo": {"default_emotion": "happy"}}), encoding="utf-8")
    return path


@pytest.mark.parametrize("engine", ENGINES)
def test_a_20_ms_budget_is_met_by_every_engine_without_waiting_for_a_phoneme(
    catalog: Catalog, engine: str
) -> None:
    ladder = catalog.ladder(catalog.model(engine, "demo"))
    assert [rung.compute_ms for rung in ladder] == [FIXED_COMPUTE_MS + MARGIN_MS] * len(ladder)
    chosen = choose_rung(ladder, 20.0)
    assert chosen in ladder[-2:] and chosen.rung.lookahead.phonemes == 0
    assert chosen.worst_case_ms <= 20.0
    # The floor, when only it fits: no lookahead at all.
    floor = choose_rung(ladder, ladder[-1].worst_case_ms)
    assert ladder[-2].worst_case_ms > floor.worst_case_ms
    assert (floor.rung.name, floor.lookahead_ms) == ("causal", 0.0)


@pytest.mark.parametrize("engine", ENGINES)
def test_a_budget_between_the_floor_and_the_best_rung_buys_the_lead_rung(
    catalog: Catalog, engine: str
) -> None:
    ladder = catalog.ladder(catalog.model(engine, "demo"))
    lead = ladder[-2]
    assert lead.rung.name.endswith("_lead") and 0.0 < lead.lookahead_ms <= 120.0
    # 150 ms is above the lead rung's wait plus compute and below every rung above it.
    assert lead.worst_case_ms <= 150.0 < ladder[-3].worst_case_ms
    assert choose_rung(ladder, 150.0) is lead
    assert choose_rung(ladder, lead.worst_case_ms - 0.01).rung.name == "causal"


# viseme-lerp's lead rung waits its filter's lag (about 20 ms) plus the 5 ms margin, so 20 ms
# gets its causal rung; anime-graph's lead rung waits about 7 ms plus the margin, so 10 ms.
CAUSAL_BUDGET_MS = {"viseme-lerp": 20, "anime-graph": 10}


@pytest.mark.parametrize("engine", ENGINES)
def test_ready_reports_the_causal_rung_and_every_frame_arrives_as_its_span_does(
    served: Served, engine: str, trained_models: dict[str, Model]
) -> None:
    with client(served.ws, "json") as ws:
        ws.send(Start("r", engine, "demo", fps=60, latency_budget_ms=CAUSAL_BUDGET_MS[engine]))
        ready = ws.recv()
        assert isinstance(ready, Ready)
        assert (ready.fidelity, ready.lookahead_ms) == ("causal", 0.0)
        received: list[Message] = []
        for item in ITEMS:
            ws.send(Phonemes("r", (item,)))
            # The frames up to the span's end come before anything waits for more input.
            while len(frame_rows(received)) < frame_count(item.end, 60.0):
                message = ws.recv()
                assert isinstance(message, Frames), message
                received.append(message)
        ws.send(End("r"))
        received.extend(ws.until_done("r"))
    rows = frame_rows(received)
    spoken = frame_count(SPANS[-1][2], 60.0)
    assert sorted(rows) == list(range(spoken + return_frames(60.0)))
    spans = [PhonemeSpan(label.rstrip("1"), start, end) for label, start, end in SPANS]
    model = trained_models[engine]
    options = dict(ready.options)
    expected = model.synthesize(spans, fps=60, audio=None, emotion="neutral", **options).frames
    np.testing.assert_allclose([rows[i] for i in range(spoken)], expected, atol=1e-6)


def test_anime_graphs_20_ms_budget_gets_its_lead_rung_and_a_causal_option_reports_custom(
    served: Served,
) -> None:
    with client(served.ws, "json") as ws:
        ws.send(Start("a", "anime-graph", "demo", fps=60, latency_budget_ms=20), End("a"))
        budgeted = ws.recv()
        ws.until_done("a")
        ws.send(Start("b", "anime-graph", "demo", fps=60, options={"causal": True}), End("b"))
        chosen = ws.recv()
        ws.until_done("b")
    assert isinstance(budgeted, Ready) and budgeted.fidelity == "causal_lead"
    assert 0.0 < budgeted.lookahead_ms < 20.0
    # Without a budget the client's options win; they select the causal search, not the
    # best rung, so ready says so and reports their own lookahead.
    assert isinstance(chosen, Ready) and (chosen.fidelity, chosen.lookahead_ms) == ("custom", 0.0)


def test_a_request_without_emotion_gets_neutral(served: Served) -> None:
    with client(served.ws, "json") as ws:
        ws.send(Start("r", "anime-graph", "demo", fps=30), End("r"))
        ready = ws.recv()
        ws.until_done("r")
    assert isinstance(ready, Ready) and ready.emotion == "neutral"


def test_a_preset_default_emotion_is_used_and_a_stated_one_wins(
    all_models_dir: Path, happy_presets: Path
) -> None:
    with serving(all_models_dir, ServerSettings(profiles=happy_presets)) as running:
        with client(running.ws, "json") as ws:
            ws.send(Start("a", "anime-graph", "demo", fps=30), End("a"))
            unnamed = ws.recv()
            ws.until_done("a")
            ws.send(Start("b", "anime-graph", "demo", fps=30, emotion="sad"), End("b"))
            stated = ws.recv()
            ws.until_done("b")
    assert isinstance(unnamed, Ready) and unnamed.emotion == "happy"
    assert isinstance(stated, Ready) and stated.emotion == "sad"


def test_the_default_emotion_searches_only_that_emotions_recordings(
    trained_models: dict[str, Model],
) -> None:
    model = trained_models["anime-graph"]
    spans = [PhonemeSpan(label.rstrip("1"), start, end) for label, start, end in SPANS]
    synthesizer = model.start(fps=60)
    synthesizer.feed(spans)
    synthesizer.finish()
    assert synthesizer.stats["view"] == "neutral"
    np.testing.assert_array_equal(
        model.synthesize(spans, fps=60).frames,
        model.synthesize(spans, fps=60, emotion="neutral").frames,
    )


def test_a_budget_that_takes_a_causal_rung_overrides_a_clients_tile_cap(served: Served) -> None:
    with client(served.ws, "json") as ws:
        ws.send(
            Start(
                "r", "anime-graph", "demo", fps=60, latency_budget_ms=150, options={"max_tile": 4}
            ),
            Phonemes("r", ITEMS),
            End("r"),
        )
        ready = ws.recv()
        messages = ws.until_done("r")
    assert isinstance(ready, Ready) and ready.fidelity == "causal_lead"
    assert 0.0 < ready.lookahead_ms <= 120.0
    assert dict(ready.options) == {
        "max_tile": 1,
        "search": "greedy",
        "causal": True,
        "lead_ms": 120.0,
    }
    assert len(frame_rows(messages)) == frame_count(SPANS[-1][2], 60.0) + return_frames(60.0)
