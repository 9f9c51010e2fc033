"""Hand-written structural validation of decoded payloads, matching ``schemas/*.json``.

Sketch: ``message_from_wire`` checks the envelope (an object with ``v`` and
``type``), then the message's own fields with the readers of ``_fields``,
and builds the typed message. It checks structure only: that names exist
in the loaded models and that times continue across messages is the
server's job. A few rules go beyond what JSON Schema can say, and are
listed in ``docs/reference/protocol.md``: phoneme ``end`` > ``start`` and no overlap
within a message, ``clamp`` low <= high, frame rows of ``n_channels``
finite float32 values, PCM16 of even length, and the depth and 64-bit
integer limits of free-form maps.
"""

from __future__ import annotations

import math
import re
import struct
from collections.abc import Callable, Mapping
from typing import Any, TypeGuard, cast

from ._fields import (
    ERROR_CODE,
    InvalidField,
    child,
    present,
    read_base64,
    read_bool,
    read_bytes,
    read_choice,
    read_integer,
    read_json_map,
    read_names,
    read_number,
    read_object,
    read_text,
    require_utf8,
)
from .errors import (
    INVALID_AUDIO,
    INVALID_FRAMES,
    INVALID_MESSAGE,
    INVALID_TIMES,
    NON_MONOTONIC_TIMES,
    UNKNOWN_TYPE,
    UNSUPPORTED_VERSION,
)
from .float32 import FLOAT32_BYTES, all_finite_float32, pack_float32
from .messages import (
    CLIENT_MESSAGE_TYPES,
    DEFAULT_FPS,
    DONE_REASONS,
    MAX_CHANNELS,
    MAX_EMOTION_LENGTH,
    MAX_ERROR_CODE_LENGTH,
    MAX_ERROR_MESSAGE_LENGTH,
    MAX_FPS,
    MAX_ID_LENGTH,
    MAX_LATENCY_BUDGET_MS,
    MAX_NAME_LENGTH,
    MAX_PHONEME_LENGTH,
    MAX_PHONEME_SOURCE_LENGTH,
    MAX_RATE_WPM,
    MAX_RETURN_MS,
    MAX_SAMPLE_RATE,
    MAX_SEQ,
    MAX_TIME_S,
    MAX_VOICE_LENGTH,
    MIN_FPS,
    MIN_RATE_WPM,
    MIN_SAMPLE_RATE,
    NAMINGS,
    PCM16_BYTES,
    PROTOCOL_VERSION,
    SERVER_MESSAGE_TYPES,
    TIMING_FORMATS,
    VISEME_SETS,
    AudioChunk,
    Cancel,
    ChannelTransform,
    Done,
    DoneReason,
    DoneStats,
    Encoding,
    End,
    ErrorMessage,
    Frames,
    Interrupt,
    Message,
    Naming,
    OutputProfile,
    PhonemeItem,
    Phonemes,
    Ready,
    Resume,
    Sender,
    Start,
    Text,
    VisemeSet,
    Words,
)

ENVELOPE = ("v", "type")
TIME_TOLERANCE_S = 1e-9


_VOICE = re.compile(r"[A-Za-z0-9_.+-]+")


def message_id(payload: object) -> str | None:
    """The request id of a payload, if it has a well-formed one."""
    if isinstance(payload, dict):
        candidate = payload.get("id")
        try:
            return read_text(candidate, "id", MAX_ID_LENGTH)
        except InvalidField:
            return None
    return None


def message_from_wire(payload: object, encoding: Encoding, sender: Sender | None) -> Message:
    """The typed message for a decoded payload; ``InvalidField`` names the first broken rule.

    ``sender`` restricts the accepted types to what that side may send.
    """
    if type(payload) is dict and payload.get("type") == "phonemes" and sender != "server":
        plain = plain_phonemes(payload)
        if plain is not None:  # every message a streaming client sends but a few
            return plain
    if not isinstance(payload, dict):
        raise InvalidField(
            INVALID_MESSAGE, None, "a message must be an object (a msgpack map or JSON object)"
        )
    _check_version(payload)
    message_type = payload.get("type")
    if not isinstance(message_type, str):
        raise InvalidField(INVALID_MESSAGE, "type", "must be a string naming the message type")
    parser = _PARSERS.get(message_type)
    if parser is None:
        raise InvalidField(UNKNOWN_TYPE, "type", f"unknown message type {message_type[:64]!r}")
    allowed = _ALLOWED_TYPES[sender] if sender else _PARSERS
    if message_type not in allowed:
        raise InvalidField(UNKNOWN_TYPE, "type", f"a {sender} may not send {message_type!r}")
    return parser(payload, encoding)


