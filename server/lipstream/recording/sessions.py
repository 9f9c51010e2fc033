"""Recording sessions on disk, shared by every server worker and the training job.

Sketch: the recordings root holds ``sessions/<id>/`` and ``models/`` (the trained
characters, ``watcher``). A session directory holds ``session.json`` (its character name
and prompt sentences), ``takes/<index>.media`` (each upload, streamed to a ``.part`` file
and renamed into place when whole, so a re-upload replaces and a cut upload leaves
nothing), and ``job.json`` (the training job's state, written by the job process and,
at its ends, by the workers). Every JSON file is written to a temporary file and renamed,
so a reader in another process sees the old or the new state, never half. Session ids are
random (``secrets``): knowing one is what lets a client use it.
"""

from __future__ import annotations

import json
import os
import re
import secrets
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import LipstreamError
from .errors import INVALID_NAME, UNKNOWN_RECORDING

SESSIONS_DIR = "sessions"
MODELS_DIR = "models"
SESSION_FILE = "session.json"
JOB_FILE = "job.json"
TAKES_DIR = "takes"
TAKE_SUFFIX = ".media"
PART_SUFFIX = ".part"
NAME_PATTERN = re.compile(r"[a-z0-9-]{1,32}")
SESSION_PATTERN = re.compile(r"[A-Za-z0-9_-]{16,64}")

QUEUED, CAPTURING, ALIGNING, TRAINING, LOADING, DONE, FAILED = (
    "queued",
    "capturing",
    "aligning",
    "training",
    "loading",
    "done",
    "failed",
)
FINISHED = frozenset({DONE, FAILED})
UPLOADED, CAPTURED, TAKE_FAILED = "uploaded", "captured", "failed"


def write_json(path: Path, document: dict[str, Any]) -> None:
    """``document`` written whole or not at all (temporary file, then rename)."""
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    temporary.write_text(json.dumps(document, indent=1, allow_nan=False), encoding="utf-8")
    os.replace(temporary, path)


def read_json(path: Path) -> dict[str, Any] | None:
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return document if isinstance(document, dict) else None


def check_name(value: object) -> str:
    """A character name: ``[a-z0-9-]{1,32}``; ``invalid_name`` otherwise."""
    if not isinstance(value, str) or NAME_PATTERN.fullmatch(value) is None:
        raise LipstreamError(
            f"must be 1 to 32 of a-z, 0-9 and -, got {value!r}", where="name", code=INVALID_NAME
        )
    return value


@dataclass(frozen=True)
class Session:
    """One recording session's directory, character name and prompt sentences."""

    directory: Path
    name: str
    sentences: tuple[str, ...]

    @property
    def id(self) -> str:
        return self.directory.name

    @property
    def job_file(self) -> Path:
        return self.directory / JOB_FILE

    @property
    def corpus_dir(self) -> Path:
        return self.directory / "corpus"

    @property
    def staging_dir(self) -> Path:
        return self.directory / "models"

    def take_path(self, index: int) -> Path:
        return self.directory / TAKES_DIR / f"{index:03d}{TAKE_SUFFIX}"

    def part_path(self, index: int) -> Path:
        return self.directory / TAKES_DIR / f"{index:03d}{PART_SUFFIX}"

    def takes(self) -> dict[int, Path]:
        """The uploaded takes by index."""
        found = {}
        for path in (self.directory / TAKES_DIR).glob(f"*{TAKE_SUFFIX}"):
            stem = path.name[: -len(TAKE_SUFFIX)]
            if stem.isdigit():
                found[int(stem)] = path
        return dict(sorted(found.items()))

    def job(self) -> dict[str, Any] | None:
        return read_json(self.job_file)

    def write_job(self, document: dict[str, Any]) -> None:
        write_json(self.job_file, document)


@dataclass(frozen=True)
class SessionStore:
    """The recordings root: sessions and the trained characters' models."""

    root: Path

    @property
    def sessions_dir(self) -> Path:
        return self.root / SESSIONS_DIR

    @property
    def models_dir(self) -> Path:
        return self.root / MODELS_DIR

    def create(self, name: str, sentences: Sequence[str]) -> Session:
        directory = self.sessions_dir / secrets.token_urlsafe(18)
        (directory / TAKES_DIR).mkdir(parents=True)
        session = Session(directory, name, tuple(sentences))
        write_json(directory / SESSION_FILE, {"name": name, "sentences": list(sentences)})
        return session

    def open(self, session_id: str) -> Session:
        """The session ``session_id``; ``unknown_recording`` when there is none."""
        directory = self.sessions_dir / session_id
        document = (
            read_json(directory / SESSION_FILE) if SESSION_PATTERN.fullmatch(session_id) else None
        )
        if document is None:
            raise LipstreamError(
                "no such recording session", where="session", code=UNKNOWN_RECORDING
            )
        return Session(directory, str(document["name"]), tuple(document["sentences"]))

    def sessions(self) -> Iterator[Session]:
        if not self.sessions_dir.is_dir():
            return
        for directory in sorted(self.sessions_dir.iterdir()):
            try:
                yield self.open(directory.name)
            except LipstreamError:
                continue

    def trained_names(self) -> set[str]:
        """The characters trained here (each a directory of models)."""
        if not self.models_dir.is_dir():
            return set()
        return {path.name for path in self.models_dir.iterdir() if path.is_dir()}
