"""Speech and phoneme timing from libespeak-ng (``libespeak``), in this process.

Sketch: ``libespeak`` speaks and reports (phoneme name, start ms) events;
each event starts a phoneme that lasts until the next event, and the last
one lasts until the end of the audio. Pause phonemes
(``_``, ``_:``, ...) and any gap before the first phoneme become ``sil``; the
other names go through a reader: by default ``normalize_phoneme(name,
source="espeak")`` (English mnemonics), or, for IPA names of any language,
``frontends.espeak_ipa.ipa_event_phonemes``. An event the reader makes
several phonemes (Mandarin ``ong``) shares its time equally among them; one
it makes none (a language switch, a bare length mark) lets the phoneme
before it go on.

libespeak-ng keeps global state and is not reentrant, so the process holds one
library handle behind one lock; an ``EspeakSynthesizer`` is only a voice setting
(voice, rate, pitch) applied under that lock before each utterance. Callers that
must survive a crash of the library speak in a worker process instead
(``worker.speak_in_worker``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from ..audio import Audio
from ..errors import LipstreamError, SpeechError
from ..phonemes import SILENCE, normalize_phoneme
from ..timeline import PhonemeSpan
from . import libespeak
from .libespeak import EspeakFailure, RawSpeech

EventReader = Callable[[str, str], tuple[str, ...]]
"""(espeak-ng phoneme name, where) -> the phonemes of the set it holds, in order."""

RATE_RANGE_WPM = (80, 450)
PITCH_RANGE = (0, 100)


def _check_range(value: int, bounds: tuple[int, int], where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not bounds[0] <= value <= bounds[1]:
        raise SpeechError(
            f"must be an integer in [{bounds[0]}, {bounds[1]}], got {value!r}", where=where
        )
    return value


@dataclass(frozen=True)
class EspeakSynthesizer:
    """An espeak-ng voice setting: ``voice`` name (``"en-us"``, ``"en-us+f3"``, ...),
    ``rate`` in words per minute, ``pitch`` and ``pitch_range`` in espeak's 0..100 scale.

    Instances are cheap and immutable; all share the process-wide library.
    """

    voice: str = "en-us"
    rate: int = 175
    pitch: int = 50
    pitch_range: int = 50

    def __post_init__(self) -> None:
        if not isinstance(self.voice, str) or not self.voice or "\0" in self.voice:
            raise SpeechError(f"voice must be a non-empty name, got {self.voice!r}", where="voice")
        _check_range(self.rate, RATE_RANGE_WPM, "EspeakSynthesizer.rate")
        _check_range(self.pitch, PITCH_RANGE, "EspeakSynthesizer.pitch")
        _check_range(self.pitch_range, PITCH_RANGE, "EspeakSynthesizer.pitch_range")

    def with_settings(
        self,
        *,
        voice: str | None = None,
        rate: int | None = None,
        pitch: int | None = None,
        pitch_range: int | None = None,
    ) -> EspeakSynthesizer:
        """A copy with the given settings changed (e.g. one speaker's rate and pitch)."""
        return EspeakSynthesizer(
            voice=self.voice if voice is None else voice,
            rate=self.rate if rate is None else rate,
            pitch=self.pitch if pitch is None else pitch,
            pitch_range=self.pitch_range if pitch_range is None else pitch_range,
        )

    @property
    def sample_rate(self) -> int:
        """espeak-ng's output rate in Hz (22050 for its standard voices)."""
        return _library().sample_rate

    def speak(self, text: str) -> tuple[Audio, list[PhonemeSpan]]:
        """Synthesize ``text``: mono float32 audio and contiguous spans covering it.

        The spans run from 0 to ``audio.duration`` seconds without gaps. The
        library carries a little state from one utterance to the next (its
        pitch-flutter phase), so repeating a request in one process may move
        samples and boundaries slightly; ``demo.speech_batch.speak_batch`` gives
        output that depends on its requests alone.
        """
        return speech_result(text, *self.raw_speech(text))

    def raw_speech(self, text: str) -> RawSpeech:
        """espeak-ng's own output for ``text``: PCM16 bytes, sample rate, (name, ms) events."""
        check_text(text)
        library = _library()
        try:
            return library.speak(self.voice, self.rate, self.pitch, self.pitch_range, text)
        except EspeakFailure as exc:
            raise SpeechError(exc.message, where=exc.where) from None


def _library() -> libespeak.Library:
    try:
        return libespeak.shared_library()
    except EspeakFailure as exc:
        raise SpeechError(exc.message, where=exc.where) from None


def check_text(text: str) -> None:
    """Text espeak-ng can speak: a non-empty string without NUL characters."""
    if not isinstance(text, str) or not text.strip():
        raise SpeechError("text to speak must be a non-empty string", where="speak")
    if "\0" in text:
        raise SpeechError("text to speak must not contain NUL characters", where="speak")


def speech_result(
    text: str,
    pcm: bytes,
    sample_rate: int,
    events: Sequence[tuple[str, int]],
    read: EventReader | None = None,
) -> tuple[Audio, list[PhonemeSpan]]:
    """Audio and contiguous spans from espeak-ng's raw output for ``text`` (``read``:
    how event names become phonemes; default English mnemonics)."""
    audio = Audio.from_pcm16(pcm, sample_rate)
    if audio.duration <= 0 or not events:
        raise SpeechError(f"espeak-ng produced no speech for {text!r}", where="speak")
    starts = [(name, position_ms / 1000.0) for name, position_ms in events]
    return audio, phoneme_spans(starts, audio.duration, where=f"speak({text!r})", read=read)


def read_mnemonic(name: str, where: str) -> tuple[str, ...]:
    """An English mnemonic event's phoneme; pauses are silence, a language switch none."""
    if not name or name.startswith("_"):
        return (SILENCE,)
    if name.startswith("(") and name.endswith(")"):
        return ()
    try:
        return (normalize_phoneme(name, source="espeak", where=where),)
    except LipstreamError as exc:
        raise SpeechError(
            f"espeak-ng phoneme {name!r} has no ARPAbet label: {exc.message}", where=where
        ) from None


def phoneme_spans(
    events: Sequence[tuple[str, float]],
    duration_s: float,
    *,
    where: str = "espeak",
    read: EventReader | None = None,
) -> list[PhonemeSpan]:
    """Contiguous spans over [0, ``duration_s``] from (espeak name, start s) events.

    Each event lasts until the next one that holds a phoneme; events past the
    end are dropped, a gap before the first becomes silence, an event of several
    phonemes shares its time equally, and touching repeats merge.
    """
    reader = read or read_mnemonic
    raw = sorted(events, key=lambda event: event[1])
    raw_ends = [start for _, start in raw[1:]] + [duration_s]
    ordered: list[tuple[tuple[str, ...], float]] = []
    for (name, start), raw_end in zip(raw, raw_ends):
        if min(raw_end, duration_s) <= start:
            continue  # an instant (a language switch, or past the end) holds no phoneme
        phonemes = reader(name, where)
        if phonemes:
            ordered.append((phonemes, start))
    spans: list[PhonemeSpan] = []
    starts = [min(max(start, 0.0), duration_s) for _, start in ordered]
    ends = starts[1:] + [duration_s]
    if starts and starts[0] > 0.0:
        spans.append(PhonemeSpan(SILENCE, 0.0, starts[0]))
    for (phonemes, _), start, end in zip(ordered, starts, ends):
        if end <= start:
            continue
        step = (end - start) / len(phonemes)
        for index, label in enumerate(phonemes):
            piece_start = start + index * step
            piece_end = end if index == len(phonemes) - 1 else start + (index + 1) * step
            _append(spans, label, piece_start, piece_end)
    if not spans:
        return [PhonemeSpan(SILENCE, 0.0, duration_s)]
    return spans


def _append(spans: list[PhonemeSpan], label: str, start: float, end: float) -> None:
    if spans and label == SILENCE and spans[-1].phoneme == SILENCE:
        spans[-1] = PhonemeSpan(SILENCE, spans[-1].start, end)
    else:
        spans.append(PhonemeSpan(label, start, end))