def _check_version(payload: Mapping[str, Any]) -> None:
    if "v" not in payload:
        raise InvalidField(INVALID_MESSAGE, None, "missing field 'v' (protocol version)")
    version = payload["v"]
    if isinstance(version, bool) or not isinstance(version, (int, float)):
        raise InvalidField(INVALID_MESSAGE, "v", "must be the protocol version number")
    if version != PROTOCOL_VERSION:
        raise InvalidField(
            UNSUPPORTED_VERSION,
            "v",
            f"protocol version {version!r} is not supported; this peer speaks {PROTOCOL_VERSION}",
        )


def _object(
    payload: Mapping[str, Any], required: tuple[str, ...], optional: tuple[str, ...] = ()
) -> dict[str, Any]:
    return read_object(payload, "", ENVELOPE + required, optional)


def _id(obj: Mapping[str, Any]) -> str:
    return read_text(obj["id"], "id", MAX_ID_LENGTH)


def _optional_text(obj: Mapping[str, Any], key: str, where: str, max_length: int) -> str | None:
    return read_text(obj[key], child(where, key), max_length) if present(obj, key) else None


def _optional_number(obj: Mapping[str, Any], key: str, **bounds: Any) -> float | None:
    return read_number(obj[key], key, **bounds) if present(obj, key) else None


def _start(payload: Mapping[str, Any], encoding: Encoding) -> Start:
    obj = _object(
        payload,
        ("id", "engine", "character"),
        (
            "fps",
            "channels",
            "output",
            "emotion",
            "latency_budget_ms",
            "options",
            "phoneme_source",
            "resume",
        ),
    )
    if present(obj, "channels") and present(obj, "output"):
        raise InvalidField(INVALID_MESSAGE, None, "give either 'channels' or 'output', not both")
    return Start(
        id=_id(obj),
        engine=read_text(obj["engine"], "engine", MAX_NAME_LENGTH),
        character=read_text(obj["character"], "character", MAX_NAME_LENGTH),
        fps=read_number(obj["fps"], "fps", minimum=MIN_FPS, maximum=MAX_FPS)
        if present(obj, "fps")
        else DEFAULT_FPS,
        channels=read_names(obj["channels"], "channels", MAX_CHANNELS)
        if present(obj, "channels")
        else None,
        output=_output(obj["output"]) if present(obj, "output") else None,
        emotion=_optional_text(obj, "emotion", "", MAX_EMOTION_LENGTH),
        latency_budget_ms=_optional_number(
            obj, "latency_budget_ms", above=0.0, maximum=MAX_LATENCY_BUDGET_MS
        ),
        options=read_json_map(obj["options"], "options") if present(obj, "options") else {},
        phoneme_source=_optional_text(obj, "phoneme_source", "", MAX_PHONEME_SOURCE_LENGTH),
        resume=_resume(obj["resume"]) if present(obj, "resume") else None,
    )


def _resume(value: object) -> Resume:
    where = "resume"
    obj = read_object(value, where, ("frames", "seq"), ("fidelity", "audio"))
    return Resume(
        frames=read_integer(obj["frames"], f"{where}.frames"),
        seq=read_integer(obj["seq"], f"{where}.seq", maximum=MAX_SEQ),
        fidelity=read_text(obj["fidelity"], f"{where}.fidelity", MAX_NAME_LENGTH)
        if present(obj, "fidelity")
        else None,
        audio=read_integer(obj["audio"], f"{where}.audio") if present(obj, "audio") else 0,
    )


