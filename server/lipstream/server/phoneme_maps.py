"""The phoneme-Isomap and contamination routes of ``expressive-dp`` models, under ``/v1/``.

Sketch: each route names a character (``/v1/characters/{character}/...``)
and works on that character's ``expressive-dp`` model (``unknown_model``, 404,
when it has none). The work runs in the speech lane, as REST synthesis
does, and answers JSON; errors answer ``{"error": {"code", "message"}}`` with
the statuses of ``rest``. Routes:

* ``GET .../phoneme-maps``: every phoneme that has nodes, with its frame and node counts
  and how many of its nodes are not contaminated.
* ``GET .../nodes/{node}``: one node's clip in channels at the frame rate it was
  recorded at, with its phoneme, emotion, context and contamination.
* ``POST .../phoneme-maps/utterance`` ``{"text", "lang", "voice", "rate"}`` or
  ``{"words": {"timings", "format"}}``: the phoneme spans a sentence is synthesized from
  (espeak-ng's for text, with its speech; the lexicon and the character's word-duration
  model for TTS timings), so that a constraint can name a phoneme by its index.
* ``GET .../phoneme-maps/{phoneme}``: the phoneme's map: every frame's point
  (``x``, ``y``), node and relative time, the Delaunay triangles (frame
  positions in the map), and its nodes with emotion, triphone context,
  contamination and their frames' span in the map (a node is a trajectory).
* ``POST .../phoneme-maps/{phoneme}/pick`` ``{"x", "y"}``: the barycentric
  blend of the triangle holding the point, in channels, with the frames and
  weights blended (the nearest frame outside the map).
* ``POST .../phoneme-maps/candidates`` ``{"items", "index", "time"}``: for the
  phoneme ``index`` of the utterance ``items`` (``{phoneme, start, end}``
  objects) at ``time`` seconds, the time-correct frames (every node
  of the phoneme at the same relative time, with its map point) and the
  context-correct nodes (the same triphone).
* ``GET``/``POST .../contamination`` ``{"mark": [ids], "restore": [ids]}``:
  the contaminated nodes, persisted beside the model, honoured from the next
  search on.
"""

from __future__ import annotations

import asyncio
import base64
import json
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from fastapi import FastAPI, Request
from fastapi.responses import Response

from ..errors import LipstreamError
from ..frontends.formats import parse_timings
from ..frontends.word_durations import WordDurationModel
from ..frontends.words_to_spans import timings_to_spans
from ..phonemes import PHONEME_INDEX, PHONEMES, SILENCE, normalize_phoneme
from ..speech.text_frontend import speak_text
from ..timeline import EMOTIONS, PhonemeSpan, coerce_spans
from .rest import HttpError, authorize, error_response, read_json_object, rest_client
from .startup import Startup
from .state import ServerState

if TYPE_CHECKING:
    from ..engines.expressive_dp import ExpressiveDpModel

ENGINE = "expressive-dp"
MAX_BODY_BYTES = 1 << 20
PREFIX = "/v1/characters/{character}"
NOT_FOUND = {"unknown_model": 404, "unknown_phoneme": 404}


def _state(request: Request) -> ServerState:
    startup: Startup = request.state.startup
    return startup.serving()


async def _answer(
    request: Request, work: Callable[[ExpressiveDpModel, dict[str, Any]], dict[str, Any]]
) -> Response:
    """Authorize, read the JSON body (if any), find the model and run ``work`` in the speech
    lane; the result or the error as JSON."""
    state = _state(request)
    try:
        authorize(request, state)
        body: dict[str, Any] = {}
        if request.method == "POST":
            body = await read_json_object(request, MAX_BODY_BYTES, "invalid_message")
        model = _model(state, request.path_params["character"])
        loop = asyncio.get_running_loop()
        lane = state.speech.client(rest_client(request))
        result = await loop.run_in_executor(lane, _guarded, work, model, body)
    except HttpError as error:
        state.metrics.errors.labels(error.code).inc()
        return error_response(error, "json")
    return Response(json.dumps(result, allow_nan=False), media_type="application/json")


def _guarded(
    work: Callable[[ExpressiveDpModel, dict[str, Any]], dict[str, Any]],
    model: ExpressiveDpModel,
    body: dict[str, Any],
) -> dict[str, Any]:
    try:
        return work(model, body)
    except LipstreamError as error:
        where = f"{error.where}: " if error.where else ""
        raise HttpError(error.code, f"{where}{error.message}", NOT_FOUND.get(error.code)) from error


