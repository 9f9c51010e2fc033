"""The engine contract, checked against every registered engine."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lipstream.corpus import Corpus
from lipstream.engines import engine_names, load_model
from lipstream.engines.base import (
    MAX_FPS,
    MIN_FPS,
    Model,
    SynthesisRequest,
    frame_count,
    frames_before,
)
from lipstream.errors import InvalidRequestError
from lipstream.timeline import PhonemeSpan

ENGINES = engine_names()


def _heldout_spans(corpus: Corpus) -> list[PhonemeSpan]:
    _, heldout = corpus.split()
    return heldout.utterances[0].phones


def _stream(model: Model, spans: list[PhonemeSpan], cuts: list[int], fps: float) -> np.ndarray:
    synthesizer = model.start(fps=fps)
    pieces = []
    bounds = [0, *sorted(set(cuts)), len(spans)]
    for first, stop in itertools.pairwise(bounds):
        synthesizer.feed(spans[first:stop])
        pieces.append(synthesizer.frames())
    pieces.append(synthesizer.finish())
    return np.concatenate(pieces)


@pytest.mark.parametrize("engine", ENGINES)
def test_output_shape_dtype_and_channels(
    engine: str, trained_models: dict[str, Model], small_demo_corpus: Corpus
) -> None:
    model = trained_models[engine]
    spans = _heldout_spans(small_demo_corpus)
    frames, channels, fps = model.synthesize(spans, fps=60)
    assert channels == small_demo_corpus.channels == model.channels
    assert fps == 60.0
    assert frames.dtype == np.float32
    assert frames.shape == (frame_count(spans[-1].end, 60.0), len(channels))
    assert np.all(np.isfinite(frames))


@pytest.mark.parametrize("engine", ENGINES)
def test_output_is_deterministic_and_survives_save_load(
    engine: str, trained_models: dict[str, Model], small_demo_corpus: Corpus, tmp_path: Path
) -> None:
    model = trained_models[engine]
    spans = _heldout_spans(small_demo_corpus)
    first = model.synthesize(spans, fps=50).frames
    assert np.array_equal(first, model.synthesize(spans, fps=50).frames)
    model.save(tmp_path / engine)
    reloaded = load_model(tmp_path / engine)
    assert type(reloaded) is type(model)
    assert np.array_equal(first, reloaded.synthesize(spans, fps=50).frames)


@pytest.mark.parametrize("engine", ENGINES)
@settings(max_examples=15, deadline=None)
@given(data=st.data())
def test_any_chunking_gives_the_offline_frames(
    engine: str, trained_models: dict[str, Model], small_demo_corpus: Corpus, data: st.DataObject
) -> None:
    model = trained_models[engine]
    spans = _heldout_spans(small_demo_corpus)
    fps = data.draw(st.sampled_from([24.0, 30.0, 60.0, 120.0]))
    cuts = data.draw(st.lists(st.integers(1, len(spans) - 1), max_size=8))
    offline = model.synthesize(spans, fps=fps).frames
    np.testing.assert_array_equal(_stream(model, spans, cuts, fps), offline)


@pytest.mark.parametrize("engine", ENGINES)
def test_frames_come_out_as_soon_as_the_lookahead_allows(
    engine: str, trained_models: dict[str, Model], small_demo_corpus: Corpus
) -> None:
    model = trained_models[engine]
    spans = _heldout_spans(small_demo_corpus)
    lookahead = model.lookahead
    synthesizer = model.start(fps=60)
    emitted = 0
    for index, span in enumerate(spans):
        synthesizer.feed([span])
        emitted += len(synthesizer.frames())
        back = index - lookahead.phonemes
        promised = spans[back].end - lookahead.seconds if back >= 0 else 0.0
        assert emitted >= frames_before(promised, 60.0), f"held back at span {index}"
    emitted += len(synthesizer.finish())
    assert emitted == frame_count(spans[-1].end, 60.0)
    assert len(synthesizer.finish()) == 0


@pytest.mark.parametrize("engine", ENGINES)
def test_fps_conversion_samples_the_same_motion(
    engine: str, trained_models: dict[str, Model], small_demo_corpus: Corpus
) -> None:
    model = trained_models[engine]
    spans = _heldout_spans(small_demo_corpus)
    fine = model.synthesize(spans, fps=120).frames
    for fps, step in [(60, 2), (30, 4), (24, 5)]:
        coarse = model.synthesize(spans, fps=fps).frames
        assert len(coarse) == frame_count(spans[-1].end, fps)
        if engine == "hmm":  # solves its trajectory at the lower rate: tests/.../hmm bound it
            continue
        np.testing.assert_allclose(coarse, fine[::step][: len(coarse)], atol=2e-3)


@pytest.mark.parametrize("engine", ENGINES)
def test_spans_as_tuples_or_mappings_are_equivalent(
    engine: str, trained_models: dict[str, Model], small_demo_corpus: Corpus
) -> None:
    model = trained_models[engine]
    spans = _heldout_spans(small_demo_corpus)
    vowels = {
        "AA",
        "AE",
        "AH",
        "AO",
        "AW",
        "AY",
        "EH",
        "ER",
        "EY",
        "IH",
        "IY",
        "OW",
        "OY",
        "UH",
        "UW",
    }
    as_tuples = [
        (s.phoneme.lower() + ("1" if s.phoneme in vowels else ""), s.start, s.end) for s in spans
    ]
    as_maps = [{"phoneme": s.phoneme, "start": s.start, "end": s.end} for s in spans]
    np.testing.assert_array_equal(
        model.synthesize(as_tuples).frames, model.synthesize(as_maps).frames
    )


@pytest.mark.parametrize("engine", ENGINES)
def test_unknown_options_get_one_coded_error_listing_the_known_ones(
    engine: str, trained_models: dict[str, Model], small_demo_corpus: Corpus
) -> None:
    model = trained_models[engine]
    spans = _heldout_spans(small_demo_corpus)
    for call in (
        lambda: model.start(fps=60, bogus=1, max_jumps=3),
        lambda: model.synthesize(spans, fps=60, bogus=1, max_jumps=3),
    ):
        with pytest.raises(InvalidRequestError) as caught:
            call()
        error = caught.value
        assert error.code == "invalid_request" and error.where == "options.bogus"
        assert f"unknown option(s) bogus, max_jumps for engine {engine}" in error.message
        known = ", ".join(model.option_names) or "none"
        assert error.message.endswith(f"known options: {known}")


def test_each_engine_declares_the_options_it_reads(trained_models: dict[str, Model]) -> None:
    assert trained_models["viseme-lerp"].option_names == ("mode", "lead_ms")
    assert set(trained_models["anime-graph"].option_names) == {
        "graph",
        "search",
        "pq_window",
        "pq_advance",
        "blend",
        "smooth",
        "match_emotion",
        "max_tile",
        "pq_budget_s",
        "causal",
        "lead_ms",
    }
    for name in ("dam", "cohen-massaro"):
        assert trained_models[name].option_names == (
            "search_ahead",
            "tail_ahead",
            "causal",
            "lead_ms",
        )
    anime = trained_models["anime-graph"]
    assert anime.start(fps=60, smooth=False, max_tile=4) is not None


@pytest.mark.parametrize("fps", [1e-308, 0.5, 0.999, 1000.5, float("nan"), float("inf"), True])
def test_a_request_outside_the_frame_rate_range_is_refused(fps: float) -> None:
    with pytest.raises(InvalidRequestError, match=r"fps must be in \[1, 1000\]") as raised:
        SynthesisRequest(fps=fps)
    assert raised.value.where == "fps"


@pytest.mark.parametrize("fps", [MIN_FPS, 1.5, MAX_FPS])
def test_the_frame_rate_range_is_closed(fps: float) -> None:
    assert SynthesisRequest(fps=fps).fps == fps


CAUSAL_AUDIO_S = 0.005


@pytest.mark.parametrize("engine", ENGINES)
def test_the_ladder_ends_in_a_causal_rung_and_waits_less_going_down(
    engine: str, trained_models: dict[str, Model]
) -> None:
    ladder = trained_models[engine].fidelity_ladder()
    floor = ladder[-1].lookahead
    assert floor.phonemes == 0 and floor.seconds == 0.0
    assert floor.audio_seconds <= CAUSAL_AUDIO_S
    # Just above it, a rung that waits a fixed time, a fraction of a phoneme.
    lead = ladder[-2].lookahead
    assert lead.phonemes == 0 and 0.0 < lead.seconds <= 0.12 and lead.audio_seconds == 0.0


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("fps", [30.0, 60.0, 100.0])
def test_a_causal_rung_never_holds_a_frame_back_and_streams_the_offline_frames(
    engine: str, fps: float, trained_models: dict[str, Model], small_demo_corpus: Corpus
) -> None:
    model = trained_models[engine]
    rung = model.fidelity_ladder()[-1]
    spans = _heldout_spans(small_demo_corpus)
    synthesizer = model.start(fps=fps, **rung.options)
    pieces = []
    for index, span in enumerate(spans):
        synthesizer.feed([span])
        pieces.append(synthesizer.frames())
        emitted = sum(len(piece) for piece in pieces)
        assert emitted == frame_count(span.end, fps), f"held back at span {index}"
    pieces.append(synthesizer.finish())
    assert len(pieces[-1]) == 0
    offline = model.synthesize(spans, fps=fps, **rung.options).frames
    np.testing.assert_array_equal(np.concatenate(pieces), offline)


@pytest.mark.parametrize("engine", ENGINES)
def test_a_lead_rung_emits_the_frame_at_t_once_the_input_covers_t_plus_the_lead(
    engine: str, trained_models: dict[str, Model], small_demo_corpus: Corpus
) -> None:
    model = trained_models[engine]
    rung = model.fidelity_ladder()[-2]
    lead = rung.lookahead.seconds
    spans = _heldout_spans(small_demo_corpus)
    synthesizer = model.start(fps=60.0, **rung.options)
    pieces = []
    for span in spans:
        synthesizer.feed([span])
        pieces.append(synthesizer.frames())
        emitted = sum(len(piece) for piece in pieces)
        assert emitted == (frame_count(span.end - lead, 60.0) if span.end >= lead else 0)
    pieces.append(synthesizer.finish())
    offline = model.synthesize(spans, fps=60.0, **rung.options).frames
    np.testing.assert_array_equal(np.concatenate(pieces), offline)


EMPTY_REQUEST_FPS = [*range(1, int(MAX_FPS) + 1), MIN_FPS, 119.5, 120.25, 999.9]


@pytest.mark.parametrize("engine", ENGINES)
def test_a_request_with_no_input_finishes_with_no_frames_at_every_fps_and_rung(
    engine: str, trained_models: dict[str, Model]
) -> None:
    # anime-graph once raised ValueError (negative dimensions) at every fps from its model's
    # 120 up: an empty smoothing block was filtered.
    model = trained_models[engine]
    for rung in model.fidelity_ladder():
        for fps in EMPTY_REQUEST_FPS:
            synthesizer = model.start(fps=fps, **rung.options)
            assert len(synthesizer.frames()) == 0
            frames = synthesizer.finish()
            assert frames.shape == (0, len(model.channels)), (rung.name, fps)
