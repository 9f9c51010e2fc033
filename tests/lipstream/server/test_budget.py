"""Latency ladder: worst-case estimates, rung choice, calibration and the catalog."""

from __future__ import annotations

import math
from itertools import pairwise
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest

from lipstream.audio import Audio
from lipstream.engines.base import CallCost, Lookahead, Rung, SynthesisRequest
from lipstream.engines.viseme_lerp import VisemeLerpModel
from lipstream.errors import ModelStoreError
from lipstream.phonemes import SILENCE
from lipstream.server.budget import (
    BudgetInfeasible,
    RungEstimate,
    choose_rung,
    estimate,
    lookahead_ms,
)
from lipstream.server.calibration import CALIBRATION_PHONEMES, calibration_spans, measure
from lipstream.server.catalog import Catalog, CatalogError
from lipstream.timeline import PhonemeSpan

if TYPE_CHECKING:
    from lipstream.engines.base import Model

EXACT = Rung("exact", Lookahead(seconds=0.1, phonemes=4))
FIXED_LAG = Rung("fixed_lag", Lookahead(seconds=0.05, phonemes=1), {"lag": 1})
GREEDY = Rung("greedy", Lookahead())


def ladder() -> list[RungEstimate]:
    # max phoneme 200 ms, margin 5 ms: exact 100 + 800 + 12 + 5 = 917 ms,
    # fixed_lag 50 + 200 + 3 + 5 = 258 ms, greedy 0 + 0 + 20.4 + 5 = 25.4 ms.
    return [
        estimate(EXACT, 200.0, 12.0, 5.0, CallCost(0.3, 0.0)),
        estimate(FIXED_LAG, 200.0, 3.0, 5.0, CallCost(0.1, 0.0)),
        estimate(GREEDY, 200.0, 20.4, 5.0, CallCost(0.2, 0.0)),
    ]


def test_lookahead_is_seconds_plus_whole_phonemes_at_the_longest_duration() -> None:
    assert lookahead_ms(EXACT, 200.0) == pytest.approx(900.0)
    assert lookahead_ms(FIXED_LAG, 150.0) == pytest.approx(200.0)
    assert lookahead_ms(GREEDY, 150.0) == 0.0
    assert [rung.worst_case_ms for rung in ladder()] == pytest.approx([917.0, 258.0, 25.4])


@pytest.mark.parametrize(
    ("budget", "chosen"),
    [
        (None, "exact"),
        (5000.0, "exact"),
        (917.0, "exact"),
        (916.9, "fixed_lag"),
        (258.0, "fixed_lag"),
        (100.0, "greedy"),
        (25.4, "greedy"),
    ],
)
def test_the_best_rung_within_the_budget_is_chosen(budget: float | None, chosen: str) -> None:
    assert choose_rung(ladder(), budget).rung.name == chosen


def test_an_impossible_budget_names_the_smallest_feasible_one() -> None:
    with pytest.raises(BudgetInfeasible) as error:
        choose_rung(ladder(), 25.0)
    assert error.value.code == "budget_infeasible"
    assert error.value.min_budget_ms == 26  # ceil(25.4)
    assert error.value.where == "latency_budget_ms"
    assert choose_rung(ladder(), float(error.value.min_budget_ms)).rung.name == "greedy"


PHONEME_COST_S = 0.001
FRAME_COST_S = 0.00001


class _ChargedSynthesizer:
    """A real synthesizer whose ``feed`` takes, on the fake clock, ``PHONEME_COST_S`` a
    phoneme and ``FRAME_COST_S`` for each frame its spans' ends add at the request's fps."""

    def __init__(self, real: Any, clock: _Clock, fps: float) -> None:
        self.real, self.clock, self.fps, self.charged_frames = real, clock, fps, 0

    def feed(self, spans: list[PhonemeSpan], audio: Audio | None = None) -> None:
        self.real.feed(spans, audio)
        frames = math.floor(spans[-1].end * self.fps + 1e-9) + 1  # frames i with i/fps <= end
        self.clock.now += PHONEME_COST_S * len(spans)
        self.clock.now += FRAME_COST_S * (frames - self.charged_frames)
        self.charged_frames = frames

    def frames(self) -> object:
        return self.real.frames()

    def finish(self) -> object:
        return self.real.finish()


class _ChargedModel:
    def __init__(self, real: Model, clock: _Clock) -> None:
        self.real, self.clock, self.uses_audio = real, clock, real.uses_audio

    def start(self, request: SynthesisRequest) -> _ChargedSynthesizer:
        return _ChargedSynthesizer(self.real.start(request), self.clock, request.fps)