def _output(value: object) -> OutputProfile:
    where = "output"
    obj = read_object(value, where, (), ("naming", "channels", "transforms", "visemes", "retarget"))
    if present(obj, "naming") and present(obj, "visemes"):
        raise InvalidField(
            INVALID_MESSAGE, where, "'naming' applies to blendshapes; omit it with 'visemes'"
        )
    if present(obj, "retarget") and (present(obj, "naming") or present(obj, "visemes")):
        raise InvalidField(
            INVALID_MESSAGE,
            where,
            "'retarget' names the output controls; omit 'naming' and 'visemes'",
        )
    naming = (
        read_choice(obj["naming"], f"{where}.naming", NAMINGS) if present(obj, "naming") else None
    )
    visemes = (
        read_choice(obj["visemes"], f"{where}.visemes", VISEME_SETS)
        if present(obj, "visemes")
        else None
    )
    return OutputProfile(
        naming=cast(Naming | None, naming),
        channels=read_names(obj["channels"], f"{where}.channels", MAX_CHANNELS)
        if present(obj, "channels")
        else None,
        transforms=_transforms(obj["transforms"]) if present(obj, "transforms") else {},
        visemes=cast(VisemeSet | None, visemes),
        retarget=read_text(obj["retarget"], f"{where}.retarget", MAX_NAME_LENGTH)
        if present(obj, "retarget")
        else None,
    )


def _transforms(value: object) -> dict[str, ChannelTransform]:
    where = "output.transforms"
    if not isinstance(value, dict):
        raise InvalidField(INVALID_MESSAGE, where, "must be an object of channel transforms")
    if len(value) > MAX_CHANNELS:
        raise InvalidField(INVALID_MESSAGE, where, f"must have at most {MAX_CHANNELS} entries")
    transforms: dict[str, ChannelTransform] = {}
    for name, spec in value.items():
        channel = read_text(name, f"{where} key", MAX_NAME_LENGTH)
        transforms[channel] = _transform(spec, f"{where}.{channel}")
    return transforms


def _transform(value: object, where: str) -> ChannelTransform:
    obj = read_object(value, where, (), ("multiplier", "offset", "clamp"))
    clamp: tuple[float, float] | None = None
    if present(obj, "clamp"):
        bounds = obj["clamp"]
        if not isinstance(bounds, list) or len(bounds) != 2:
            raise InvalidField(INVALID_MESSAGE, f"{where}.clamp", "must be [low, high]")
        low = read_number(bounds[0], f"{where}.clamp[0]")
        high = read_number(bounds[1], f"{where}.clamp[1]")
        if low > high:
            raise InvalidField(INVALID_MESSAGE, f"{where}.clamp", f"low {low} exceeds high {high}")
        clamp = (low, high)
    multiplier = (
        read_number(obj["multiplier"], f"{where}.multiplier") if present(obj, "multiplier") else 1.0
    )
    offset = read_number(obj["offset"], f"{where}.offset") if present(obj, "offset") else 0.0
    return ChannelTransform(multiplier, offset, clamp)


def _phonemes(payload: Mapping[str, Any], encoding: Encoding) -> Phonemes:
    obj = _object(payload, ("id", "items"))
    identifier = _id(obj)
    raw_items = obj["items"]
    if not isinstance(raw_items, list) or not raw_items:
        raise InvalidField(INVALID_MESSAGE, "items", "must be a non-empty list of phonemes")
    items: list[PhonemeItem] = []
    for index, raw in enumerate(raw_items):
        item = _phoneme_item(raw, f"items[{index}]")
        if items and item.start < items[-1].end - TIME_TOLERANCE_S:
            raise InvalidField(
                NON_MONOTONIC_TIMES,
                f"items[{index}].start",
                f"starts at {item.start} before the previous phoneme ends at {items[-1].end}",
            )
        items.append(item)
    return Phonemes(identifier, tuple(items))


