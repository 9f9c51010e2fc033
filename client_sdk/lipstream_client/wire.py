"""Typed messages to plain wire payloads (the inverse of ``validate``).

Sketch: every message becomes a map with ``v`` and ``type`` first and then
its fields under their wire names. Optional fields that are None, and
free-form maps that are empty, are left out (absent and null mean the same
on the wire), except ``error.id``, which is always present and null for
connection-level errors. An empty ``output`` profile is sent as ``{}``: it
differs from no profile (the character's preset). Binary fields differ by
encoding: msgpack carries ``bytes`` as ``bin``; JSON carries frame data as
nested lists of the shortest decimals that round to the same float32, and
PCM16 audio as base64 text.
"""

from __future__ import annotations

import base64
from collections.abc import Callable
from typing import Any

from .float32 import shortest_float32, split_rows, unpack_float32
from .messages import (
    AudioChunk,
    Cancel,
    ChannelTransform,
    Done,
    DoneStats,
    Encoding,
    End,
    ErrorMessage,
    Frames,
    Interrupt,
    Message,
    OutputProfile,
    PhonemeItem,
    Phonemes,
    Ready,
    Resume,
    Start,
    Text,
    Words,
)

Payload = dict[str, Any]


def message_to_wire(message: Message, encoding: Encoding) -> Payload:
    """The plain map that the msgpack or JSON serializer writes for ``message``."""
    fields = _ENCODERS[message.type](message, encoding)
    payload: Payload = {"v": message.v, "type": message.type}
    payload.update(fields)
    return payload


def _compact(fields: Payload, keep_null: tuple[str, ...] = ()) -> Payload:
    return {key: value for key, value in fields.items() if key in keep_null or value is not None}


def _start(message: Start, encoding: Encoding) -> Payload:
    return _compact(
        {
            "id": message.id,
            "engine": message.engine,
            "character": message.character,
            "fps": message.fps,
            "channels": list(message.channels) if message.channels is not None else None,
            "output": _output(message.output) if message.output is not None else None,
            "emotion": message.emotion,
            "latency_budget_ms": message.latency_budget_ms,
            "options": dict(message.options) or None,
            "phoneme_source": message.phoneme_source,
            "resume": _resume(message.resume) if message.resume is not None else None,
        }
    )


def _resume(resume: Resume) -> Payload:
    fields = {"frames": resume.frames, "seq": resume.seq, "fidelity": resume.fidelity}
    return _compact({**fields, "audio": resume.audio or None})  # 0, the default: left out


def _output(profile: OutputProfile) -> Payload:
    return _compact(
        {
            "naming": profile.naming,
            "channels": list(profile.channels) if profile.channels is not None else None,
            "transforms": {name: _transform(spec) for name, spec in profile.transforms.items()}
            or None,
            "visemes": profile.visemes,
            "retarget": profile.retarget,
        }
    )


def _transform(spec: ChannelTransform) -> Payload:
    return _compact(
        {
            "multiplier": spec.multiplier,
            "offset": spec.offset,
            "clamp": list(spec.clamp) if spec.clamp is not None else None,
        }
    )


def _phonemes(message: Phonemes, encoding: Encoding) -> Payload:
    return {"id": message.id, "items": [_item(item) for item in message.items]}


def _item(item: PhonemeItem) -> Payload:
    return _compact(
        {"phoneme": item.phoneme, "start": item.start, "end": item.end, "emotion": item.emotion}
    )


def _audio(message: AudioChunk, encoding: Encoding) -> Payload:
    pcm: bytes | str = (
        message.pcm16 if encoding == "msgpack" else base64.b64encode(message.pcm16).decode("ascii")
    )
    return _compact(
        {"id": message.id, "sample_rate": message.sample_rate, "pcm16": pcm, "start": message.start}
    )


def _text(message: Text, encoding: Encoding) -> Payload:
    return _compact(
        {
            "id": message.id,
            "text": message.text,
            "voice": message.voice,
            "rate": message.rate,
            "lang": message.lang,
        }
    )


def _words(message: Words, encoding: Encoding) -> Payload:
    return _compact(
        {
            "id": message.id,
            "timings": message.timings,
            "format": None if message.format == "auto" else message.format,
            "offset": message.offset or None,
            "voice": message.voice,
        }
    )


def _end(message: End, encoding: Encoding) -> Payload:
    return {"id": message.id}


def _cancel(message: Cancel, encoding: Encoding) -> Payload:
    return {"id": message.id}


def _interrupt(message: Interrupt, encoding: Encoding) -> Payload:
    return _compact({"id": message.id, "at": message.at, "return_ms": message.return_ms})


def _ready(message: Ready, encoding: Encoding) -> Payload:
    return _compact(
        {
            "id": message.id,
            "engine": message.engine,
            "character": message.character,
            "fps": message.fps,
            "channels": list(message.channels),
            "lookahead_ms": message.lookahead_ms,
            "fidelity": message.fidelity,
            "emotion": message.emotion,
            "latency_budget_ms": message.latency_budget_ms,
            "options": dict(message.options) or None,
            "phoneme_source": message.phoneme_source,
        }
    )


def _frames(message: Frames, encoding: Encoding) -> Payload:
    data: bytes | list[list[float]] = (
        message.data
        if encoding == "msgpack"
        else split_rows(
            [shortest_float32(value) for value in unpack_float32(message.data)], message.n_channels
        )
    )
    return {
        "id": message.id,
        "seq": message.seq,
        "first_frame": message.first_frame,
        "fps": message.fps,
        "n_channels": message.n_channels,
        "data": data,
    }


def _done(message: Done, encoding: Encoding) -> Payload:
    return {"id": message.id, "reason": message.reason, "stats": _stats(message.stats)}


def _stats(stats: DoneStats) -> Payload:
    return _compact(
        {
            "frames": stats.frames,
            "first_frame_latency_ms": stats.first_frame_latency_ms,
            "max_lag_ms": stats.max_lag_ms,
            "budget_met": stats.budget_met,
            "speech_synthesis_ms": stats.speech_synthesis_ms,
            "engine": dict(stats.engine) or None,
        }
    )


def _error(message: ErrorMessage, encoding: Encoding) -> Payload:
    return _compact(
        {
            "code": message.code,
            "message": message.message,
            "id": message.id,
            "fatal": message.fatal,
            "details": dict(message.details) or None,
        },
        keep_null=("id",),
    )


_ENCODERS: dict[str, Callable[[Any, Encoding], Payload]] = {
    "start": _start,
    "phonemes": _phonemes,
    "audio": _audio,
    "text": _text,
    "words": _words,
    "end": _end,
    "cancel": _cancel,
    "interrupt": _interrupt,
    "ready": _ready,
    "frames": _frames,
    "done": _done,
    "error": _error,
}