def test_calibration_utterance_and_measurement(
    trained_models: dict[str, Model], monkeypatch: pytest.MonkeyPatch
) -> None:
    spans = calibration_spans()
    assert len(spans) == CALIBRATION_PHONEMES
    assert all(left.end == pytest.approx(right.start) for left, right in pairwise(spans))
    clock = _Clock()
    monkeypatch.setattr("lipstream.server.calibration.time", clock)
    model = _ChargedModel(trained_models["viseme-lerp"], clock)
    cost = measure(model, Rung("default", Lookahead(phonemes=1)))  # type: ignore[arg-type]  # a stand-in with what measure uses
    # 48 phonemes of 80 ms at 60 fps: frames 0..4 come with the first (4.8 frames each, so
    # 4 or 5 after it), 231 in all (3.84 s). The slowest call is the first: 1 + 5 × 0.01 ms.
    assert cost.max_call_ms == pytest.approx(1.05)
    assert cost.per_phoneme_ms == pytest.approx((48 * 1.0 + 231 * 0.01) / 48)
    # The extra frames of the higher rate cost what each frame was charged.
    assert cost.per_frame_ms == pytest.approx(0.01)


def test_catalog_resolves_models_and_names_the_missing_field(catalog: Catalog) -> None:
    assert catalog.model("viseme-lerp", "demo").manifest.engine == "viseme-lerp"
    with pytest.raises(CatalogError) as error:
        catalog.model("no-such-engine", "demo")
    assert (error.value.code, error.value.where) == ("unknown_engine", "engine")
    with pytest.raises(CatalogError) as error:
        catalog.model("viseme-lerp", "nobody")
    assert (error.value.code, error.value.where) == ("unknown_character", "character")


# Worst-case waits (ms) of the demo models' rungs with phonemes of at most 200 ms. viseme-lerp
# waits one phoneme. anime-graph (120 fps, 0.1 s smoothing window: half-width 12 frames)
# waits 13 / 120 s = 108.333 ms for the next grid sample and the filter (1 / 120 s = 8.333 ms
# unsmoothed), 32.5 ms for the audio (two 10 ms MFCC steps and half a 25 ms window), and
# max_tile phonemes: 10 -> 2140.833, 4 -> 940.833, 2 -> 540.833, 1 -> 340.833.
DEMO_LOOKAHEAD_MS = {
    "viseme-lerp": {
        "lerp": 200.0,
        "causal": 0.0,
    },
    # Viterbi lag + trajectory block and future context, + the 80 ms bilabial lead (the rungs
    # with a lag above 100 ms), + half a feature window
    "hmm": {
        "full": 500.0 + 1000.0 * 44 / 120 + 80.0 + 12.5,
        "short": 200.0 + 1000.0 * 17 / 120 + 80.0 + 12.5,
        "causal": 0.0,
    },
    "anime-graph": {
        "greedy_tile10": 2140.833,
        "greedy_tile4": 940.833,
        "greedy_tile2": 540.833,
        "greedy_tile1": 340.833,
        "greedy_tile1_unsmoothed": 240.833,
        "causal": 0.0,
    },
    # expressive-dp: a fixed lag of L phonemes, plus two for smoothing and interpolation
    "expressive-dp": {
        "lag-4": 1200.0,
        "lag-2": 800.0,
        "lag-1": 600.0,
        "lag-0": 400.0,
        "causal": 0.0,
    },
}


def test_catalog_ladder_follows_each_models_declared_rungs(catalog: Catalog) -> None:
    assert catalog.settings.max_phoneme_ms == 200.0
    for model in catalog.registry.models.values():
        rungs = catalog.ladder(model)
        assert [estimate.rung for estimate in rungs] == list(model.fidelity_ladder())
        engine = model.manifest.engine
        waits = {e.rung.name: e.lookahead_ms for e in rungs}
        if engine in ("dam", "cohen-massaro"):
            # the mode search looks 2, 1, 0 phonemes ahead, beside the fitted tail; the
            # bilabial lead waits one phoneme and the lead more
            tail = model.manifest.extra["tail"]
            lead_s = model.manifest.hyperparameters["bilabial_lead_s"]
            assert lead_s > 0.0
            led = 200.0 + 1000.0 * lead_s
            expected = {"full": (tail + 2) * 200.0 + led, "search-1": (tail + 1) * 200.0 + led}
            expected["search-0"] = tail * 200.0 + led
            expected["causal"] = 0.0
        else:
            expected = DEMO_LOOKAHEAD_MS[engine]
        # The lead rung waits its filter's lag, a trained figure, of at most 120 ms.
        lead = waits.pop(rungs[-2].rung.name)
        assert rungs[-2].rung.name.endswith("_lead") and 0.0 < lead <= 120.0
        assert waits == pytest.approx(expected, abs=1e-3)
        for estimate_ in rungs:
            assert estimate_.compute_ms >= catalog.settings.compute_margin_ms


def test_rest_pose_of_viseme_lerp_is_its_silence_key_pose(catalog: Catalog) -> None:
    model = catalog.model("viseme-lerp", "demo")
    assert isinstance(model, VisemeLerpModel)
    silence_row = model.scheme.classes.index(model.scheme.viseme_of(SILENCE))
    expected = model.poses[silence_row]
    for emotion in (None, "happy"):
        np.testing.assert_allclose(catalog.rest_pose(model, emotion), expected, atol=1e-7)