def plain_phonemes(payload: dict[str, Any]) -> Phonemes | None:
    """A ``phonemes`` payload in its plainest valid shape as its message, without the
    field readers; None for anything else (the readers then accept it or name its fault).

    Plain: exactly the fields ``v`` (the integer version), ``type``, ``id`` and ``items``;
    the id and every label and emotion a printable ASCII string of an allowed length;
    every time a float, each item ending after it starts, in order. The readers accept
    all of it and return the same values, so the message is the one they would build."""
    if len(payload) != 4 or type(payload.get("v")) is not int or payload["v"] != PROTOCOL_VERSION:
        return None
    identifier = payload.get("id")
    raw_items = payload.get("items")
    if not _plain_text(identifier, MAX_ID_LENGTH) or type(raw_items) is not list or not raw_items:
        return None
    items: list[PhonemeItem] = []
    previous_end = -math.inf
    for raw in raw_items:
        if type(raw) is not dict:
            return None
        size = len(raw)
        phoneme = raw.get("phoneme")
        start = raw.get("start")
        end = raw.get("end")
        emotion = raw.get("emotion")
        if type(start) is not float or type(end) is not float:
            return None
        if not (0.0 <= start < end <= MAX_TIME_S and start >= previous_end - TIME_TOLERANCE_S):
            return None
        if size != (3 if emotion is None else 4) or not _plain_text(phoneme, MAX_PHONEME_LENGTH):
            return None
        if emotion is not None and not _plain_text(emotion, MAX_EMOTION_LENGTH):
            return None
        items.append(PhonemeItem(phoneme, start, end, emotion))
        previous_end = end
    return Phonemes(identifier, tuple(items))


def _plain_text(value: object, max_length: int) -> TypeGuard[str]:
    """``value`` is printable ASCII of 1 to ``max_length`` characters: no control
    characters, valid UTF-8, so ``read_text`` takes it as it is."""
    return (
        type(value) is str
        and 0 < len(value) <= max_length
        and value.isascii()
        and value.isprintable()
    )


def _phoneme_item(value: object, where: str) -> PhonemeItem:
    obj = read_object(value, where, ("phoneme", "start", "end"), ("emotion",))
    phoneme = read_text(obj["phoneme"], f"{where}.phoneme", MAX_PHONEME_LENGTH)
    start = read_number(
        obj["start"], f"{where}.start", minimum=0.0, maximum=MAX_TIME_S, code=INVALID_TIMES
    )
    end = read_number(
        obj["end"], f"{where}.end", minimum=0.0, maximum=MAX_TIME_S, code=INVALID_TIMES
    )
    if end <= start:
        raise InvalidField(INVALID_TIMES, f"{where}.end", f"end {end} must be after start {start}")
    return PhonemeItem(
        phoneme, start, end, _optional_text(obj, "emotion", where, MAX_EMOTION_LENGTH)
    )


def _audio(payload: Mapping[str, Any], encoding: Encoding) -> AudioChunk:
    obj = _object(payload, ("id", "sample_rate", "pcm16"), ("start",))
    identifier = _id(obj)
    rate = read_integer(
        obj["sample_rate"], "sample_rate", minimum=MIN_SAMPLE_RATE, maximum=MAX_SAMPLE_RATE
    )
    pcm = (
        read_bytes(obj["pcm16"], "pcm16")
        if encoding == "msgpack"
        else read_base64(obj["pcm16"], "pcm16", INVALID_AUDIO)
    )
    if not pcm or len(pcm) % PCM16_BYTES:
        raise InvalidField(
            INVALID_AUDIO, "pcm16", f"must hold whole 16-bit samples, got {len(pcm)} bytes"
        )
    start = _optional_number(obj, "start", minimum=0.0, maximum=MAX_TIME_S, code=INVALID_TIMES)
    return AudioChunk(identifier, rate, pcm, start)


def _text(payload: Mapping[str, Any], encoding: Encoding) -> Text:
    obj = _object(payload, ("id", "text"), ("voice", "rate", "lang"))
    identifier = _id(obj)
    text = obj["text"]
    if not isinstance(text, str):
        raise InvalidField(INVALID_MESSAGE, "text", "must be a string")
    require_utf8(text, "text")
    voice = (
        read_text(obj["voice"], "voice", MAX_VOICE_LENGTH, pattern=_VOICE)
        if present(obj, "voice")
        else None
    )
    rate = (
        read_integer(obj["rate"], "rate", minimum=MIN_RATE_WPM, maximum=MAX_RATE_WPM)
        if present(obj, "rate")
        else None
    )
    lang = (
        read_text(obj["lang"], "lang", MAX_VOICE_LENGTH, pattern=_VOICE)
        if present(obj, "lang")
        else None
    )
    return Text(identifier, text, voice, rate, lang)


