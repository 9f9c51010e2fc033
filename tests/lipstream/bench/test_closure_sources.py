from types import SimpleNamespace
from typing import cast

import numpy as np
import pytest

from lipstream.bench.closure_sources import (
    RealPhones,
    aperture_r,
    bilabial_contexts,
    character_aperture,
    format_split,
    phoneme_mean_aperture_r,
    split_lags,
)
from lipstream.bench.real_faces import Clip
from lipstream.engines.base import Model
from lipstream.timeline import PhonemeSpan

FPS = 100.0


def test_a_bilabial_is_after_silence_when_it_opens_the_clip_or_follows_a_pause() -> None:
    phones = [
        PhonemeSpan("B", 0.0, 0.1),
        PhonemeSpan("AA", 0.1, 0.2),
        PhonemeSpan("M", 0.2, 0.3),
        PhonemeSpan("sil", 0.3, 0.4),
        PhonemeSpan("P", 0.4, 0.5),
        PhonemeSpan("IY", 0.5, 0.6),
    ]
    contexts = [(span.phoneme, context) for span, context in bilabial_contexts(phones)]
    assert contexts == [("B", "after_silence"), ("M", "after_speech"), ("P", "after_silence")]


def _dip(times: np.ndarray, centre: float) -> np.ndarray:
    """Lips that close once, lowest at ``centre``, open 0.2 a frame either side."""
    return np.minimum(np.abs(times - centre) * 20.0, 1.0)


def _clip(stem: str, phones: list[PhonemeSpan], real_at: float) -> Clip:
    times = np.arange(100) / FPS
    speech = np.ones(len(times), dtype=bool)
    return Clip(stem, "s", _dip(times, real_at), speech, phones)


def test_each_engines_lag_on_real_lips_splits_into_its_lag_behind_the_character_and_the_characters() -> (
    None
):
    times = np.arange(100) / FPS
    # clip a: a /p/ after silence, real lips shut at 0.40 s, the character at 0.43 s, the
    # engine at 0.48 s; clip b: a /b/ after a vowel, real 0.50 s, character 0.46 s,
    # engine 0.52 s
    a = _clip("a", [PhonemeSpan("sil", 0.0, 0.38), PhonemeSpan("P", 0.38, 0.46)], 0.40)
    b = _clip("b", [PhonemeSpan("AA", 0.0, 0.47), PhonemeSpan("B", 0.47, 0.55)], 0.50)
    character = [_dip(times, 0.43), _dip(times, 0.46)]
    engine = [_dip(times, 0.48), _dip(times, 0.52)]
    split = split_lags([a, b], character, {"dam": engine}, FPS)

    behind_real = split["character_behind_real"]
    assert behind_real["after_silence"]["mean_ms"] == pytest.approx(30.0)
    assert behind_real["after_speech"]["mean_ms"] == pytest.approx(-40.0)
    assert behind_real["all"]["mean_ms"] == pytest.approx(-5.0)
    assert behind_real["all"]["se_ms"] == pytest.approx(np.std([30.0, -40.0], ddof=1) / np.sqrt(2))
    assert behind_real["after_silence"]["se_ms"] is None
    dam = split["engines"]["dam"]
    assert dam["behind_character"]["after_silence"]["mean_ms"] == pytest.approx(50.0)
    assert dam["behind_character"]["after_speech"]["mean_ms"] == pytest.approx(60.0)
    assert dam["behind_real"]["after_silence"]["mean_ms"] == pytest.approx(80.0)
    assert dam["behind_real"]["after_speech"]["mean_ms"] == pytest.approx(20.0)
    assert dam["behind_real"]["all"]["count"] == 2
    table = format_split(split)
    assert "character behind real" in table and "dam behind character" in table


def test_aperture_r_is_pearson_on_the_speech_frames_averaged_over_clips() -> None:
    times = np.arange(100) / FPS
    same = _clip("a", [PhonemeSpan("M", 0.38, 0.46)], 0.42)
    # a character shut where the real lips are open, and the reverse: r = -1 on clip b
    mirrored = _clip("b", [PhonemeSpan("M", 0.38, 0.46)], 0.42)
    character = [2.0 * _dip(times, 0.42) + 0.1, 1.0 - _dip(times, 0.42)]
    assert aperture_r([same, mirrored], character) == pytest.approx(0.0)
    assert aperture_r([same], character[:1]) == pytest.approx(1.0)
    # only the speech frames count: outside them the character may do anything
    masked = Clip("c", "s", same.aperture, times < 0.6, same.phones)
    noisy = character[0].copy()
    noisy[times >= 0.6] = np.linspace(5.0, -5.0, int(np.sum(times >= 0.6)))
    assert aperture_r([masked], [noisy]) == pytest.approx(1.0)


