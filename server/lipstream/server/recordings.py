"""The ``/v1/recordings`` routes: record your face, hear it speak.

Sketch: thin routes over ``lipstream.recording``. ``POST /v1/recordings`` ``{"name",
"sentences"?}`` opens a session with prompt sentences (``recording.prompts``); ``PUT
.../takes/{index}`` streams one recording to disk, refusing it (and removing what was
written) once it passes ``LIPSTREAM_MAX_TAKE_BYTES``; ``POST .../train`` starts the job
in its own process (``recording.runner``); ``GET /v1/recordings/{session}`` answers the
session's takes and job from disk, so any worker answers it. ``watch`` starts the
worker's ``ModelWatcher``, which loads each published character (``hot_load``) and marks
its session's job done (or failed with ``load_failed``). Errors answer ``{"error":
{"code", "message"}}`` like every REST route, and the routes take a bearer token when
``LIPSTREAM_AUTH_TOKENS`` is set. See docs/reference/recordings.md.
"""

from __future__ import annotations

import asyncio
import json
import os
import secrets
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Request
from fastapi.responses import Response

from ..config import recordings_root
from ..errors import LipstreamError
from ..recording.errors import (
    JOB_RUNNING,
    LOAD_FAILED,
    NAME_TAKEN,
    RECORDINGS_DISABLED,
    TAKE_TOO_LARGE,
    TOO_FEW_TAKES,
    TOO_MANY_TAKES,
    UNKNOWN_TAKE,
)
from ..recording.prompts import checked_sentences, choose_prompts
from ..recording.recipe import MIN_GOOD_TAKES, PROMPT_COUNT
from ..recording.runner import lost, running, running_jobs, start_job
from ..recording.sessions import (
    DONE,
    FAILED,
    LOADING,
    UPLOADED,
    Session,
    SessionStore,
    check_name,
)
from ..recording.watcher import ModelWatcher
from .hot_load import load_character
from .rest import HttpError, authorize, error_response, read_json_object
from .startup import Startup
from .state import ServerState

MAX_JSON_BYTES = 1 << 16
STATUS = {
    RECORDINGS_DISABLED: 404,
    "invalid_name": 400,
    "invalid_request": 400,
    NAME_TAKEN: 409,
    "unknown_recording": 404,
    UNKNOWN_TAKE: 404,
    TAKE_TOO_LARGE: 413,
    TOO_MANY_TAKES: 422,
    TOO_FEW_TAKES: 422,
    JOB_RUNNING: 409,
    "server_busy": 503,
}
VIDEO_TYPES = ("video/", "application/octet-stream")


ERROR = {"$ref": "#/components/schemas/lipstream_Error"}
CREATE_BODY = {
    "type": "object",
    "properties": {
        "name": {"type": "string", "pattern": "^[a-z0-9-]{1,32}$"},
        "sentences": {
            "type": "array",
            "items": {"type": "string"},
            "description": "your own prompt sentences (default: chosen to cover the phonemes)",
        },
    },
    "required": ["name"],
}
TAKE_BODY = {"video/*": {"schema": {"type": "string", "format": "binary"}}}


def _operation(
    answer: tuple[str, str], errors: dict[str, str], body: dict[str, Any] | None = None
) -> dict[str, Any]:
    """``openapi_extra`` of a route: its answer (status, what), errors and request body."""
    responses: dict[str, Any] = {answer[0]: {"description": answer[1]}}
    for status, what in errors.items():
        responses[status] = {
            "description": what,
            "content": {"application/json": {"schema": ERROR}},
        }
    operation: dict[str, Any] = {"responses": responses}
    if body is not None:
        operation["requestBody"] = {"required": True, "content": body}
    return operation


SESSION_ERRORS = {"401": "a token is required", "404": "no such session, or recording is off"}


def store_of(state: ServerState) -> SessionStore:
    return SessionStore(recordings_root(state.settings))


def min_takes(state: ServerState) -> int:
    return state.settings.recording_min_takes or MIN_GOOD_TAKES


def _coded(error: LipstreamError) -> HttpError:
    return _refused(error.code, error.message)


def _refused(code: str, message: str, details: dict[str, Any] | None = None) -> HttpError:
    """An error answer with this module's status for ``code`` (else the REST routes')."""
    return HttpError(code, message, STATUS.get(code), details)


