"""The text front end: text in, speech audio and the phoneme spans espeak-ng spoke out.

Sketch: the text is checked (not empty, at most ``MAX_TEXT_CHARS`` characters,
no NUL), spoken by espeak-ng in a worker process (``worker``: a crash or a
hang is an error for this text only) and its phoneme events become contiguous
spans of the phoneme set over [0, duration] (``espeak.speech_result``). Every
failure is a ``LipstreamError`` whose code the protocol lists: ``empty_text``,
``text_too_long``, ``unspeakable_text`` (espeak-ng said nothing, or a phoneme
the set lacks), ``invalid_request`` (an unknown voice) and ``speech_failed``
(espeak-ng failed).
"""

from __future__ import annotations

from dataclasses import dataclass

from lipstream_client.errors import (
    EMPTY_TEXT,
    INVALID_REQUEST,
    SPEECH_FAILED,
    TEXT_TOO_LONG,
    UNSPEAKABLE_TEXT,
)

from ..audio import Audio
from ..errors import LipstreamError, SpeechError
from ..phonemes import SILENCE
from ..timeline import PhonemeSpan
from .espeak import RATE_RANGE_WPM, speech_result
from .worker import SpeechRequest, speak_in_worker

MAX_TEXT_CHARS = 1000
DEFAULT_VOICE = "en-us"
DEFAULT_RATE_WPM = 175
SPEECH_TIMEOUT_S = 20.0


@dataclass(frozen=True)
class SpokenText:
    """What espeak-ng said for a text: PCM16 mono bytes at ``sample_rate`` Hz, the same
    audio as floats, and contiguous spans over [0, ``audio.duration``]."""

    pcm16: bytes
    sample_rate: int
    audio: Audio
    spans: list[PhonemeSpan]


def check_text(text: str) -> str:
    """``text`` if espeak-ng may be asked to speak it, else a coded ``LipstreamError``."""
    if not text.strip():
        raise LipstreamError("there is no text to speak", where="text", code=EMPTY_TEXT)
    if len(text) > MAX_TEXT_CHARS:
        raise LipstreamError(
            f"{len(text)} characters; the text front end speaks at most {MAX_TEXT_CHARS}",
            where="text",
            code=TEXT_TOO_LONG,
        )
    if "\0" in text:
        raise LipstreamError(
            "contains a NUL character, which espeak-ng cannot speak",
            where="text",
            code=UNSPEAKABLE_TEXT,
        )
    return text


def speak_text(
    text: str,
    voice: str | None = None,
    rate: int | None = None,
    timeout_s: float = SPEECH_TIMEOUT_S,
) -> SpokenText:
    """Speak ``text`` with espeak-ng (``voice`` default en-us, ``rate`` in words per minute,
    default 175) in a worker process; coded errors as the module says."""
    check_text(text)
    rate = DEFAULT_RATE_WPM if rate is None else rate
    low, high = RATE_RANGE_WPM
    if isinstance(rate, bool) or not isinstance(rate, int) or not low <= rate <= high:
        raise LipstreamError(
            f"must be an integer in [{low}, {high}] words per minute, got {rate!r}",
            where="rate",
            code=INVALID_REQUEST,
        )
    request = SpeechRequest(text, voice or DEFAULT_VOICE, rate)
    try:
        pcm, sample_rate, events = speak_in_worker([request], timeout_s)[0]
    except SpeechError as error:
        if "no voice" in error.message:
            raise LipstreamError(error.message, where="voice", code=INVALID_REQUEST) from None
        raise LipstreamError(error.message, where=error.where, code=SPEECH_FAILED) from None
    try:
        audio, spans = speech_result(text, pcm, sample_rate, events)
    except SpeechError as error:
        raise LipstreamError(error.message, where="text", code=UNSPEAKABLE_TEXT) from None
    if all(span.phoneme == SILENCE for span in spans):
        raise LipstreamError(
            f"espeak-ng spoke no sound for {_clipped(text)!r}", where="text", code=UNSPEAKABLE_TEXT
        )
    return SpokenText(pcm, sample_rate, audio, spans)


def _clipped(text: str, length: int = 40) -> str:
    return text if len(text) <= length else text[: length - 3] + "..."
