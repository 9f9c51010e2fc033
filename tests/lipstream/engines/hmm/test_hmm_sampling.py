"""Where training samples the face: ``sample_offset``, at the instants (the default) or at
the centre of the interval each state is held over.

The synthesizer holds HMM frame j's state over [j / R, (j + 1) / R); a model trained on the
face at the instants j / R closes the lips about half an HMM frame late, one trained at the
hold centres (j + ½) / R on time. A synthetic character whose lips are shut exactly over
each /M/ span (known closure times, the spans' centres) shows it, and stored models from
before the hyperparameter, with no ``sample_offset`` in their manifest, still load.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lipstream.corpus import Corpus, Utterance
from lipstream.engines import load_model
from lipstream.engines.hmm import HmmEngine, HmmModel
from lipstream.engines.hmm.engine import HOLD_CENTRE, observations
from lipstream.errors import ModelStoreError
from lipstream.evaluation import closure_centre
from lipstream.numerics.basis import fit_basis
from lipstream.timeline import PhonemeSpan
from tests.helpers import REMOVED, edit_hyperparameters

FPS = 120.0
HMM_FPS = 40.0
CHANNELS = ("jawOpen", "mouthClose")
OPEN, SHUT, REST = 0.6, 0.0, 0.1


def _line(rng: np.random.Generator, index: int) -> tuple[Utterance, list[float]]:
    """A line of /AA M/ pairs between silences, the lips shut over each /M/ span (smoothed
    by a symmetric window, so each closure stays centred on its span), and the centres of
    those spans: the known closure times."""
    phones, t, closures = [PhonemeSpan("sil", 0.0, 0.2)], 0.2, []
    for _ in range(6):
        vowel, shut = rng.uniform(0.12, 0.22), rng.uniform(0.07, 0.12)
        phones.append(PhonemeSpan("AA", t, t + vowel))
        phones.append(PhonemeSpan("M", t + vowel, t + vowel + shut))
        closures.append(t + vowel + shut / 2.0)
        t += vowel + shut
    vowel = rng.uniform(0.12, 0.22)
    phones += [PhonemeSpan("AA", t, t + vowel), PhonemeSpan("sil", t + vowel, t + vowel + 0.2)]
    times = np.arange(int((t + vowel + 0.2) * FPS) + 1) / FPS
    aperture = np.where((times < 0.2) | (times >= t + vowel), REST, OPEN)
    for span in phones:
        if span.phoneme == "M":
            aperture[(times >= span.start) & (times < span.end)] = SHUT
    window = np.hanning(9) / np.hanning(9).sum()
    aperture = np.convolve(np.pad(aperture, 4, mode="edge"), window, mode="valid")
    frames = np.stack([aperture, np.zeros_like(aperture)], axis=1)
    return Utterance(f"line{index:03d}", frames, phones, FPS), closures


@pytest.fixture(scope="module")
def lines() -> tuple[Corpus, list[tuple[Utterance, list[float]]]]:
    rng = np.random.default_rng(0)
    train = [_line(rng, index)[0] for index in range(40)]
    return Corpus("closures", FPS, CHANNELS, train), [_line(rng, 100 + i) for i in range(10)]


def _closure_lags_ms(model: HmmModel, tests: list[tuple[Utterance, list[float]]]) -> np.ndarray:
    """Each known closure's lag: the centre of the synthesized aperture's plateau within
    100 ms of it, less its time (phoneme-driven, offline rung)."""
    lags = []
    for utterance, closures in tests:
        frames = model.synthesize(utterance.phones, fps=FPS, lag_ms=None, window_ms=None).frames
        aperture = frames[:, 0] - frames[:, 1]
        for closure in closures:
            first, stop = round((closure - 0.1) * FPS), round((closure + 0.1) * FPS)
            centre = (first + closure_centre(aperture[first:stop])) / FPS
            lags.append(1000.0 * (centre - closure))
    return np.array(lags)


def test_observations_sample_the_face_at_the_hold_centres() -> None:
    times = np.arange(121) / FPS
    ramp = np.stack([np.sin(3.0 * times), np.cos(2.0 * times)], axis=1)
    line = Utterance("ramp", ramp, [PhonemeSpan("AA", 0.0, 1.0)], FPS)
    basis, _ = fit_basis(ramp, 1.0)
    seen = observations(line, basis, HMM_FPS)
    centres = np.minimum((np.arange(41) + 0.5) / HMM_FPS, 1.0)  # past the end: the last frame
    expected = np.stack([np.interp(centres, times, ramp[:, c]) for c in range(2)], axis=1)
    np.testing.assert_allclose(
        basis.reconstruct(seen[:, : len(basis.components)]), expected, atol=1e-9
    )
    at_instants = observations(line, basis, HMM_FPS, 0.0)
    np.testing.assert_allclose(
        basis.reconstruct(at_instants[:, : len(basis.components)]), ramp[::3]
    )


def test_a_closure_lands_on_its_known_time_when_trained_at_the_hold_centres(
    lines: tuple[Corpus, list[tuple[Utterance, list[float]]]],
) -> None:
    """Within a quarter of an HMM frame (6.25 ms) of the known closure times; the same
    model trained at the instants j / R closes later than that. This character shuts its
    lips on the acoustic /M/ spans, so the models read them (no bilabial lead)."""
    corpus, tests = lines
    quarter_frame_ms = 250.0 / HMM_FPS
    centred = HmmEngine(hmm_fps=HMM_FPS, sample_offset=HOLD_CENTRE, bilabial_lead_s=0.0).fit(corpus)
    assert isinstance(centred, HmmModel) and centred.sample_offset == 0.5
    on_time = _closure_lags_ms(centred, tests)
    assert len(on_time) == 60
    assert abs(on_time.mean()) < quarter_frame_ms, on_time.mean()
    instant = HmmEngine(hmm_fps=HMM_FPS, bilabial_lead_s=0.0).fit(corpus)
    assert isinstance(instant, HmmModel) and instant.sample_offset == 0.0
    assert _closure_lags_ms(instant, tests).mean() > quarter_frame_ms


def test_a_sample_offset_outside_one_hmm_frame_is_refused(
    lines: tuple[Corpus, list[tuple[Utterance, list[float]]]],
) -> None:
    for offset in (-0.1, 1.0):
        with pytest.raises(ValueError, match="sample_offset must be in"):
            HmmEngine(sample_offset=offset).fit(lines[0])


def test_a_model_stored_before_the_offset_loads_as_sampled_at_the_instants(
    lines: tuple[Corpus, list[tuple[Utterance, list[float]]]], tmp_path: Path
) -> None:
    corpus, tests = lines
    model = HmmEngine(n_states=8, n_iter=3, sample_offset=HOLD_CENTRE).fit(corpus)
    model.save(tmp_path / "hmm")
    assert model.manifest.hyperparameters["sample_offset"] == 0.5
    manifest_path = edit_hyperparameters(tmp_path / "hmm", sample_offset=REMOVED)
    old = load_model(tmp_path / "hmm")
    assert isinstance(old, HmmModel) and old.sample_offset == 0.0
    phones = tests[0][0].phones
    np.testing.assert_array_equal(
        old.synthesize(phones, fps=FPS).frames, model.synthesize(phones, fps=FPS).frames
    )
    edit_hyperparameters(tmp_path / "hmm", sample_offset="half")
    with pytest.raises(ModelStoreError) as refused:
        load_model(tmp_path / "hmm")
    assert refused.value.code == "model_invalid"
    assert refused.value.where == f"{manifest_path}: hyperparameters.sample_offset"
