"""espeak-ng through ctypes: audio, phoneme spans, timing against energy, errors."""

from __future__ import annotations

import ctypes
import threading
from itertools import pairwise
from typing import TypedDict

import numpy as np
import pytest

from lipstream.demo.speech_batch import speak_batch
from lipstream.errors import SpeechError
from lipstream.speech import libespeak
from lipstream.speech.espeak import EspeakSynthesizer, phoneme_spans
from lipstream.timeline import PhonemeSpan


class VoiceSettings(TypedDict, total=False):
    """The synthesizer settings a test sets out of range."""

    voice: str
    rate: int
    pitch: int


VOWELS = {"AA", "AE", "AH", "AO", "AW", "AY", "EH", "ER", "EY", "IH", "IY", "OW", "OY", "UH", "UW"}


def _labels(spans: list[PhonemeSpan]) -> list[str]:
    return [span.phoneme for span in spans]


def _contains_in_order(labels: list[str], wanted: list[str]) -> bool:
    text = " " + " ".join(labels) + " "
    return " " + " ".join(wanted) + " " in text


def _rms(audio_samples: np.ndarray, rate: int, span: PhonemeSpan) -> float:
    piece = audio_samples[int(span.start * rate) : int(span.end * rate)]
    return float(np.sqrt(np.mean(piece.astype(np.float64) ** 2)))


def test_event_struct_matches_the_lp64_header_layout() -> None:
    # speak_lib.h: six 4-byte ints, a pointer at offset 24, the 8-byte union at 32.
    assert ctypes.sizeof(libespeak.Event) == 40
    assert libespeak.Event.user_data.offset == 24
    assert libespeak.Event.id.offset == 32


def test_word_map_gives_m_ae_p_and_plausible_audio() -> None:
    audio, spans = EspeakSynthesizer().speak("map")
    assert audio.sample_rate == 22050
    assert audio.samples.dtype == np.float32
    assert 0.25 < audio.duration < 1.2
    assert _contains_in_order(
        [label for label in _labels(spans) if label != "sil"], ["M", "AE", "P"]
    )


def test_known_sentence_phonemes() -> None:
    _, spans = EspeakSynthesizer().speak("She sees two cats.")
    speech = [label for label in _labels(spans) if label != "sil"]
    assert speech == ["SH", "IY", "S", "IY", "Z", "T", "UW", "K", "AE", "T", "S"]


def test_spans_cover_the_audio_contiguously() -> None:
    audio, spans = EspeakSynthesizer().speak("Please book a table for four at noon.")
    assert spans[0].start == 0.0
    assert spans[-1].end == pytest.approx(audio.duration, abs=1e-12)
    for before, after in pairwise(spans):
        assert after.start == before.end
        assert after.end > after.start
        assert not (before.phoneme == "sil" and after.phoneme == "sil")


def test_silence_spans_are_quiet_and_vowels_loud() -> None:
    audio, spans = EspeakSynthesizer().speak("Map the house. Then he saw two boats.")
    interior_silences = [
        span for span in spans[1:-1] if span.phoneme == "sil" and span.duration > 0.05
    ]
    vowels = [span for span in spans if span.phoneme in VOWELS]
    assert interior_silences, "the full stop should make a pause"
    quiet = max(_rms(audio.samples, audio.sample_rate, span) for span in interior_silences)
    loud = np.median([_rms(audio.samples, audio.sample_rate, span) for span in vowels])
    assert quiet < 0.01
    assert loud > 0.04
    assert loud > 10 * quiet


def test_rate_changes_duration_and_pitch_keeps_phonemes() -> None:
    text = "The quick brown fox jumps over the lazy dog."
    slow_audio, _ = EspeakSynthesizer(rate=120).speak(text)
    fast_audio, _ = EspeakSynthesizer(rate=240).speak(text)
    assert slow_audio.duration > 1.5 * fast_audio.duration
    low_audio, low_spans = EspeakSynthesizer(pitch=20).speak(text)
    high_audio, high_spans = EspeakSynthesizer().with_settings(pitch=80).speak(text)
    assert _labels(low_spans) == _labels(high_spans)
    assert not np.array_equal(low_audio.samples, high_audio.samples)