def _model(state: ServerState, character: str) -> ExpressiveDpModel:
    try:
        model = state.registry.find(ENGINE, character)
    except LipstreamError as error:
        raise HttpError(error.code, error.message, 404) from error
    from ..engines.expressive_dp import ExpressiveDpModel  # only once such a model is served

    assert isinstance(model, ExpressiveDpModel)
    return model


def _phoneme(label: str) -> int:
    return PHONEME_INDEX[normalize_phoneme(label, where="phoneme")]


def _number(body: dict[str, Any], name: str) -> float:
    value = body.get(name)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value:
        raise LipstreamError(f"must be a number, got {value!r}", where=name, code="invalid_request")
    return float(value)


def _ids(body: dict[str, Any], name: str) -> list[int]:
    value = body.get(name, [])
    if not isinstance(value, list):
        raise LipstreamError("must be a list of node ids", where=name, code="invalid_request")
    return value


def phoneme_map(model: ExpressiveDpModel, phoneme: int) -> dict[str, Any]:
    maps, nodes = model.maps, model.nodes
    rows = maps.phoneme_rows(phoneme)
    triangulation = maps.triangulation(phoneme)
    contaminated = model.contamination.mask()
    relative = nodes.relative_times()
    members = maps.phoneme_nodes(phoneme)
    first_row = {int(row): position for position, row in enumerate(rows)}
    return {
        "phoneme": PHONEMES[phoneme],
        "frames": {
            "x": maps.points[rows, 0].tolist(),
            "y": maps.points[rows, 1].tolist(),
            "node": maps.frame_node[rows].tolist(),
            "time": relative[rows].tolist(),
        },
        "triangles": [] if triangulation is None else triangulation.simplices.tolist(),
        "nodes": [
            {
                "id": int(node),
                "emotion": _emotion(model, int(node)),
                "previous": PHONEMES[int(nodes.previous[node])],
                "next": PHONEMES[int(nodes.next[node])],
                "contaminated": bool(contaminated[node]),
                "first_frame": first_row[int(nodes.offsets[node])],
                "frame_count": int(nodes.offsets[node + 1] - nodes.offsets[node]),
            }
            for node in members
        ],
    }


def phoneme_summary(model: ExpressiveDpModel) -> dict[str, Any]:
    nodes = model.nodes
    clean = ~model.contamination.mask()
    frame_counts = np.diff(nodes.offsets)
    listed = []
    for phoneme in np.unique(nodes.phoneme):
        members = nodes.phoneme == phoneme
        listed.append(
            {
                "phoneme": PHONEMES[int(phoneme)],
                "frame_count": int(frame_counts[members].sum()),
                "node_count": int(members.sum()),
                "clean_node_count": int((members & clean).sum()),
            }
        )
    return {"phonemes": listed, "node_count": nodes.size}


def node_clip(model: ExpressiveDpModel, node: int) -> dict[str, Any]:
    nodes = model.nodes
    if not 0 <= node < nodes.size:
        raise LipstreamError(
            f"no node {node}; the model has {nodes.size}", where="node", code="invalid_request"
        )
    frames = model.basis.reconstruct(nodes.node_frames(node))
    return {
        "id": node,
        "phoneme": PHONEMES[int(nodes.phoneme[node])],
        "emotion": _emotion(model, node),
        "previous": PHONEMES[int(nodes.previous[node])],
        "next": PHONEMES[int(nodes.next[node])],
        "contaminated": bool(model.contamination.mask()[node]),
        "fps": nodes.fps,
        "channels": list(model.channels),
        "frames": np.asarray(frames, dtype=float).tolist(),
    }


def utterance(
    model: ExpressiveDpModel, body: dict[str, Any], durations: Callable[[], WordDurationModel]
) -> dict[str, Any]:
    if "words" in body:
        words = body["words"]
        if not isinstance(words, dict) or "timings" not in words:
            raise LipstreamError(
                "must be an object {timings, format}", where="words", code="invalid_request"
            )
        format = words.get("format", "auto")
        if not isinstance(format, str):
            raise LipstreamError("must be a string", where="words.format", code="invalid_request")
        spans = timings_to_spans(parse_timings(words["timings"], format), durations())
        return {"items": _items(spans)}
    text = body.get("text")
    if not isinstance(text, str):
        raise LipstreamError(
            "give text (a string) or words {timings, format}", where="text", code="invalid_request"
        )
    options = {key: body[key] for key in ("voice", "rate", "lang") if body.get(key) is not None}
    spoken = speak_text(text, **options)
    return {
        "items": _items(spoken.spans),
        "speech": {
            "sample_rate": spoken.sample_rate,
            "pcm16": base64.b64encode(spoken.pcm16).decode("ascii"),
        },
    }


