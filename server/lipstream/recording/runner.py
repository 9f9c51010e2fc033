"""Starting a training job in its own process, and knowing which jobs still run.

Sketch: a job is ``python -m lipstream.recording.job SESSION_DIR MODELS_DIR MIN_TAKES``,
started with ``subprocess.Popen`` (its output goes to the session's ``job.log``), so
capture and training use their own process and never the server's event loop or thread
pools. ``job.json`` is written ``queued`` with the job's pid before it starts; a thread
waits for the process and, if it exits without having written an end (a crash, a kill),
marks the job failed with ``job_lost``. Jobs are counted on disk, over every worker: a job
is running while its state is not finished and its process (whose pid it writes in every
state) lives, or while it is queued.
"""

from __future__ import annotations

import os
import secrets
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import lipstream

from .errors import JOB_LOST
from .sessions import FAILED, FINISHED, LOADING, QUEUED, Session, SessionStore

JOB_MODULE = "lipstream.recording.job"
LOG_FILE = "job.log"


def job_document(job_id: str, state: str, **fields: Any) -> dict[str, Any]:
    """A ``job.json``: the fields the status route answers, and the job's bookkeeping."""
    document: dict[str, Any] = {
        "job": job_id,
        "state": state,
        "step": fields.pop("step", state),
        "progress": fields.pop("progress", 0.0),
        "error": fields.pop("error", None),
        "character": fields.pop("character", None),
        "takes": fields.pop("takes", {}),
    }
    document.update(fields)
    return document


def alive(pid: object) -> bool:
    if not isinstance(pid, int) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def running(document: dict[str, Any] | None) -> bool:
    """The job of ``document`` is at work: not finished and not waiting to be loaded, and
    its process lives."""
    if document is None or document.get("state") in FINISHED | {LOADING}:
        return False
    return document.get("state") == QUEUED or alive(document.get("pid"))


def lost(document: dict[str, Any]) -> dict[str, Any]:
    """``document`` as a failed job when its process died before finishing its part (a
    queued job's process has not written its pid yet: its reaper watches it)."""
    if document.get("state") in FINISHED | {LOADING, QUEUED} or alive(document.get("pid")):
        return document
    error = {
        "code": JOB_LOST,
        "message": "the training process ended without finishing (killed or crashed); train again",
        "where": None,
    }
    return {**document, "state": FAILED, "step": "failed", "error": error}


def running_jobs(store: SessionStore) -> int:
    return sum(1 for session in store.sessions() if running(session.job()))


def start_job(session: Session, models_dir: Path, min_takes: int) -> str:
    """Start the job training ``session`` into ``models_dir``; its id."""
    job_id = secrets.token_hex(8)
    session.write_job(job_document(job_id, QUEUED, step="waiting for the job process"))
    package_parent = str(Path(lipstream.__file__).resolve().parents[1])
    path = os.environ.get("PYTHONPATH", "")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [package_parent, path]))}
    command = [sys.executable, "-m", JOB_MODULE, str(session.directory), str(models_dir)]
    with (session.directory / LOG_FILE).open("ab") as log:
        process = subprocess.Popen(
            [*command, str(min_takes), job_id],
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=subprocess.STDOUT,
            env=env,
            start_new_session=True,
        )
    threading.Thread(
        target=_reap, args=(process, session, job_id), name="lipstream-recording-job", daemon=True
    ).start()
    return job_id


def _reap(process: subprocess.Popen[bytes], session: Session, job_id: str) -> None:
    process.wait()
    document = session.job()
    if document is None or document.get("job") != job_id:
        return
    if document.get("state") not in FINISHED | {LOADING}:
        session.write_job(lost({**document, "pid": None}))