def test_concurrent_requests_are_serialized_and_complete() -> None:
    synthesizer = EspeakSynthesizer(voice="en-us+f3", rate=160, pitch=55)
    reference_audio, reference_spans = synthesizer.speak("Hold your breath and dive.")
    results: list[tuple[float, list[PhonemeSpan]]] = []

    def worker() -> None:
        audio, spans = synthesizer.speak("Hold your breath and dive.")
        results.append((audio.duration, spans))

    threads = [threading.Thread(target=worker) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(results) == 4
    for duration, spans in results:
        # Same utterance up to espeak's carried-over pitch flutter (a few samples).
        assert duration == pytest.approx(reference_audio.duration, abs=0.005)
        assert _labels(spans) == _labels(reference_spans)
        for span, reference in zip(spans, reference_spans):
            assert span.start == pytest.approx(reference.start, abs=0.005)


def test_batch_speech_is_reproducible_whatever_was_spoken_before() -> None:
    requests = [
        (EspeakSynthesizer(voice="en-us+m3", rate=150), "The boy found a coin."),
        (EspeakSynthesizer(pitch=70), "The boy found a coin."),
    ]
    first = speak_batch(requests)
    EspeakSynthesizer().speak("Something else entirely, to move the library state.")
    second = speak_batch(requests)
    for (audio_a, spans_a), (audio_b, spans_b) in zip(first, second):
        assert audio_a.samples.tobytes() == audio_b.samples.tobytes()
        assert spans_a == spans_b
    assert _labels(first[0][1]) == _labels(first[1][1])
    assert first[0][0].duration > first[1][0].duration  # 150 wpm against the default 175


def test_batch_reports_bad_voice_as_speech_error() -> None:
    with pytest.raises(SpeechError, match="no voice"):
        speak_batch([(EspeakSynthesizer(voice="xx-nonexistent"), "hello")])
    assert speak_batch([]) == []


def test_phoneme_spans_from_hand_made_events() -> None:
    events = [("m", 0.05), ("a", 0.12), ("_:", 0.30), ("_", 0.35), ("p", 0.9)]
    assert phoneme_spans(events, 0.5) == [
        PhonemeSpan("sil", 0.0, 0.05),
        PhonemeSpan("M", 0.05, 0.12),
        PhonemeSpan("AE", 0.12, 0.30),
        PhonemeSpan("sil", 0.30, 0.5),
    ]


def test_phoneme_spans_drop_zero_length_events() -> None:
    events = [("_", 0.0), ("t", 0.0), ("u:", 0.1)]
    assert phoneme_spans(events, 0.3) == [PhonemeSpan("T", 0.0, 0.1), PhonemeSpan("UW", 0.1, 0.3)]


def test_unknown_espeak_name_is_a_speech_error() -> None:
    with pytest.raises(SpeechError, match="no ARPAbet label"):
        phoneme_spans([("%%", 0.0)], 0.2)


@pytest.mark.parametrize(
    ("settings", "where"),
    [({"rate": 10}, "rate"), ({"pitch": 101}, "pitch"), ({"voice": ""}, "voice")],
)
def test_bad_settings_raise(settings: VoiceSettings, where: str) -> None:
    with pytest.raises(SpeechError) as raised:
        EspeakSynthesizer(**settings)
    assert where in str(raised.value.where)


def test_unknown_voice_and_empty_text_raise() -> None:
    with pytest.raises(SpeechError, match="no voice"):
        EspeakSynthesizer(voice="xx-nonexistent").speak("hello")
    with pytest.raises(SpeechError, match="non-empty"):
        EspeakSynthesizer().speak("   ")


def test_missing_library_names_the_debian_package(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(libespeak, "LIBRARY_NAME", "libespeak-ng-missing.so.9")
    monkeypatch.setattr(libespeak, "_library", None)
    with pytest.raises(SpeechError, match="install the Debian package espeak-ng") as raised:
        EspeakSynthesizer().speak("hello")
    assert raised.value.code == "speech_failed"