def _items(spans: list[PhonemeSpan]) -> list[dict[str, Any]]:
    return [{"phoneme": span.phoneme, "start": span.start, "end": span.end} for span in spans]


def _emotion(model: ExpressiveDpModel, node: int) -> str:
    return EMOTIONS[int(model.nodes.emotion[node])]


def pick(model: ExpressiveDpModel, phoneme: int, body: dict[str, Any]) -> dict[str, Any]:
    picked = model.maps.pick(phoneme, _number(body, "x"), _number(body, "y"))
    frame = model.basis.reconstruct(picked.frame[None])[0]
    return {
        "inside": picked.inside,
        "channels": list(model.channels),
        "frame": [float(value) for value in frame],
        "nodes": model.maps.frame_node[picked.vertices].tolist(),
        "weights": picked.weights.tolist(),
    }


def candidates(model: ExpressiveDpModel, body: dict[str, Any]) -> dict[str, Any]:
    spans = coerce_spans(body.get("items", []))
    index = body.get("index")
    if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < len(spans):
        raise LipstreamError(
            f"must be a phoneme index in [0, {len(spans) - 1}], got {index!r}",
            where="index",
            code="invalid_request",
        )
    span = spans[index]
    time = _number(body, "time")
    relative = min(max((time - span.start) / (span.end - span.start), 0.0), 1.0)
    phoneme = PHONEME_INDEX[span.phoneme]
    previous = PHONEME_INDEX[spans[index - 1].phoneme] if index > 0 else PHONEME_INDEX[SILENCE]
    following = (
        PHONEME_INDEX[spans[index + 1].phoneme]
        if index + 1 < len(spans)
        else PHONEME_INDEX[SILENCE]
    )
    members, placed = model.maps.time_correct(phoneme, relative)
    return {
        "phoneme": span.phoneme,
        "relative_time": relative,
        "context": [PHONEMES[previous], span.phoneme, PHONEMES[following]],
        "time_correct": [
            {"node": int(node), "x": float(point[0]), "y": float(point[1])}
            for node, point in zip(members, placed)
        ],
        "context_correct": model.maps.context_correct(phoneme, previous, following).tolist(),
    }


def contamination(model: ExpressiveDpModel, body: dict[str, Any] | None) -> dict[str, Any]:
    if body is None:
        nodes = model.contamination.nodes()
    else:
        nodes = model.contamination.change(_ids(body, "mark"), _ids(body, "restore"))
    return {"nodes": nodes, "node_count": model.nodes.size}


def _schema(properties: dict[str, Any], required: list[str]) -> dict[str, Any]:
    return {"type": "object", "properties": properties, "required": required}


def _operation(body: dict[str, Any] | None, answer: str) -> dict[str, Any]:
    error = {"$ref": "#/components/schemas/lipstream_Error"}
    operation: dict[str, Any] = {
        "responses": {
            "200": {"description": answer},
            "404": {
                "description": "no expressive-dp model for the character, or unknown phoneme",
                "content": {"application/json": {"schema": error}},
            },
            "422": {
                "description": "invalid field (named in the message)",
                "content": {"application/json": {"schema": error}},
            },
        }
    }
    if body is not None:
        operation["requestBody"] = {
            "required": True,
            "content": {"application/json": {"schema": body}},
        }
    return operation


NUMBER = {"type": "number"}
IDS = {"type": "array", "items": {"type": "integer"}}