def install(app: FastAPI) -> None:
    """Add the recording routes to ``app``."""

    async def answer(request: Request, work: Callable[[ServerState], Any]) -> Response:
        startup: Startup = request.state.startup
        state = startup.serving()
        try:
            if not state.settings.recordings_enabled:
                raise _refused(
                    RECORDINGS_DISABLED,
                    "recording is switched off on this server (LIPSTREAM_RECORDINGS_ENABLED)",
                )
            authorize(request, state)
            status, body = await work(state)
        except LipstreamError as error:
            return _failed(state, _coded(error))
        except HttpError as error:
            return _failed(state, error)
        return Response(json.dumps(body), status, media_type="application/json")

    @app.post(
        "/v1/recordings",
        summary="Open a recording session",
        operation_id="create_recording",
        status_code=201,
        response_class=Response,
        openapi_extra=_operation(
            ("201", "the session id, its sentences and its limits"),
            {"400": "invalid name or sentences", "409": "the name is taken", **SESSION_ERRORS},
            {"application/json": {"schema": CREATE_BODY}},
        ),
    )
    async def create(request: Request) -> Response:
        """``{"name", "sentences"?}``: the session, its prompt sentences and its limits."""
        return await answer(request, lambda state: _create(request, state))

    @app.put(
        "/v1/recordings/{session}/takes/{index}",
        summary="Upload one recording",
        operation_id="upload_take",
        response_class=Response,
        openapi_extra=_operation(
            ("200", "the take's index and size"),
            {
                "409": "the training job is running",
                "413": "over the size limit",
                "415": "not video/*",
                "422": "over the count limit",
                **SESSION_ERRORS,
            },
            TAKE_BODY,
        ),
    )
    async def upload(request: Request, session: str, index: str) -> Response:
        """The raw body is one recording (video and audio, any format PyAV decodes)."""
        return await answer(request, lambda state: _upload(request, state, session, index))

    @app.post(
        "/v1/recordings/{session}/train",
        summary="Train a character on the recordings",
        operation_id="train_recording",
        status_code=202,
        response_class=Response,
        openapi_extra=_operation(
            ("202", "the job id; follow it with GET /v1/recordings/{session}"),
            {
                "409": "a job runs already, or the name was taken meanwhile",
                "422": "too few recordings uploaded",
                "503": "as many jobs as allowed are running",
                **SESSION_ERRORS,
            },
        ),
    )
    async def train(request: Request, session: str) -> Response:
        """Start the training job (capture, then the recipe's engines) in its own process."""
        return await answer(request, lambda state: _train(state, session))

    @app.get(
        "/v1/recordings/{session}",
        summary="A recording session's takes and job",
        operation_id="get_recording",
        response_class=Response,
        openapi_extra=_operation(("200", "the session's takes and job"), SESSION_ERRORS),
    )
    async def status(request: Request, session: str) -> Response:
        """Each take's status and error, and the job's state, step and progress."""
        return await answer(request, lambda state: _status(state, session))


def _failed(state: ServerState, error: HttpError) -> Response:
    state.metrics.errors.labels(error.code).inc()
    return error_response(error, "json")


async def _json_body(request: Request) -> dict[str, Any]:
    try:
        return await read_json_object(request, MAX_JSON_BYTES)
    except HttpError as error:
        raise _refused(error.code, error.message) from error


def _check_free(state: ServerState, store: SessionStore, name: str) -> None:
    if name in state.registry.characters() or name in store.trained_names():
        raise _refused(NAME_TAKEN, f"a character {name!r} exists already; pick another name")


async def _create(request: Request, state: ServerState) -> tuple[int, dict[str, Any]]:
    body = await _json_body(request)
    name = check_name(body.get("name"))
    store = store_of(state)
    _check_free(state, store, name)
    settings = state.settings
    loop = asyncio.get_running_loop()
    if "sentences" in body:
        sentences = checked_sentences(body["sentences"], settings.max_takes)
    else:
        count = min(PROMPT_COUNT, settings.max_takes)
        sentences = await loop.run_in_executor(None, choose_prompts, count)
    session = await loop.run_in_executor(None, store.create, name, sentences)
    return 201, {
        "session": session.id,
        "name": name,
        "sentences": [{"index": i, "text": text} for i, text in enumerate(sentences)],
        "limits": {
            "max_recordings": len(sentences),
            "max_bytes": settings.max_take_bytes,
            "min_recordings": min(min_takes(state), len(sentences)),
        },
    }


def _take_index(session: Session, text: str, max_takes: int) -> int:
    if not text.isdigit() or len(text) > 6:
        raise _refused(UNKNOWN_TAKE, f"take index must be a number, got {text!r}")
    index = int(text)
    if index >= max_takes:
        raise _refused(
            TOO_MANY_TAKES, f"take {index}: a session takes at most {max_takes} recordings"
        )
    if index >= len(session.sentences):
        raise _refused(
            UNKNOWN_TAKE,
            f"take {index}: the session has {len(session.sentences)} sentences (0 to "
            f"{len(session.sentences) - 1})",
        )
    return index


