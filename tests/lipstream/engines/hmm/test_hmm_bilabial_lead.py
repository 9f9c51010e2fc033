"""The bilabial lead of phoneme-driven ``hmm``: /p b m/ read from their articulatory spans.

A synthetic character whose lips shut ``ARTICULATORY_LEAD`` before each /M/'s acoustic span
(known closure times) shows a model trained with that lead closing on time and earlier than
one trained on the acoustic spans by about the lead; the rungs that lead wait the lead more
and still stream their offline frames; models stored before the lead load without it.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lipstream.corpus import Corpus, Utterance
from lipstream.engines import load_model
from lipstream.engines.base import SynthesisRequest, frames_before
from lipstream.engines.hmm import HmmEngine, HmmModel
from lipstream.engines.hmm.engine import HOLD_CENTRE, phoneme_labels
from lipstream.engines.hmm.model import RUNGS
from lipstream.errors import ModelStoreError
from lipstream.evaluation import closure_centre
from lipstream.phonemes import PHONEME_INDEX
from lipstream.timeline import PhonemeSpan
from tests.helpers import REMOVED, edit_hyperparameters

FPS = 120.0
CHANNELS = ("jawOpen", "mouthClose")
OPEN, SHUT, REST = 0.6, 0.0, 0.1
ARTICULATORY_LEAD = 0.05
"""How far before its acoustic onset the synthetic character shuts its lips for /M/."""


def _line(rng: np.random.Generator, index: int) -> tuple[Utterance, list[float]]:
    """A line of /AA M/ pairs between silences, the lips shut over each /M/ span moved
    ``ARTICULATORY_LEAD`` earlier (smoothed by a symmetric window), and the centres of those
    shut stretches: the known closure times."""
    phones, t, closures = [PhonemeSpan("sil", 0.0, 0.2)], 0.2, []
    for _ in range(6):
        vowel, shut = rng.uniform(0.12, 0.22), rng.uniform(0.07, 0.12)
        phones.append(PhonemeSpan("AA", t, t + vowel))
        phones.append(PhonemeSpan("M", t + vowel, t + vowel + shut))
        closures.append(t + vowel + shut / 2.0 - ARTICULATORY_LEAD)
        t += vowel + shut
    vowel = rng.uniform(0.12, 0.22)
    phones += [PhonemeSpan("AA", t, t + vowel), PhonemeSpan("sil", t + vowel, t + vowel + 0.2)]
    times = np.arange(int((t + vowel + 0.2) * FPS) + 1) / FPS
    aperture = np.where((times < 0.2) | (times >= t + vowel), REST, OPEN)
    for span in phones:
        if span.phoneme == "M":
            start, end = span.start - ARTICULATORY_LEAD, span.end - ARTICULATORY_LEAD
            aperture[(times >= start) & (times < end)] = SHUT
    window = np.hanning(9) / np.hanning(9).sum()
    aperture = np.convolve(np.pad(aperture, 4, mode="edge"), window, mode="valid")
    frames = np.stack([aperture, np.zeros_like(aperture)], axis=1)
    return Utterance(f"line{index:03d}", frames, phones, FPS), closures


@pytest.fixture(scope="module")
def lines() -> tuple[Corpus, list[tuple[Utterance, list[float]]]]:
    rng = np.random.default_rng(0)
    train = [_line(rng, index)[0] for index in range(40)]
    return Corpus("led-closures", FPS, CHANNELS, train), [_line(rng, 100 + i) for i in range(10)]


@pytest.fixture(scope="module")
def models(lines: tuple[Corpus, list[tuple[Utterance, list[float]]]]) -> dict[float, HmmModel]:
    """Models trained at the hold centres (so a closure's only lag is the spans') with no
    lead and with the character's."""
    out = {}
    for lead in (0.0, ARTICULATORY_LEAD):
        model = HmmEngine(sample_offset=HOLD_CENTRE, bilabial_lead_s=lead).fit(lines[0])
        assert isinstance(model, HmmModel) and model.bilabial_lead_s == lead
        out[lead] = model
    return out


def _closure_lags_ms(
    model: HmmModel, tests: list[tuple[Utterance, list[float]]], **options: Any
) -> np.ndarray:
    """Each known closure's lag: the centre of the synthesized aperture's plateau within
    100 ms of it, less its time (phoneme-driven)."""
    lags = []
    for utterance, closures in tests:
        frames = model.synthesize(utterance.phones, fps=FPS, **options).frames
        aperture = frames[:, 0] - frames[:, 1]
        for closure in closures:
            first, stop = round((closure - 0.1) * FPS), round((closure + 0.1) * FPS)
            centre = (first + closure_centre(aperture[first:stop])) / FPS
            lags.append(1000.0 * (centre - closure))
    return np.array(lags)