def install(app: FastAPI) -> None:
    """Add the routes to ``app`` (they appear in its OpenAPI document)."""

    @app.get(
        PREFIX + "/phoneme-maps",
        summary="The phonemes of the maps (expressive-dp)",
        operation_id="list_phoneme_maps",
        response_class=Response,
        openapi_extra=_operation(None, "each phoneme's frame and node counts"),
    )
    async def maps_route(request: Request, character: str) -> Response:
        """Every phoneme with nodes: frames, nodes, and nodes not contaminated."""
        return await _answer(request, lambda model, _: phoneme_summary(model))

    @app.get(
        PREFIX + "/nodes/{node}",
        summary="A motion node's clip (expressive-dp)",
        operation_id="get_motion_node",
        response_class=Response,
        openapi_extra=_operation(None, "the node's frames in channels, at its recorded fps"),
    )
    async def node_route(request: Request, character: str, node: int) -> Response:
        """One motion node: its frames in channels, phoneme, emotion and context."""
        return await _answer(request, lambda model, _: node_clip(model, node))

    @app.post(
        PREFIX + "/phoneme-maps/utterance",
        summary="The phoneme spans of a sentence",
        operation_id="phoneme_map_utterance",
        response_class=Response,
        openapi_extra=_operation(
            _schema(
                {
                    "text": {"type": "string"},
                    "lang": {"type": "string"},
                    "voice": {"type": "string"},
                    "rate": {"type": "integer"},
                    "words": {"type": "object", "description": "{timings, format}"},
                },
                [],
            ),
            "the phoneme spans (items) and, for text, espeak-ng's speech",
        ),
    )
    async def utterance_route(request: Request, character: str) -> Response:
        """A sentence's phoneme spans, numbered as constraints name them."""
        catalog = _state(request).catalog

        def durations() -> WordDurationModel:
            return catalog.word_durations(ENGINE, character)

        return await _answer(request, lambda model, body: utterance(model, body, durations))

    @app.get(
        PREFIX + "/phoneme-maps/{phoneme}",
        summary="A phoneme's map (expressive-dp)",
        operation_id="get_phoneme_map",
        response_class=Response,
        openapi_extra=_operation(None, "the phoneme's map: frames, triangles and nodes"),
    )
    async def map_route(request: Request, character: str, phoneme: str) -> Response:
        """A phoneme cluster's 2D Isomap, its triangulation and its nodes (expressive-dp)."""
        return await _answer(request, lambda model, _: phoneme_map(model, _phoneme(phoneme)))

    @app.post(
        PREFIX + "/phoneme-maps/{phoneme}/pick",
        summary="Pick a point of a phoneme's map",
        operation_id="pick_phoneme_map_point",
        response_class=Response,
        openapi_extra=_operation(
            _schema({"x": NUMBER, "y": NUMBER}, ["x", "y"]),
            "the blended frame in channels, the nodes and barycentric weights blended",
        ),
    )
    async def pick_route(request: Request, character: str, phoneme: str) -> Response:
        """Pick a point of a phoneme map: the barycentric blend of its triangle's frames."""
        return await _answer(request, lambda model, body: pick(model, _phoneme(phoneme), body))

    @app.post(
        PREFIX + "/phoneme-maps/candidates",
        summary="Constraint candidates for one phoneme",
        operation_id="phoneme_constraint_candidates",
        response_class=Response,
        openapi_extra=_operation(
            _schema(
                {
                    "items": {"type": "array", "description": "{phoneme, start, end} objects"},
                    "index": {"type": "integer"},
                    "time": NUMBER,
                },
                ["items", "index", "time"],
            ),
            "time-correct frames and context-correct nodes of the constrained phoneme",
        ),
    )
    async def candidates_route(request: Request, character: str) -> Response:
        """Constraint candidates for one phoneme of an utterance (Fig. 9 of the paper)."""
        return await _answer(request, candidates)

    @app.get(
        PREFIX + "/contamination",
        summary="The contaminated nodes",
        operation_id="get_contamination",
        response_class=Response,
        openapi_extra=_operation(None, "the contaminated node ids"),
    )
    async def contamination_route(request: Request, character: str) -> Response:
        """The nodes marked contaminated (never chosen by a search)."""
        return await _answer(request, lambda model, _: contamination(model, None))

    @app.post(
        PREFIX + "/contamination",
        summary="Mark and restore contaminated nodes",
        operation_id="change_contamination",
        response_class=Response,
        openapi_extra=_operation(
            _schema({"mark": IDS, "restore": IDS}, []),
            "the contaminated node ids after the change",
        ),
    )
    async def change_contamination_route(request: Request, character: str) -> Response:
        """Mark and restore nodes; persisted beside the model, honoured by the next search."""
        return await _answer(request, contamination)
