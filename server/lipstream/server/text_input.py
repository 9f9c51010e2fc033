"""A request's ``text`` message: the server speaks it and feeds the engine what it said.

Sketch: ``speak`` runs the text front end (espeak-ng in a worker process, so a
failure ends this request only) and turns its coded errors into request
errors. The speech starts where the request's input so far ends (the later of
its phonemes' and its audio's end, 0 for the first input). ``speech_messages``
cuts the PCM16 into ``audio`` messages of at most ``AUDIO_CHUNK_S`` with their
``start`` on the utterance clock, sent before the frames they drive, so a
client can schedule sound and face on one clock. ``engine_audio`` is the same
speech for the engine, preceded by silence where the request's audio stopped
short of the speech's start (audio is contiguous from 0), and ``speech_spans``
espeak-ng's spans moved to the speech's start, already canonical phonemes: the
request hands both to the engine in one call (``ActiveRequest.add_speech``), so
an engine that can hear and read (``hmm``) is driven by both.
"""

from __future__ import annotations

import numpy as np

from lipstream_client import AudioChunk, Text
from lipstream_client.errors import TEXT_TOO_LONG
from lipstream_client.messages import JsonValue

from ..audio import Audio
from ..errors import LipstreamError, UnmappedPhonemeError
from ..speech.text_frontend import MAX_TEXT_CHARS, SpokenText, speak_text
from ..timeline import PhonemeSpan
from .outgoing import Outgoing
from .request import ActiveRequest, RequestError

AUDIO_CHUNK_S = 0.5
_PCM16_BYTES = 2


def speak(message: Text) -> SpokenText:
    """espeak-ng's speech for ``message``; a ``RequestError`` with the front end's code."""
    try:
        return speak_text(message.text, message.voice, message.rate, lang=message.lang)
    except LipstreamError as error:
        details: dict[str, JsonValue] | None = None
        if error.code == TEXT_TOO_LONG:
            details = {"max_text_chars": MAX_TEXT_CHARS}
        elif isinstance(error, UnmappedPhonemeError):
            details = {"phoneme": error.phoneme, "lang": error.lang}
        raise RequestError(
            error.message, code=error.code, where=error.where, details=details
        ) from None


def speech_start(request: ActiveRequest) -> float:
    """Where new speech begins on the request's clock: the end of its input so far."""
    return max(request.phonemes_end, request.audio_s)


def speech_messages(request: ActiveRequest, speech: SpokenText, start: float) -> list[Outgoing]:
    """The speech as ``audio`` messages of at most ``AUDIO_CHUNK_S``, each with its start."""
    rate = speech.sample_rate
    step = max(1, round(AUDIO_CHUNK_S * rate)) * _PCM16_BYTES
    pcm = speech.pcm16
    return [
        Outgoing(
            AudioChunk(request.id, rate, pcm[offset : offset + step], start + offset / 2 / rate),
            request.spec.clock,
        )
        for offset in range(0, len(pcm) - len(pcm) % _PCM16_BYTES, step)
    ]


def engine_audio(request: ActiveRequest, speech: SpokenText, start: float) -> Audio:
    """The speech as the request's next audio input, with silence before it where the
    request's audio ends before ``start``."""
    gap = max(0, round((start - request.audio_s) * speech.sample_rate))
    samples = np.asarray(speech.audio.samples, dtype=np.float32)
    if gap:
        samples = np.concatenate([np.zeros(gap, dtype=np.float32), samples])
    return Audio(samples, speech.sample_rate)


def speech_spans(speech: SpokenText, start: float) -> list[PhonemeSpan]:
    """espeak-ng's spans (canonical phonemes), contiguous from ``start``."""
    return [
        PhonemeSpan(span.phoneme, start + span.start, start + span.end) for span in speech.spans
    ]