def _words(payload: Mapping[str, Any], encoding: Encoding) -> Words:
    obj = _object(payload, ("id", "timings"), ("format", "offset", "voice"))
    identifier = _id(obj)
    timings = obj["timings"]
    if isinstance(timings, str):
        require_utf8(timings, "timings")
    elif isinstance(timings, (list, dict)):
        read_json_map({"timings": timings}, "")
    else:
        raise InvalidField(
            INVALID_MESSAGE, "timings", "must be a JSON object, a list or JSON lines text"
        )
    format = (
        read_choice(obj["format"], "format", TIMING_FORMATS) if present(obj, "format") else "auto"
    )
    offset = _optional_number(obj, "offset", minimum=0.0, maximum=MAX_TIME_S, code=INVALID_TIMES)
    voice = (
        read_text(obj["voice"], "voice", MAX_VOICE_LENGTH, pattern=_VOICE)
        if present(obj, "voice")
        else None
    )
    return Words(identifier, timings, format, offset or 0.0, voice)


def _end(payload: Mapping[str, Any], encoding: Encoding) -> End:
    return End(_id(_object(payload, ("id",))))


def _cancel(payload: Mapping[str, Any], encoding: Encoding) -> Cancel:
    return Cancel(_id(_object(payload, ("id",))))


def _interrupt(payload: Mapping[str, Any], encoding: Encoding) -> Interrupt:
    obj = _object(payload, ("id", "at"), ("return_ms",))
    return Interrupt(
        _id(obj),
        read_number(obj["at"], "at", minimum=0.0, maximum=MAX_TIME_S, code=INVALID_TIMES),
        _optional_number(obj, "return_ms", minimum=0.0, maximum=MAX_RETURN_MS),
    )


def _ready(payload: Mapping[str, Any], encoding: Encoding) -> Ready:
    obj = _object(
        payload,
        ("id", "engine", "character", "fps", "channels", "lookahead_ms", "fidelity"),
        ("emotion", "latency_budget_ms", "options", "phoneme_source"),
    )
    return Ready(
        id=_id(obj),
        engine=read_text(obj["engine"], "engine", MAX_NAME_LENGTH),
        character=read_text(obj["character"], "character", MAX_NAME_LENGTH),
        fps=read_number(obj["fps"], "fps", minimum=MIN_FPS, maximum=MAX_FPS),
        channels=read_names(obj["channels"], "channels", MAX_CHANNELS),
        lookahead_ms=read_number(
            obj["lookahead_ms"], "lookahead_ms", minimum=0.0, maximum=MAX_TIME_S * 1000.0
        ),
        fidelity=read_text(obj["fidelity"], "fidelity", MAX_NAME_LENGTH),
        emotion=_optional_text(obj, "emotion", "", MAX_EMOTION_LENGTH),
        latency_budget_ms=_optional_number(
            obj, "latency_budget_ms", above=0.0, maximum=MAX_LATENCY_BUDGET_MS
        ),
        options=read_json_map(obj["options"], "options") if present(obj, "options") else {},
        phoneme_source=_optional_text(obj, "phoneme_source", "", MAX_PHONEME_SOURCE_LENGTH),
    )


def _frames(payload: Mapping[str, Any], encoding: Encoding) -> Frames:
    obj = _object(payload, ("id", "seq", "first_frame", "fps", "n_channels", "data"))
    identifier = _id(obj)
    n_channels = read_integer(obj["n_channels"], "n_channels", minimum=1, maximum=MAX_CHANNELS)
    data = (
        _frame_bytes(obj["data"], n_channels)
        if encoding == "msgpack"
        else _frame_rows(obj["data"], n_channels)
    )
    if not all_finite_float32(data):
        raise InvalidField(INVALID_FRAMES, "data", "values must be finite")
    return Frames(
        id=identifier,
        seq=read_integer(obj["seq"], "seq", maximum=MAX_SEQ),
        first_frame=read_integer(obj["first_frame"], "first_frame"),
        fps=read_number(obj["fps"], "fps", minimum=MIN_FPS, maximum=MAX_FPS),
        n_channels=n_channels,
        data=data,
    )