def test_phoneme_means_from_the_other_clips_predict_a_clip_whose_phonemes_keep_their_apertures() -> (
    None
):
    # 25 fps; AA open (1.0) and M shut (0.0) in every clip, in different orders, so each
    # clip's predictor (the other clips' means, smoothed) tracks it: r near 1
    fps = 25.0

    def clip(stem: str, order: list[str]) -> Clip:
        phones = [PhonemeSpan(p, 0.4 * i, 0.4 * (i + 1)) for i, p in enumerate(order)]
        aperture = np.repeat([1.0 if p == "AA" else 0.0 for p in order], 10)
        return Clip(stem, "s", aperture, np.ones(len(aperture), dtype=bool), phones)

    clips = [clip("a", ["AA", "M", "AA", "M"]), clip("b", ["M", "AA", "M", "AA"])]
    clips.append(clip("c", ["AA", "AA", "M", "M"]))
    r = phoneme_mean_aperture_r(clips, fps)
    assert 0.9 < r < 1.0
    # a clip whose AA is shut and M open is predicted backwards
    backwards = Clip("d", "s", 1.0 - clips[0].aperture, clips[0].speech, clips[0].phones)
    assert phoneme_mean_aperture_r([*clips[1:], backwards], fps) < 0.5


def test_a_context_without_bilabials_has_no_mean() -> None:
    times = np.arange(100) / FPS
    clip = _clip("a", [PhonemeSpan("AA", 0.0, 0.38), PhonemeSpan("M", 0.38, 0.46)], 0.42)
    split = split_lags([clip], [_dip(times, 0.42)], {}, FPS)
    assert split["character_behind_real"]["after_silence"] == {
        "mean_ms": None,
        "se_ms": None,
        "count": 0,
    }
    assert split["character_behind_real"]["after_speech"]["mean_ms"] == pytest.approx(0.0)
    assert "n/a" in format_split(split)


def test_the_character_shuts_its_lips_in_the_m_and_opens_them_in_the_vowels() -> None:
    phones = [
        PhonemeSpan("sil", 0.0, 0.3),
        PhonemeSpan("AA", 0.3, 0.5),
        PhonemeSpan("M", 0.5, 0.62),
        PhonemeSpan("AA", 0.62, 0.82),
        PhonemeSpan("sil", 0.82, 1.2),
    ]
    aperture = character_aperture(phones, 31, 25.0, seed=3)
    assert aperture.shape == (31,)
    # 25 fps: frame 14 is 0.56 s, inside the /m/; frames 10 and 18 are 0.40 s and 0.72 s,
    # the vowels' middles
    assert aperture[14] < 0.02
    assert aperture[10] > 0.1 and aperture[18] > 0.1


class _DippingModel:
    """A model whose lips close once, lowest ``shift_s`` after the start of its input's
    first /B/ (jawOpen the aperture, mouthClose 0)."""

    channels = ("jawOpen", "mouthClose")

    def __init__(self, shift_s: float) -> None:
        self.shift_s = shift_s
        self.manifest = SimpleNamespace(engine="dipping")

    def synthesize(self, phones: list[PhonemeSpan], fps: float, audio: None) -> SimpleNamespace:
        onset = next(span.start for span in phones if span.phoneme == "B")
        times = np.arange(100) / fps
        frames = np.stack([_dip(times, onset + self.shift_s), np.zeros(len(times))], axis=1)
        return SimpleNamespace(frames=frames)


def test_real_phones_time_a_model_behind_the_character_and_behind_the_real_lips() -> None:
    phones = [PhonemeSpan("AA", 0.0, 0.4), PhonemeSpan("B", 0.4, 0.5), PhonemeSpan("IY", 0.5, 1.0)]
    times = np.arange(100) / FPS
    clip = _clip("a", phones, real_at=0.42)
    real = RealPhones("set", [clip], [_dip(times, 0.45)], FPS)  # the character at 0.45 s
    model = cast(Model, _DippingModel(0.08))  # lowest at 0.48 s
    found = real.timed(model)
    assert found["behind_character"]["mean_ms"] == pytest.approx(30.0)
    assert found["behind_real"]["mean_ms"] == pytest.approx(60.0)
    assert found["behind_real"]["count"] == 1
    # the model's dip, 60 ms after the real one, against the real lips' own
    predicted = _dip(times, 0.48)
    expected_r = np.corrcoef(predicted[clip.speech], clip.aperture[clip.speech])[0, 1]
    assert found["aperture_r"] == pytest.approx(expected_r)
    # led by 30 ms, the model's /B/ starts at 0.37 s: lowest at 0.45 s, with the character
    led = real.timed(model, lead_s=0.03)
    assert led["behind_character"]["mean_ms"] == pytest.approx(0.0, abs=1e-6)
