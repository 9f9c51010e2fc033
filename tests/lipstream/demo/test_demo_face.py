"""The articulatory face generator: lip closure, rounding anticipation, speed,
determinism, emotion and speaker effects, blinks, input errors."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from lipstream.demo.face import DEMO_CHANNELS, DEMO_SPEAKERS, JAW_MAX_SPEED, generate_face
from lipstream.demo.speakers import Speaker
from lipstream.errors import InvalidRequestError, UnknownPhonemeError
from lipstream.speech.espeak import EspeakSynthesizer
from lipstream.timeline import PhonemeSpan

CHANNEL = {name: index for index, name in enumerate(DEMO_CHANNELS)}
FPS = 120.0
EMOTIONS = ("neutral", "happy", "angry", "sad")
BILABIAL_SENTENCES = (
    "Please map the old path by the bamboo pond.",
    "Bob bought a big box of apples for my mom.",
    "The happy puppy jumped up and ate a plump plum.",
)


def _speak(text: str) -> tuple[float, list[PhonemeSpan]]:
    audio, spans = EspeakSynthesizer().speak(text)
    return audio.duration, spans


def _channel(frames: np.ndarray, name: str) -> np.ndarray:
    return frames[:, CHANNEL[name]]


def _lips_apart(frames: np.ndarray) -> np.ndarray:
    return np.asarray(_channel(frames, "jawOpen") - _channel(frames, "mouthClose"))


def _frame(time_s: float) -> int:
    return round(time_s * FPS)


def _spans(*items: tuple[str, float]) -> tuple[float, list[PhonemeSpan]]:
    spans, start = [], 0.0
    for phoneme, length in items:
        spans.append(PhonemeSpan(phoneme, start, start + length))
        start += length
    return start, spans


@pytest.fixture(scope="module")
def spoken() -> list[tuple[float, list[PhonemeSpan]]]:
    return [_speak(text) for text in BILABIAL_SENTENCES]


def test_channels_and_shape() -> None:
    assert len(DEMO_CHANNELS) == 28 == len(set(DEMO_CHANNELS))
    assert DEMO_CHANNELS[:2] == ("jawOpen", "mouthClose")
    duration, spans = _spans(("sil", 0.3), ("AA", 0.2), ("sil", 0.3))
    for fps in (120.0, 60.0, 29.97):
        frames = generate_face(
            spans, duration, emotion="neutral", speaker=DEMO_SPEAKERS[0], fps=fps, seed=1
        )
        assert frames.shape == (math.floor(duration * fps) + 1, 28)
        assert frames.dtype == np.float32


@pytest.mark.parametrize("emotion", EMOTIONS)
def test_bilabials_close_the_lips_and_open_vowels_open_them(
    spoken: list[tuple[float, list[PhonemeSpan]]], emotion: str
) -> None:
    n_bilabials = n_open = 0
    for speaker in DEMO_SPEAKERS:
        for seed, (duration, spans) in enumerate(spoken):
            frames = generate_face(spans, duration, emotion=emotion, speaker=speaker, seed=seed)
            apart = _lips_apart(frames)
            press = _channel(frames, "mouthPressLeft")
            for span in spans:
                middle = _frame(span.centre)
                if span.phoneme in ("P", "B", "M"):
                    n_bilabials += 1
                    assert apart[middle] < 0.02, (speaker.name, span)
                    inside = apart[_frame(span.start) : _frame(span.end) + 1]
                    # shut by about the acoustic onset and held for 40% of the span
                    # (CONTACT_HOLD) before the release starts
                    assert np.mean(inside < 0.02) >= 0.4, (speaker.name, span)
                    assert press[middle] > 0.1, (speaker.name, span)
                if span.phoneme in ("AA", "AE"):
                    n_open += 1
                    assert apart[middle] > 0.1, (speaker.name, span)
    assert n_bilabials >= 3 * 20 and n_open >= 3 * 5


def test_labiodentals_tuck_the_lower_lip(spoken: list[tuple[float, list[PhonemeSpan]]]) -> None:
    duration, spans = _speak("Five very fine fish for Victor.")
    frames = generate_face(spans, duration, emotion="neutral", speaker=DEMO_SPEAKERS[1], seed=4)
    roll = _channel(frames, "mouthRollLower")
    apart = _lips_apart(frames)
    labiodental = [span for span in spans if span.phoneme in ("F", "V")]
    vowels = [span for span in spans if span.phoneme in ("AY", "IY", "EH", "IH")]
    assert len(labiodental) >= 5
    assert min(roll[_frame(span.centre)] for span in labiodental) > 0.25
    assert max(roll[_frame(span.centre)] for span in vowels) < 0.1
    assert max(apart[_frame(span.centre)] for span in labiodental) < 0.1


FAR_SIGHTED = tuple(replace(speaker, lookahead_s=0.3) for speaker in DEMO_SPEAKERS)
"""The demo speakers with a 0.3 s rounding look-ahead (theirs is calibrated to about 0.08 s),
so rounding reaches back across two consonants."""


def _rounding_before(vowel: str) -> np.ndarray:
    duration, spans = _spans(
        ("sil", 0.3), ("IY", 0.15), ("S", 0.1), ("T", 0.06), (vowel, 0.2), ("sil", 0.3)
    )
    return generate_face(spans, duration, emotion="neutral", speaker=FAR_SIGHTED[0], seed=2)


def test_rounding_is_anticipated_across_the_consonants() -> None:
    before_uw = _channel(_rounding_before("UW"), "mouthPucker")
    before_iy = _channel(_rounding_before("IY"), "mouthPucker")
    s_middle, t_middle = _frame(0.5), _frame(0.58)
    assert before_uw[s_middle] > before_iy[s_middle] + 0.05
    assert before_uw[t_middle] > before_iy[t_middle] + 0.2
    assert before_uw[t_middle] > before_uw[s_middle]  # still rising into UW
    assert before_iy[t_middle] < 0.05


def test_rounding_anticipation_in_espeak_timing() -> None:
    def pucker_on_consonants(text: str) -> float:
        duration, spans = _speak(text)
        frames = generate_face(spans, duration, emotion="neutral", speaker=FAR_SIGHTED[2], seed=3)
        pucker = _channel(frames, "mouthPucker") + _channel(frames, "mouthFunnel")
        labels = [span.phoneme for span in spans]
        t_index = labels.index("T")
        assert labels[t_index - 1] == "Z"
        return float(np.mean([pucker[_frame(spans[i].centre)] for i in (t_index - 1, t_index)]))

    assert pucker_on_consonants("She needs two.") > pucker_on_consonants("She needs tea.") + 0.15


@pytest.mark.parametrize("emotion", EMOTIONS)
def test_jaw_speed_is_bounded_and_channels_are_consistent(
    spoken: list[tuple[float, list[PhonemeSpan]]], emotion: str
) -> None:
    fastest = 0.0
    for speaker in DEMO_SPEAKERS:
        for seed, (duration, spans) in enumerate(spoken):
            frames = generate_face(spans, duration, emotion=emotion, speaker=speaker, seed=seed)
            jaw = _channel(frames, "jawOpen").astype(np.float64)
            fastest = max(fastest, float(np.max(np.abs(np.diff(jaw))) * FPS))
            assert np.all(frames >= 0.0) and np.all(frames <= 1.0)
            assert np.all(_channel(frames, "mouthClose") <= _channel(frames, "jawOpen") + 1e-6)
    # float32 rounding of the stored values is far below 1e-4 per frame.
    assert fastest <= JAW_MAX_SPEED + 1e-4 * FPS
    assert fastest > 0.3 * JAW_MAX_SPEED


def test_same_seed_is_identical_and_speakers_differ(
    spoken: list[tuple[float, list[PhonemeSpan]]],
) -> None:
    duration, spans = spoken[0]
    first = generate_face(spans, duration, emotion="happy", speaker=DEMO_SPEAKERS[0], seed=7)
    again = generate_face(spans, duration, emotion="happy", speaker=DEMO_SPEAKERS[0], seed=7)
    assert first.tobytes() == again.tobytes()
    other_seed = generate_face(spans, duration, emotion="happy", speaker=DEMO_SPEAKERS[0], seed=8)
    other_speaker = generate_face(
        spans, duration, emotion="happy", speaker=DEMO_SPEAKERS[1], seed=7
    )
    assert np.abs(first - other_seed).max() > 0.01
    assert np.abs(first - other_speaker).max() > 0.05


def test_speaker_traits_are_drawn_from_the_seed() -> None:
    assert Speaker.from_seed("x", 42) == Speaker.from_seed("x", 42)
    assert Speaker.from_seed("x", 42).jaw_scale != Speaker.from_seed("x", 43).jaw_scale
    wide = Speaker("wide", 1, jaw_scale=1.3, noise_level=0.0)
    narrow = Speaker("narrow", 1, jaw_scale=0.8, noise_level=0.0)
    duration, spans = _spans(("sil", 0.3), ("AA", 0.4), ("sil", 0.3))
    jaw_wide = _channel(
        generate_face(spans, duration, emotion="neutral", speaker=wide, seed=0), "jawOpen"
    )
    jaw_narrow = _channel(
        generate_face(spans, duration, emotion="neutral", speaker=narrow, seed=0), "jawOpen"
    )
    # The same token variation applies to both, so the peaks scale with jaw_scale.
    rest = 0.03
    peak_ratio = (jaw_wide.max() - rest) / (jaw_narrow.max() - rest)
    assert peak_ratio == pytest.approx(1.3 / 0.8, rel=0.05)


def _mean(frames: np.ndarray, name: str) -> float:
    return float(np.mean(_channel(frames, name)))


def test_emotions_change_the_face(spoken: list[tuple[float, list[PhonemeSpan]]]) -> None:
    duration, spans = spoken[1]
    faces = {
        emotion: generate_face(spans, duration, emotion=emotion, speaker=DEMO_SPEAKERS[0], seed=5)
        for emotion in EMOTIONS
    }
    neutral = faces["neutral"]
    assert _mean(faces["happy"], "mouthSmileLeft") > _mean(neutral, "mouthSmileLeft") + 0.3
    assert _mean(faces["happy"], "browOuterUpLeft") > _mean(neutral, "browOuterUpLeft") + 0.1
    assert _mean(faces["sad"], "jawOpen") < 0.85 * _mean(neutral, "jawOpen")
    assert _mean(faces["sad"], "browInnerUp") > _mean(neutral, "browInnerUp") + 0.25
    assert _mean(faces["angry"], "browDownLeft") > _mean(neutral, "browDownLeft") + 0.35
    assert _mean(faces["angry"], "mouthPressLeft") > _mean(neutral, "mouthPressLeft") + 0.15
    assert _mean(faces["angry"], "jawOpen") > _mean(neutral, "jawOpen")


def _blink_events(lid: np.ndarray, threshold: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    closed = lid > threshold
    starts = np.flatnonzero(closed[1:] & ~closed[:-1]) + 1
    ends = np.flatnonzero(~closed[1:] & closed[:-1]) + 1
    return starts, ends[ends > starts[0]][: len(starts)]


def test_blink_rate_and_duration_over_ten_minutes() -> None:
    speaker = DEMO_SPEAKERS[1]
    duration, spans = 600.0, [PhonemeSpan("sil", 0.0, 600.0)]
    frames = generate_face(spans, duration, emotion="neutral", speaker=speaker, seed=11)
    left_starts, left_ends = _blink_events(_channel(frames, "eyeBlinkLeft"))
    right_starts, _ = _blink_events(_channel(frames, "eyeBlinkRight"))
    per_minute = len(left_starts) / 10.0
    assert 15.0 - 3.0 <= per_minute <= 20.0 + 3.0
    assert abs(per_minute - speaker.blinks_per_minute) < 3.0
    assert len(right_starts) == len(left_starts)
    assert np.max(np.abs(right_starts - left_starts)) <= 2  # frames: both eyes together
    # Time above half closure is the middle part of a 100-250 ms blink.
    half_closed_s = (left_ends - left_starts[: len(left_ends)]) / FPS
    assert half_closed_s.min() >= 0.03 and half_closed_s.max() <= 0.2
    resting = np.median(_channel(frames, "eyeBlinkLeft"))
    assert resting < 0.05


def test_bad_arguments_raise() -> None:
    duration, spans = _spans(("sil", 0.2), ("AA", 0.2))
    speaker = DEMO_SPEAKERS[0]
    with pytest.raises(InvalidRequestError, match="emotion"):
        generate_face(spans, duration, emotion="bored", speaker=speaker, seed=0)
    with pytest.raises(InvalidRequestError, match="fps"):
        generate_face(spans, duration, emotion="sad", speaker=speaker, fps=0.0, seed=0)
    with pytest.raises(InvalidRequestError, match="seed"):
        generate_face(spans, duration, emotion="sad", speaker=speaker, seed=-1)
    with pytest.raises(InvalidRequestError, match="duration"):
        generate_face(spans, float("nan"), emotion="sad", speaker=speaker, seed=0)
    with pytest.raises(UnknownPhonemeError, match="spans\\[1\\]"):
        generate_face(
            [PhonemeSpan("sil", 0, 0.1), PhonemeSpan("QQ", 0.1, 0.2)],
            0.3,
            emotion="sad",
            speaker=speaker,
            seed=0,
        )
    with pytest.raises(InvalidRequestError, match="jaw_scale"):
        Speaker("bad", 1, jaw_scale=-1.0)