NO_FRAMES = np.zeros((0, 1), dtype=np.float32)


Fed = tuple[PhonemeSpan, Audio | None]  # a feed's first span and its audio


class _RecordingSynthesizer:
    def __init__(self, fed: list[Fed]) -> None:
        self.fed = fed

    def feed(self, spans: list[PhonemeSpan], audio: Audio | None = None) -> None:
        self.fed.append((spans[0], audio))

    def frames(self) -> np.ndarray:
        return NO_FRAMES

    def finish(self) -> np.ndarray:
        return NO_FRAMES


class _AudioEngineModel:
    """Just what ``measure`` touches of a model whose engine uses audio."""

    uses_audio = True

    def __init__(self) -> None:
        self.passes: list[list[Fed]] = []

    def start(self, request: object) -> _RecordingSynthesizer:
        self.passes.append([])
        return _RecordingSynthesizer(self.passes[-1])


def test_an_engine_that_uses_audio_is_also_calibrated_with_audio_under_each_span() -> None:
    model = _AudioEngineModel()
    measure(model, Rung("default", Lookahead(phonemes=1)))  # type: ignore[arg-type]  # a stand-in with what measure uses
    streamed = [fed for fed in model.passes if len(fed) > 1]
    with_audio = [fed for fed in streamed if fed[0][1] is not None]
    without = [fed for fed in streamed if fed[0][1] is None]
    assert len(with_audio) == len(without) == 4  # warm-up + CALIBRATION_PASSES each
    # The frame cost: the whole utterance in one feed, at two frame rates, 3 passes each.
    offline = [fed for fed in model.passes if len(fed) == 1]
    assert len(offline) == 8 and all(fed[0][1] is None for fed in offline)
    for fed in with_audio:
        voiced = [(span, audio) for span, audio in fed if audio is not None]
        assert len(voiced) == len(fed)  # audio under every span
        ends = [round(span.end * audio.sample_rate) for span, audio in voiced]
        assert [len(audio.samples) for _, audio in voiced] == np.diff([0, *ends]).tolist()
        assert all(np.abs(audio.samples).max() > 0.2 for _, audio in voiced)  # voiced, not silence


class _Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def perf_counter(self) -> float:
        return self.now


class _TimedSynthesizer:
    """Each feed takes 1 ms of the fake clock, or 10 ms at the call index its pass names."""

    def __init__(self, clock: _Clock, slow_call: int | None) -> None:
        self.clock, self.slow_call, self.calls = clock, slow_call, 0

    def feed(self, spans: list[PhonemeSpan], audio: Audio | None = None) -> None:
        self.clock.now += 0.010 if self.calls == self.slow_call else 0.001
        self.calls += 1

    def frames(self) -> np.ndarray:
        return NO_FRAMES

    def finish(self) -> np.ndarray:
        return NO_FRAMES


class _PreemptedModel:
    """Streamed passes (warm-up, then three measured) each preempted at a different call."""

    uses_audio = False

    def __init__(self, clock: _Clock) -> None:
        self.clock, self.started = clock, 0

    def start(self, request: object) -> _TimedSynthesizer:
        slow = [None, 5, 17, 30][self.started] if self.started < 4 else None
        self.started += 1
        return _TimedSynthesizer(self.clock, slow)


def test_compute_time_is_the_slowest_call_at_its_fastest_over_the_passes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    clock = _Clock()
    monkeypatch.setattr("lipstream.server.calibration.time", clock)
    cost = measure(_PreemptedModel(clock), GREEDY)  # type: ignore[arg-type]  # a stand-in with what measure uses
    # Every call takes 1 ms in some pass; the finish calls take no time.
    assert cost.max_call_ms == pytest.approx(1.0)
    # 48 calls at their fastest, 1 ms each, over 48 phonemes.
    assert cost.per_phoneme_ms == pytest.approx(1.0)


class _NanAtCall(_RecordingSynthesizer):
    """Frames at every call, the third call's holding a NaN."""

    def frames(self) -> np.ndarray:
        values = np.zeros((2, 3), dtype=np.float32)
        if len(self.fed) == 3:
            values[1, 2] = np.nan
        return values


class _NanModel(_AudioEngineModel):
    uses_audio = False

    def start(self, request: object) -> _RecordingSynthesizer:
        self.passes.append([])
        return _NanAtCall(self.passes[-1])


def test_a_non_finite_frame_in_calibration_refuses_the_model_naming_the_rung() -> None:
    with pytest.raises(ModelStoreError) as caught:
        measure(_NanModel(), Rung("lag-2", Lookahead(phonemes=1)), where="/m/x")  # type: ignore[arg-type]  # a stand-in with what measure uses
    assert (caught.value.code, caught.value.where) == ("model_invalid", "/m/x: probe on rung lag-2")
    assert caught.value.message.startswith(
        "synthesized 1 NaN or infinite values from the calibration utterance "
        "(first at frame 1, channel 2)"
    )