def test_training_reads_each_frames_phoneme_from_the_led_spans() -> None:
    phones = [PhonemeSpan("sil", 0.0, 0.2), PhonemeSpan("AA", 0.2, 0.26)]
    phones += [PhonemeSpan("M", 0.26, 0.4), PhonemeSpan("AA", 0.4, 0.5)]
    line = Utterance("x", np.zeros((61, 2)), phones, FPS)
    # at 40 Hz frame j is at 25 j ms and takes the span with start < t <= end; /M/ starts
    # 50 ms early at most half the 60 ms /AA/ before it: 30 ms, at 230 ms
    sil, aa, m = PHONEME_INDEX["sil"], PHONEME_INDEX["AA"], PHONEME_INDEX["M"]
    acoustic = [sil] * 9 + [aa] * 2 + [m] * 6 + [aa] * 4
    led = [sil] * 9 + [aa] * 1 + [m] * 7 + [aa] * 4
    assert phoneme_labels(line, 40.0).tolist() == acoustic
    assert phoneme_labels(line, 40.0, 0.05).tolist() == led


def _led_by_hand(spans: list[PhonemeSpan], lead: float) -> list[PhonemeSpan]:
    """Each /p b m/ after another span started ``lead`` earlier, that span ended there, by at
    most half that span (as moved already), loop by loop."""
    led = list(spans)
    for k in range(1, len(led)):
        if led[k].phoneme in ("P", "B", "M"):
            shift = min(lead, (led[k - 1].end - led[k - 1].start) / 2)
            led[k - 1] = dataclasses.replace(led[k - 1], end=led[k - 1].end - shift)
            led[k] = dataclasses.replace(led[k], start=led[k].start - shift)
    return led


def _without_lead(model: HmmModel, directory: Path) -> HmmModel:
    """``model`` as an artifact saved before the lead existed loads it: no lead anywhere."""
    model.save(directory)
    edit_hyperparameters(directory, bilabial_lead_s=REMOVED)
    acoustic = load_model(directory)
    assert isinstance(acoustic, HmmModel) and acoustic.bilabial_lead_s == 0.0
    return acoustic


def test_the_lead_is_the_same_in_training_and_synthesis(
    models: dict[float, HmmModel],
    lines: tuple[Corpus, list[tuple[Utterance, list[float]]]],
    tmp_path: Path,
) -> None:
    """Trained with the lead, the model is the one trained without it on lines whose spans
    were led by hand (the facial HMM does not see the phonemes); served on a rung that
    leads, its frames are its own without the lead run on spans led by hand."""
    corpus, tests = lines
    led = models[ARTICULATORY_LEAD]
    by_hand = Corpus(
        corpus.name,
        corpus.fps,
        corpus.channels,
        [
            dataclasses.replace(u, phones=_led_by_hand(u.phones, ARTICULATORY_LEAD))
            for u in corpus.utterances
        ],
    )
    on_led = HmmEngine(sample_offset=HOLD_CENTRE, bilabial_lead_s=0.0).fit(by_hand)
    for name in ("transition", "means", "phoneme_log_probs", "emotion_log_probs"):
        np.testing.assert_array_equal(led.stored[name], on_led.stored[name])
    acoustic = _without_lead(led, tmp_path / "hmm")
    phones = tests[0][0].phones
    for options in ({"lag_ms": None, "window_ms": None}, {}, {"lag_ms": 200.0}):
        np.testing.assert_array_equal(
            led.synthesize(phones, fps=FPS, **options).frames,
            acoustic.synthesize(_led_by_hand(phones, ARTICULATORY_LEAD), fps=FPS, **options).frames,
        )


def test_led_closures_land_on_the_known_times_no_later_than_the_acoustic_ones(
    models: dict[float, HmmModel], lines: tuple[Corpus, list[tuple[Utterance, list[float]]]]
) -> None:
    """Trained and run with the character's lead, within half an HMM frame (12.5 ms) of the
    known times and earlier than the model trained on the acoustic spans, on the offline
    rung and the ``full`` rung alike. By much less than the lead: the state sequence
    already anticipates the closure from the acoustic labels (a closing state is labelled
    with the vowel before /M/), so the lead refines where the HMM puts it."""
    tests = lines[1]
    half_frame_ms = 500.0 / 40.0
    for options in ({"lag_ms": None, "window_ms": None}, {}):
        acoustic = _closure_lags_ms(models[0.0], tests, **options)
        led = _closure_lags_ms(models[ARTICULATORY_LEAD], tests, **options)
        assert len(led) == 60
        assert abs(led.mean()) < half_frame_ms, led.mean()
        assert led.mean() < acoustic.mean(), (led.mean(), acoustic.mean())


