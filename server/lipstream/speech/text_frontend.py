"""The text front end: text in, speech audio and the phoneme spans espeak-ng spoke out.

Sketch: the text is checked (not empty, at most ``MAX_TEXT_CHARS`` characters,
no NUL), spoken by espeak-ng in a worker process (``worker``: a crash or a
hang is an error for this text only) and its phoneme events become contiguous
spans of the phoneme set over [0, duration] (``espeak.speech_result``). Every
failure is a ``LipstreamError`` whose code the protocol lists: ``empty_text``,
``text_too_long``, ``unspeakable_text`` (espeak-ng said nothing, or a phoneme
the set lacks), ``invalid_request`` (an unknown voice), ``unknown_language``,
``unmapped_phoneme`` and ``speech_failed`` (espeak-ng failed).

The language: ``lang`` names one of espeak-ng's languages
(``frontends.espeak_languages``) and ``voice`` then one of its voice
variants (``f3``, ``klatt``); without ``lang``, ``voice`` is a whole espeak-ng
voice name as before (``en-us+f3``), and its language part, if espeak-ng
lists it, is the language. English is read from espeak-ng's English
mnemonics (the table the demo corpus was built with); every other language
from espeak-ng's IPA names, mapped by articulatory features
(``frontends.espeak_ipa``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

from lipstream_client.errors import (
    EMPTY_TEXT,
    INVALID_REQUEST,
    SPEECH_FAILED,
    TEXT_TOO_LONG,
    UNSPEAKABLE_TEXT,
)

from ..audio import Audio
from ..errors import LipstreamError, SpeechError
from ..frontends.espeak_ipa import ipa_event_phonemes
from ..frontends.espeak_languages import find_language, resolve_language, resolve_variant
from ..phonemes import SILENCE
from ..timeline import PhonemeSpan
from .espeak import RATE_RANGE_WPM, EventReader, read_mnemonic, speech_result
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


@dataclass(frozen=True)
class VoiceChoice:
    """What espeak-ng is asked for: the ``voice`` name it loads, the ``lang`` it speaks
    (None: a voice espeak-ng does not list by language) and whether its phoneme names
    are read as IPA."""

    voice: str
    lang: str | None
    ipa_names: bool


def choose_voice(voice: str | None, lang: str | None) -> VoiceChoice:
    """The espeak-ng voice for a request's ``voice`` and ``lang`` (see the module)."""
    if lang is not None:
        language = resolve_language(lang)
        variant = None if voice is None else resolve_variant(voice)
        return VoiceChoice(language.voice(variant), language.code, not language.english)
    name = voice or DEFAULT_VOICE
    listed = find_language(name.split("+", 1)[0])
    if listed is None or listed.english:
        return VoiceChoice(name, None if listed is None else listed.code, False)
    return VoiceChoice(name, listed.code, True)


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
    lang: str | None = None,
) -> SpokenText:
    """Speak ``text`` with espeak-ng (``lang`` an espeak-ng language, ``voice`` default
    en-us, ``rate`` in words per minute, default 175) in a worker process; coded errors
    as the module says."""
    check_text(text)
    choice = choose_voice(voice, lang)
    rate = DEFAULT_RATE_WPM if rate is None else rate
    low, high = RATE_RANGE_WPM
    if isinstance(rate, bool) or not isinstance(rate, int) or not low <= rate <= high:
        raise LipstreamError(
            f"must be an integer in [{low}, {high}] words per minute, got {rate!r}",
            where="rate",
            code=INVALID_REQUEST,
        )
    request = SpeechRequest(text, choice.voice, rate, ipa_names=choice.ipa_names)
    try:
        pcm, sample_rate, events = speak_in_worker([request], timeout_s)[0]
    except SpeechError as error:
        if "no voice" in error.message:
            raise LipstreamError(error.message, where="voice", code=INVALID_REQUEST) from None
        raise LipstreamError(error.message, where=error.where, code=SPEECH_FAILED) from None
    read = event_reader(choice)
    try:
        audio, spans = speech_result(text, pcm, sample_rate, events, read)
    except SpeechError as error:
        raise LipstreamError(error.message, where="text", code=UNSPEAKABLE_TEXT) from None
    if all(span.phoneme == SILENCE for span in spans):
        raise LipstreamError(
            f"espeak-ng spoke no sound for {_clipped(text)!r}", where="text", code=UNSPEAKABLE_TEXT
        )
    return SpokenText(pcm, sample_rate, audio, spans)


def event_reader(choice: VoiceChoice, where: str = "text") -> EventReader:
    """How the phoneme events of ``choice`` become phonemes: English mnemonics, or IPA
    read through the feature table (an unmapped one names ``where``)."""
    if not choice.ipa_names:
        return read_mnemonic
    return partial(_read_ipa_event, lang=choice.lang or choice.voice, at=where)


def _read_ipa_event(name: str, where: str, *, lang: str, at: str) -> tuple[str, ...]:
    return ipa_event_phonemes(name, lang, where=at)


def _clipped(text: str, length: int = 40) -> str:
    return text if len(text) <= length else text[: length - 3] + "..."
