"""The OpenAPI description of ``POST /v1/synthesize``, built from the protocol's JSON Schemas.

Sketch: the request body's schema is the ``start`` message's properties
(without ``v``, ``type`` and ``id``), plus the ``phonemes`` message's
``items`` or a ``words`` object with the ``words`` message's fields, each with an
``audio`` object with the ``audio`` message's ``sample_rate`` and ``pcm16``, or instead
the ``text`` message's ``text``, ``lang``, ``voice`` and ``rate``. Their ``#/$defs/X``
references move to ``#/components/schemas/lipstream_X``, so the schemas shipped with the
client SDK stay the single source. The response and error bodies are described by hand
here, as they are not protocol messages.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi

from lipstream_client import load_schema

PREFIX = "lipstream_"
ENVELOPE = ("v", "type", "id")


def _moved(node: Any) -> Any:
    """A copy of a schema with ``#/$defs/X`` references pointing into the components."""
    if isinstance(node, dict):
        return {
            key: (
                value.replace("#/$defs/", f"#/components/schemas/{PREFIX}")
                if key == "$ref" and isinstance(value, str)
                else _moved(value)
            )
            for key, value in node.items()
        }
    if isinstance(node, list):
        return [_moved(item) for item in node]
    return node


def components() -> dict[str, Any]:
    """``components.schemas`` entries: every protocol definition and the three bodies."""
    start, phonemes, audio, words, text = (
        load_schema(kind) for kind in ("start", "phonemes", "audio", "words", "text")
    )
    schemas: dict[str, Any] = {}
    for schema in (start, phonemes, audio, words, text):
        schemas.update(
            {PREFIX + name: _moved(value) for name, value in schema.get("$defs", {}).items()}
        )
    properties = {
        key: _moved(value) for key, value in start["properties"].items() if key not in ENVELOPE
    }
    properties["items"] = _moved(phonemes["properties"]["items"])
    properties["words"] = {
        "type": "object",
        "additionalProperties": False,
        "required": ["timings"],
        "properties": {
            key: _moved(value) for key, value in words["properties"].items() if key not in ENVELOPE
        },
        "description": "Instead of items: a TTS's word, character, viseme or phoneme "
        "timings, the fields of a words message.",
    }
    properties["audio"] = {
        "type": "object",
        "additionalProperties": False,
        "required": ["sample_rate", "pcm16"],
        "properties": {key: _moved(audio["properties"][key]) for key in ("sample_rate", "pcm16")},
        "description": "Optional speech audio for engines that use it (PCM16 mono; bin in "
        "msgpack, base64 in JSON).",
    }
    for key in ("text", "lang", "voice", "rate"):
        properties[key] = _moved(text["properties"][key])
    properties["transcript"] = {
        "type": "string",
        "description": "Instead of items: what the audio (then required) says; its phonemes "
        "come from forced alignment (English), and the answer carries alignment.confidence.",
    }
    inputs = ("items", "words", "text", "transcript")
    schemas[PREFIX + "SynthesizeRequest"] = {
        "type": "object",
        "additionalProperties": False,
        "required": ["engine", "character"],
        "oneOf": [
            {"required": ["items"], "not": _any_of(inputs, "items")},
            {"required": ["words"], "not": _any_of(inputs, "words")},
            {"required": ["text"], "not": _any_of((*inputs, "audio"), "text")},
            {
                "required": ["transcript", "audio"],
                "not": _any_of((*inputs, "phoneme_source"), "transcript"),
            },
        ],
        "properties": properties,
        "description": "A start message's fields, then the utterance's phonemes (or a TTS's "
        "timings) and optional audio, or a text for espeak-ng to speak (in lang, with voice "
        "and rate), or audio and its transcript.",
    }
    schemas[PREFIX + "SynthesizeResponse"] = _response_schema()
    schemas[PREFIX + "Error"] = _error_schema()
    return schemas


