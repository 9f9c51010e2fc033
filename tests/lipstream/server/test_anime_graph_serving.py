"""The server with the real anime-graph model: its fidelity ladder under latency budgets, and
per-phoneme emotion carried from the wire to the engine."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lipstream.engines.anime_graph import AnimeGraphModel
from lipstream.engines.base import frames_before
from lipstream.server.catalog import Catalog
from lipstream_client import End, ErrorMessage, PhonemeItem, Phonemes, Ready, Start, decode, encode
from lipstream_client.messages import JsonValue
from tests.lipstream.server.test_session import frames_of, new_session, play, returning

ENGINE = "anime-graph"


@pytest.fixture(scope="module")
def catalog(fixed_cost_catalog: Catalog) -> Catalog:
    """Calibrated at a fixed cost: the rungs' order is their lookahead's, not a race between
    the lead rung's few milliseconds of wait and the causal rung's measured compute."""
    return fixed_cost_catalog


WORDS = [
    ("sil", 0.0, 0.12),
    ("HH", 0.12, 0.2),
    ("AH0", 0.2, 0.27),
    ("L", 0.27, 0.35),
    ("OW1", 0.35, 0.55),
    ("W", 0.55, 0.63),
    ("ER1", 0.63, 0.78),
    ("L", 0.78, 0.85),
    ("D", 0.85, 0.92),
    ("sil", 0.92, 1.1),
    ("M", 1.1, 1.2),
    ("AA1", 1.2, 1.45),
    ("M", 1.45, 1.55),
    ("sil", 1.55, 1.8),
]


def _demo(catalog: Catalog) -> AnimeGraphModel:
    model = catalog.model(ENGINE, "demo")
    assert isinstance(model, AnimeGraphModel)
    return model


def test_the_catalog_measures_every_rung_of_the_declared_ladder(catalog: Catalog) -> None:
    model = _demo(catalog)
    ladder = catalog.ladder(model)
    assert [estimate.rung for estimate in ladder] == list(model.fidelity_ladder())
    # Hand-computed in test_budget.DEMO_LOOKAHEAD_MS: 108.333 ms of grid sample and filter,
    # 32.5 ms of audio, max_tile phonemes of 200 ms; unsmoothed, 8.333 ms instead of 108.333;
    # the causal rungs wait their lead (the filter's lag, at most 120 ms) and no audio.
    waits = [estimate.lookahead_ms for estimate in ladder]
    assert waits[:5] + waits[6:] == pytest.approx(
        [2140.833, 940.833, 540.833, 340.833, 240.833, 0.0], abs=1e-3
    )
    assert 0.0 < waits[5] <= 120.0
    worst = [estimate.worst_case_ms for estimate in ladder]
    assert worst == sorted(worst, reverse=True) and len(set(worst)) == len(worst)


@pytest.mark.parametrize("lower", [1, 2, 3, 4])
def test_a_budget_between_two_rungs_gets_the_lower_one(catalog: Catalog, lower: int) -> None:
    model = _demo(catalog)
    ladder = catalog.ladder(model)
    if lower >= len(ladder):
        pytest.skip(f"the demo model's ladder has {len(ladder)} rungs")
    chosen = ladder[lower]
    budget = 0.5 * (ladder[lower - 1].worst_case_ms + chosen.worst_case_ms)
    session = new_session(catalog)
    out = play(
        session,
        Start(
            "a",
            ENGINE,
            "demo",
            fps=60,
            latency_budget_ms=budget,
            options={"max_tile": 50, "graph": "unclustered"},
        ),
        Phonemes("a", tuple(PhonemeItem(*word) for word in WORDS)),
        End("a"),
    )
    ready = out[0]
    assert isinstance(ready, Ready)
    assert (ready.fidelity, ready.lookahead_ms) == (chosen.rung.name, chosen.lookahead_ms)
    # The rung's options override the client's (max_tile), the client's others stay.
    assert ready.options == {"graph": "unclustered", **chosen.rung.options}
    expected = model.synthesize(WORDS, fps=60, audio=None, emotion=None, **ready.options).frames
    np.testing.assert_array_equal(frames_of(out)[: -returning(60)], expected)


def test_without_a_budget_the_top_rung_serves(catalog: Catalog) -> None:
    model = _demo(catalog)
    top = catalog.ladder(model)[0]
    [ready] = play(new_session(catalog), Start("a", ENGINE, "demo"))
    assert isinstance(ready, Ready)
    assert (ready.fidelity, ready.lookahead_ms) == (top.rung.name, top.lookahead_ms)
    assert ready.options == dict(top.rung.options)


# The demo model (120 fps, 0.1 s smoothing window: half-width 12 frames) waits 13 / 120 s
# = 108.333 ms for the next grid sample and the filter (1 / 120 s = 8.333 ms unsmoothed),
# 32.5 ms for the audio, and max_tile (or pq_window) phonemes of 200 ms.
@pytest.mark.parametrize(
    ("options", "lookahead_ms"),
    [
        ({"max_tile": 3}, 108.333 + 32.5 + 3 * 200.0),
        ({"search": "pq", "pq_window": 2, "pq_advance": 1, "smooth": False}, 8.333 + 32.5 + 400.0),
    ],
)
def test_options_that_leave_every_rung_are_served_as_custom_with_their_own_lookahead(
    catalog: Catalog, options: dict[str, JsonValue], lookahead_ms: float
) -> None:
    [ready] = play(new_session(catalog), Start("a", ENGINE, "demo", options=options))
    assert isinstance(ready, Ready) and ready.fidelity == "custom"
    assert ready.lookahead_ms == pytest.approx(lookahead_ms, abs=1e-3)


def test_an_uncapped_tile_may_wait_for_the_longest_request(catalog: Catalog) -> None:
    [ready] = play(new_session(catalog), Start("a", ENGINE, "demo", options={"max_tile": 0}))
    assert isinstance(ready, Ready) and ready.fidelity == "custom"
    # the default 10 000 phonemes a request of 200 ms each
    assert ready.lookahead_ms == 10_000 * 200.0


def test_a_client_repeating_the_top_rungs_options_gets_that_rung(catalog: Catalog) -> None:
    top = catalog.ladder(_demo(catalog))[0]
    [ready] = play(
        new_session(catalog),
        Start("a", ENGINE, "demo", options={**top.rung.options, "blend": True}),
    )
    assert isinstance(ready, Ready)
    assert (ready.fidelity, ready.lookahead_ms) == (top.rung.name, top.lookahead_ms)


def test_a_budget_below_the_lowest_rung_names_the_smallest_feasible_one(catalog: Catalog) -> None:
    model = _demo(catalog)
    lowest = catalog.ladder(model)[-1]
    smallest = math.ceil(lowest.worst_case_ms)
    session = new_session(catalog)
    [error] = play(session, Start("a", ENGINE, "demo", latency_budget_ms=smallest - 1.0))
    assert isinstance(error, ErrorMessage)
    assert (error.code, error.fatal, error.details) == (
        "budget_infeasible",
        True,
        {"min_budget_ms": smallest},
    )
    [ready] = play(session, Start("a", ENGINE, "demo", latency_budget_ms=float(smallest)))
    assert isinstance(ready, Ready) and ready.fidelity == lowest.rung.name


def test_each_phonemes_emotion_reaches_the_engine(catalog: Catalog) -> None:
    model = _demo(catalog)
    emotions = ["happy"] * 5 + [None] * 4 + ["sad"] * 5
    items = tuple(PhonemeItem(*word, emotion) for word, emotion in zip(WORDS, emotions))
    # Over the wire and back, in three messages, with the request's own emotion angry.
    messages = [
        decode(encode(Phonemes("a", items[low:high]), "msgpack"), "msgpack", sender="client")
        for low, high in [(0, 3), (3, 10), (10, 14)]
    ]
    out = play(
        new_session(catalog),
        Start("a", ENGINE, "demo", fps=50, emotion="angry"),
        *messages,
        End("a"),
    )
    spans = [(*word, emotion) for word, emotion in zip(WORDS, emotions)]
    expected = model.synthesize(spans, fps=50, emotion="angry").frames
    streamed = frames_of(out)[: -returning(50)]
    np.testing.assert_array_equal(streamed, expected)
    all_angry = model.synthesize(WORDS, fps=50, emotion="angry").frames
    assert not np.allclose(streamed, all_angry, atol=1e-3)
    # The middle phonemes name no emotion, so they are angry, like the request.
    views = model.start(fps=50, emotion="angry")
    views.feed(spans)
    assert [searcher.view.name for searcher in views.searchers] == ["happy"] * 5 + ["angry"] * 4 + [
        "sad"
    ] * 5


def test_the_emotion_of_each_phoneme_changes_the_frames_of_its_run_only(catalog: Catalog) -> None:
    model = _demo(catalog)
    first = len(WORDS) - 5
    spans = [(*word, "happy" if index >= first else None) for index, word in enumerate(WORDS)]
    out = play(
        new_session(catalog),
        Start("a", ENGINE, "demo", fps=60, emotion="sad"),
        Phonemes("a", tuple(PhonemeItem(*span) for span in spans)),
        End("a"),
    )
    assert not [message for message in out if isinstance(message, ErrorMessage)]
    mixed = frames_of(out)[: -returning(60)]
    # The sad run is what sad alone gives, up to its last fragment (which the join into the
    # happy run reshapes) less the smoothing and interpolation reach.
    sad_alone = model.synthesize(WORDS[:first], fps=60, emotion="sad").frames
    reach = (model.half_width + 1) / model.fps
    settled = frames_before(WORDS[first - 1][1] - reach, 60.0)
    assert settled > 20
    np.testing.assert_array_equal(mixed[:settled], sad_alone[:settled])
    all_sad = model.synthesize(WORDS, fps=60, emotion="sad").frames
    assert not np.allclose(
        mixed[frames_before(WORDS[first][2], 60.0) :],
        all_sad[frames_before(WORDS[first][2], 60.0) :],
        atol=1e-3,
    )