def _frame_bytes(value: object, n_channels: int) -> bytes:
    data = read_bytes(value, "data")
    row_bytes = FLOAT32_BYTES * n_channels
    if not data or len(data) % row_bytes:
        raise InvalidField(
            INVALID_FRAMES,
            "data",
            f"must be whole rows of {n_channels} float32 values "
            f"({row_bytes} bytes each), got {len(data)} bytes",
        )
    return data


def _frame_rows(value: object, n_channels: int) -> bytes:
    if not isinstance(value, list) or not value:
        raise InvalidField(INVALID_MESSAGE, "data", "must be a non-empty list of rows")
    flat: list[float] = []
    for index, row in enumerate(value):
        where = f"data[{index}]"
        if not isinstance(row, list) or not row:
            raise InvalidField(INVALID_MESSAGE, where, "must be a non-empty list of numbers")
        for item in row:
            if isinstance(item, bool) or not isinstance(item, (int, float)):
                raise InvalidField(
                    INVALID_MESSAGE, where, f"values must be numbers, got {type(item).__name__}"
                )
        if len(row) != n_channels:
            raise InvalidField(
                INVALID_FRAMES, where, f"must have n_channels = {n_channels} values, got {len(row)}"
            )
        flat.extend(row)
    try:
        return pack_float32(flat)
    except (OverflowError, struct.error):
        raise InvalidField(INVALID_FRAMES, "data", "values must fit in float32") from None


def _done(payload: Mapping[str, Any], encoding: Encoding) -> Done:
    obj = _object(payload, ("id", "stats"), ("reason",))
    reason = read_choice(obj["reason"], "reason", DONE_REASONS) if present(obj, "reason") else "end"
    return Done(_id(obj), _stats(obj["stats"]), cast(DoneReason, reason))


def _stats(value: object) -> DoneStats:
    where = "stats"
    obj = read_object(
        value,
        where,
        ("frames",),
        ("first_frame_latency_ms", "max_lag_ms", "budget_met", "speech_synthesis_ms", "engine"),
    )

    def duration(key: str) -> float | None:
        return read_number(obj[key], f"{where}.{key}", minimum=0.0) if present(obj, key) else None

    return DoneStats(
        frames=read_integer(obj["frames"], f"{where}.frames"),
        first_frame_latency_ms=duration("first_frame_latency_ms"),
        max_lag_ms=duration("max_lag_ms"),
        budget_met=read_bool(obj["budget_met"], f"{where}.budget_met")
        if present(obj, "budget_met")
        else None,
        speech_synthesis_ms=duration("speech_synthesis_ms"),
        engine=read_json_map(obj["engine"], f"{where}.engine") if present(obj, "engine") else {},
    )


def _error(payload: Mapping[str, Any], encoding: Encoding) -> ErrorMessage:
    obj = _object(payload, ("code", "message", "id", "fatal"), ("details",))
    return ErrorMessage(
        code=read_text(obj["code"], "code", MAX_ERROR_CODE_LENGTH, pattern=ERROR_CODE),
        message=read_text(obj["message"], "message", MAX_ERROR_MESSAGE_LENGTH, control=True),
        id=_id(obj) if obj["id"] is not None else None,
        fatal=read_bool(obj["fatal"], "fatal"),
        details=read_json_map(obj["details"], "details") if present(obj, "details") else {},
    )


_PARSERS: dict[str, Callable[[Mapping[str, Any], Encoding], Message]] = {
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
_ALLOWED_TYPES: dict[Sender, Mapping[str, object]] = {
    "client": CLIENT_MESSAGE_TYPES,
    "server": SERVER_MESSAGE_TYPES,
}