def _response_schema() -> dict[str, Any]:
    number = {"type": "number"}
    return {
        "type": "object",
        "required": [
            "engine",
            "character",
            "fps",
            "channels",
            "fidelity",
            "lookahead_ms",
            "first_frame",
            "n_frames",
            "n_channels",
            "data",
            "stats",
        ],
        "properties": {
            "engine": {"type": "string"},
            "character": {"type": "string"},
            "fps": number,
            "channels": {"type": "array", "items": {"type": "string"}},
            "fidelity": {"type": "string"},
            "lookahead_ms": number,
            "emotion": {"type": "string"},
            "latency_budget_ms": number,
            "options": {"type": "object"},
            "phoneme_source": {"type": "string"},
            "first_frame": {"type": "integer", "const": 0},
            "n_frames": {"type": "integer"},
            "n_channels": {"type": "integer"},
            "data": {
                "description": "JSON: n_frames rows of n_channels numbers (shortest "
                "float32 decimals). msgpack: bin of float32 little-endian, "
                "row-major.",
                "type": "array",
                "items": {"type": "array", "items": number},
            },
            "stats": {
                "type": "object",
                "properties": {"frames": {"type": "integer"}, "engine": {"type": "object"}},
            },
            "speech": {
                "type": "object",
                "required": ["sample_rate", "pcm16"],
                "properties": {"sample_rate": {"type": "integer"}, "pcm16": {}},
                "description": "a text request's speech, whole: PCM16 mono (bin in msgpack, "
                "base64 in JSON), frame i at i / fps on its clock",
            },
            "alignment": {
                "type": "object",
                "required": ["confidence"],
                "properties": {"confidence": {"type": "number", "minimum": 0, "maximum": 1}},
                "description": "a transcript request's forced alignment: its confidence",
            },
        },
        "description": "ready's resolved parameters, every frame, and done's stats.",
    }


def _any_of(fields: tuple[str, ...], but: str) -> dict[str, Any]:
    """A schema matching an object that has any of ``fields`` other than ``but``."""
    return {"anyOf": [{"required": [key]} for key in fields if key != but]}


def _error_schema() -> dict[str, Any]:
    return {
        "type": "object",
        "required": ["error"],
        "properties": {
            "error": {
                "type": "object",
                "required": ["code", "message"],
                "properties": {
                    "code": {"type": "string"},
                    "message": {"type": "string"},
                    "details": {"type": "object"},
                },
            }
        },
    }


def _content(name: str) -> dict[str, Any]:
    reference = {"$ref": f"#/components/schemas/{PREFIX}{name}"}
    return {"application/json": {"schema": reference}, "application/msgpack": {"schema": reference}}


def synthesize_operation() -> dict[str, Any]:
    """``openapi_extra`` for the route: request body and responses."""
    errors = {
        str(status): {"description": meaning, "content": _content("Error")}
        for status, meaning in (
            (400, "malformed or invalid body"),
            (401, "missing or wrong bearer token"),
            (404, "unknown engine or character"),
            (406, "Accept allows no supported type"),
            (413, "body too large"),
            (415, "unsupported Content-Type"),
            (422, "valid but not acceptable (phoneme, emotion, channel, budget, limits)"),
        )
    }
    return {
        "requestBody": {"required": True, "content": _content("SynthesizeRequest")},
        "responses": {
            "200": {
                "description": "all frames of the utterance; with Accept: text/csv, the frames "
                "alone as CSV: a header `time,<channel>,...`, then one row per frame, frame i at "
                "i / fps seconds, values with 6 decimals",
                "content": {
                    **_content("SynthesizeResponse"),
                    "text/csv": {"schema": {"type": "string"}},
                },
            },
            **errors,
        },
    }


def install(app: FastAPI) -> Callable[[], dict[str, Any]]:
    """Make ``app.openapi`` add the protocol's schemas to the generated document."""

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            document = get_openapi(
                title=app.title, version=app.version, description=app.description, routes=app.routes
            )
            document.setdefault("components", {}).setdefault("schemas", {}).update(components())
            app.openapi_schema = document
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
    return openapi