def test_the_rungs_that_lead_wait_the_lead_more_and_the_causal_ones_keep_their_wait(
    models: dict[float, HmmModel],
) -> None:
    led, acoustic = models[ARTICULATORY_LEAD], models[0.0]
    for (name, lag_ms, _), rung, before in zip(
        RUNGS, led.fidelity_ladder(), acoustic.fidelity_ladder(), strict=True
    ):
        assert rung.name == before.name == name
        extra = ARTICULATORY_LEAD if lag_ms > 100.0 else 0.0
        assert rung.lookahead.seconds == pytest.approx(before.lookahead.seconds + extra)
        assert rung.lookahead.phonemes == before.lookahead.phonemes == 0
    assert [rung.name for rung in led.fidelity_ladder() if rung.lookahead.seconds >= 0.5] == [
        "full"
    ]


def test_only_the_rungs_that_lead_read_the_led_spans(
    models: dict[float, HmmModel],
    lines: tuple[Corpus, list[tuple[Utterance, list[float]]]],
    tmp_path: Path,
) -> None:
    """The led model's artifact with its lead taken out of the manifest reads the acoustic
    spans on every rung: the same frames on ``causal_lead`` and ``causal``, others where
    ``full`` and ``short`` lead; driven by audio alone there is no lead."""
    led = models[ARTICULATORY_LEAD]
    acoustic = _without_lead(led, tmp_path / "hmm")
    phones = lines[1][0][0].phones
    for name, lag_ms, window_ms in RUNGS:
        options: dict[str, Any] = {"lag_ms": lag_ms, "window_ms": window_ms}
        same = np.array_equal(
            led.synthesize(phones, fps=FPS, **options).frames,
            acoustic.synthesize(phones, fps=FPS, **options).frames,
        )
        assert same == (lag_ms <= 100.0), name
    assert led.leads(500.0, "audio") == 0.0
    assert led.plan({"lag_ms": None, "window_ms": None}).lead_s == ARTICULATORY_LEAD


@pytest.mark.parametrize("rung", [name for name, _, _ in RUNGS])
def test_every_rung_streams_its_offline_frames_once_its_lookahead_allows(
    models: dict[float, HmmModel],
    lines: tuple[Corpus, list[tuple[Utterance, list[float]]]],
    rung: str,
) -> None:
    model = models[ARTICULATORY_LEAD]
    chosen = next(r for r in model.fidelity_ladder() if r.name == rung)
    spans = lines[1][0][0].phones
    offline = model.synthesize(spans, fps=60.0, **chosen.options).frames
    synthesizer = model.start(SynthesisRequest(fps=60.0, options=dict(chosen.options)))
    pieces = []
    for span in spans:
        synthesizer.feed([span], None)
        pieces.append(synthesizer.frames())
        promised = span.end - chosen.lookahead.seconds
        emitted = sum(len(piece) for piece in pieces)
        assert emitted >= frames_before(promised, 60.0), f"held back at {span}"
    pieces.append(synthesizer.finish())
    np.testing.assert_array_equal(np.concatenate(pieces), offline)


def test_a_lead_above_the_stored_range_is_refused(
    lines: tuple[Corpus, list[tuple[Utterance, list[float]]]],
) -> None:
    for lead in (-0.01, 0.25):
        with pytest.raises(ValueError, match="bilabial_lead_s must be in"):
            HmmEngine(bilabial_lead_s=lead).fit(lines[0])


def test_a_model_stored_before_the_lead_loads_without_it_with_the_frames_of_before(
    lines: tuple[Corpus, list[tuple[Utterance, list[float]]]], tmp_path: Path
) -> None:
    corpus, tests = lines
    model = HmmEngine(n_states=8, n_iter=3, bilabial_lead_s=0.0).fit(corpus)
    model.save(tmp_path / "hmm")
    assert model.manifest.hyperparameters["bilabial_lead_s"] == 0.0
    manifest_path = edit_hyperparameters(tmp_path / "hmm", bilabial_lead_s=REMOVED)
    old = load_model(tmp_path / "hmm")
    assert isinstance(old, HmmModel) and old.bilabial_lead_s == 0.0
    assert old.fidelity_ladder() == model.fidelity_ladder()
    phones = tests[0][0].phones
    for rung in model.fidelity_ladder():
        np.testing.assert_array_equal(
            old.synthesize(phones, fps=FPS, **rung.options).frames,
            model.synthesize(phones, fps=FPS, **rung.options).frames,
        )
    for bad in ("early", 0.5):
        edit_hyperparameters(tmp_path / "hmm", bilabial_lead_s=bad)
        with pytest.raises(ModelStoreError) as refused:
            load_model(tmp_path / "hmm")
        assert refused.value.code == "model_invalid"
        assert refused.value.where == f"{manifest_path}: hyperparameters.bilabial_lead_s"