async def _upload(
    request: Request, state: ServerState, session_id: str, text: str
) -> tuple[int, dict[str, Any]]:
    settings = state.settings
    session = store_of(state).open(session_id)
    index = _take_index(session, text, settings.max_takes)
    if running(session.job()):
        raise _refused(JOB_RUNNING, "the session's training job is running; wait for it")
    media = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if not media.startswith(VIDEO_TYPES):
        raise _refused(
            "unsupported_media_type",
            f"Content-Type must be video/* (as MediaRecorder records), got {media or 'none'!r}",
        )
    limit = settings.max_take_bytes
    declared = request.headers.get("content-length", "")
    if declared.isdigit() and int(declared) > limit:
        raise _too_large(index, int(declared), limit)
    part = session.part_path(index).with_suffix(f".{secrets.token_hex(4)}.part")
    size = 0
    try:
        with part.open("wb") as out:
            async for chunk in request.stream():
                size += len(chunk)
                if size > limit:
                    raise _too_large(index, size, limit)
                out.write(chunk)
        if size == 0:
            raise _refused("invalid_request", f"take {index}: the body is empty")
        os.replace(part, session.take_path(index))
    finally:
        part.unlink(missing_ok=True)
    _forget_take(session, index)
    state.metrics.recording_takes.inc()
    state.metrics.recording_take_bytes.inc(size)
    return 200, {"take": index, "bytes": size}


def _too_large(index: int, size: int, limit: int) -> HttpError:
    return _refused(
        TAKE_TOO_LARGE,
        f"take {index}: at least {size} bytes, over the limit of {limit} bytes",
    )


def _forget_take(session: Session, index: int) -> None:
    """A new upload replaces the take: a finished job's verdict on the old one goes."""
    document = session.job()
    if document is not None and str(index) in document.get("takes", {}):
        takes = {key: value for key, value in document["takes"].items() if key != str(index)}
        session.write_job({**document, "takes": takes})


async def _train(state: ServerState, session_id: str) -> tuple[int, dict[str, Any]]:
    store = store_of(state)
    session = store.open(session_id)
    if running(session.job()):
        raise _refused(JOB_RUNNING, "the session's training job is running already")
    _check_free(state, store, session.name)
    uploaded, needed = len(session.takes()), min_takes(state)
    if uploaded < needed:
        raise _refused(
            TOO_FEW_TAKES,
            f"{uploaded} recording(s) uploaded, at least {needed} needed",
            {"uploaded": uploaded, "needed": needed},
        )
    if running_jobs(store) >= state.settings.max_recording_jobs:
        raise _refused(
            "server_busy",
            f"{state.settings.max_recording_jobs} training job(s) running already; try later",
            {"retry_after_ms": 10_000},
        )
    loop = asyncio.get_running_loop()
    job_id = await loop.run_in_executor(None, start_job, session, store.models_dir, needed)
    state.metrics.recording_jobs.inc()
    return 202, {"job": job_id}


async def _status(state: ServerState, session_id: str) -> tuple[int, dict[str, Any]]:
    session = store_of(state).open(session_id)
    document = session.job()
    verdicts = (document or {}).get("takes", {})
    takes = []
    for index, path in session.takes().items():
        verdict = verdicts.get(str(index)) or {"status": UPLOADED, "error": None}
        try:
            size = path.stat().st_size
        except OSError:
            continue
        takes.append({"index": index, "bytes": size, **verdict})
    return 200, {
        "session": session.id,
        "name": session.name,
        "sentences": [{"index": i, "text": text} for i, text in enumerate(session.sentences)],
        "takes": takes,
        "job": None if document is None else _job(state, session, document),
    }


def _job(state: ServerState, session: Session, document: dict[str, Any]) -> dict[str, Any]:
    document = lost(document)
    job = {
        key: document.get(key) for key in ("job", "state", "step", "progress", "error", "character")
    }
    if job["state"] == DONE and session.name not in state.registry.characters():
        job.update(state=LOADING, step="loading the character into this worker", progress=0.0)
    return job


def watch(state: ServerState) -> Callable[[], None]:
    """Start serving the characters trained here (now, and as jobs publish them) on a
    thread; the function that stops it."""
    store = store_of(state)

    def load(directories: list[Path]) -> None:
        for directory in directories:
            error = load_character(state.catalog, directory)
            outcome = "served" if error is None else "refused"
            state.metrics.characters_hot_loaded.labels(outcome).inc()
            _finish_jobs(store, directory.name, error)

    watcher = ModelWatcher(store.models_dir, load)
    watcher.start()
    return watcher.stop


def _finish_jobs(store: SessionStore, name: str, error: LipstreamError | None) -> None:
    for session in store.sessions():
        document = session.job()
        if session.name != name or document is None or document.get("state") != LOADING:
            continue
        if error is None:
            session.write_job({**document, "state": DONE, "step": "done", "progress": 1.0})
            continue
        failure = {"code": LOAD_FAILED, "message": f"{error.code}: {error.message}", "where": None}
        session.write_job({**document, "state": FAILED, "step": "failed", "error": failure})
