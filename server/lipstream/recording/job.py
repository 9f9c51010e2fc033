"""The training job of one recording session, run as its own process.

Sketch: ``python -m lipstream.recording.job SESSION_DIR MODELS_DIR MIN_TAKES JOB_ID``.
Capturing: each take is decoded and its face tracked and checked (``capture``); aligning:
each tracked take's speech is force-aligned to its prompt sentence. A take that fails
either step is marked failed with the capture's coded error (``no_face``,
``corrupt_video``, ``not_speech``, ``alignment_failed``...) and the others go on. With
fewer than ``MIN_TAKES`` good takes the job fails with ``too_few_takes``, listing each
failed take and why. Training: the good takes become one corpus (``capture.pipeline``,
written to the session's ``corpus/``) and the recipe's engines are trained on all of it,
each then warmed so its kernels are in numba's disk cache. Loading: the models move into
``MODELS_DIR/<name>`` in one rename and the watchers are told (``watcher``); the server
workers load them and mark the job done. Every state change rewrites ``job.json``
(state, step, progress in [0, 1] within the state, each take's status).
"""

from __future__ import annotations

import os
import shutil
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..errors import LipstreamError
from .errors import NAME_TAKEN, TOO_FEW_TAKES, TRAINING_FAILED
from .recipe import ENGINES
from .runner import job_document
from .sessions import (
    ALIGNING,
    CAPTURED,
    CAPTURING,
    FAILED,
    LOADING,
    SESSION_FILE,
    TAKE_FAILED,
    TRAINING,
    Session,
    read_json,
)
from .watcher import bump_generation

INTERNAL = "internal_error"


def error_json(error: LipstreamError | Exception, where: str | None) -> dict[str, Any]:
    if isinstance(error, LipstreamError):
        return {"code": error.code, "message": error.message, "where": where}
    return {"code": INTERNAL, "message": f"{type(error).__name__}: {error}", "where": where}


class Job:
    """The job's state, written to ``job.json`` at every change."""

    def __init__(self, session: Session, job_id: str) -> None:
        self.session = session
        self.job_id = job_id
        self.takes: dict[str, dict[str, Any]] = {}

    def write(self, state: str, step: str, progress: float = 0.0, **fields: Any) -> None:
        self.session.write_job(
            job_document(
                self.job_id,
                state,
                step=step,
                progress=round(min(max(progress, 0.0), 1.0), 4),
                takes=self.takes,
                pid=os.getpid(),
                **fields,
            )
        )

    def take(self, index: int, error: LipstreamError | Exception | None = None) -> None:
        self.takes[str(index)] = {
            "status": CAPTURED if error is None else TAKE_FAILED,
            "error": None if error is None else error_json(error, f"takes[{index}]"),
        }

    def fail(self, error: dict[str, Any]) -> None:
        self.write(FAILED, "failed", 0.0, error=error)


def run(session: Session, models_dir: Path, min_takes: int, job: Job) -> None:
    from ..capture.jobs import CaptureJob

    takes = session.takes()
    jobs = {
        index: CaptureJob(path, session.sentences[index], f"take-{index:03d}")
        for index, path in takes.items()
        if index < len(session.sentences)
    }
    tracked = _track(jobs, job)
    clips = _align(tracked, job)
    if len(clips) < min_takes:
        job.fail(_too_few(len(clips), min_takes, job))
        return
    try:
        trained = _train(session, clips, job)
    except Exception as error:  # a fault in training fails this job, and says why
        job.fail({**error_json(error, "training"), "code": TRAINING_FAILED, "message": str(error)})
        return
    target = models_dir / session.name
    if target.exists():
        job.fail(
            {
                "code": NAME_TAKEN,
                "message": f"a character {session.name!r} was trained meanwhile",
                "where": "name",
            }
        )
        return
    models_dir.mkdir(parents=True, exist_ok=True)
    os.replace(trained, target)
    bump_generation(models_dir)
    job.write(LOADING, "loading the character into the server", 0.0, character=session.name)


def _track(jobs: dict[int, Any], job: Job) -> dict[int, tuple[Any, Any, Any]]:
    from ..capture.pipeline import tracked_video

    tracked = {}
    for number, (index, capture_job) in enumerate(jobs.items()):
        job.write(CAPTURING, f"tracking the face in take {index}", number / len(jobs))
        where = f"takes[{index}]"
        try:
            audio, track = tracked_video(capture_job.video, where)
            tracked[index] = (capture_job, audio, track)
        except Exception as error:  # noqa: BLE001 - every failure is the take's, named
            job.take(index, error)
    return tracked


def _align(tracked: dict[int, tuple[Any, Any, Any]], job: Job) -> list[Any]:
    from ..capture.pipeline import TrackedClip
    from ..capture.pose import face_frame
    from ..frontends.align import align

    clips = []
    for number, (index, (capture_job, audio, track)) in enumerate(tracked.items()):
        job.write(ALIGNING, f"aligning the speech of take {index}", number / len(tracked))
        try:
            alignment = align(audio, capture_job.transcript, where=f"takes[{index}]")
            face = face_frame(track.landmarks)
        except Exception as error:  # noqa: BLE001 - every failure is the take's, named
            job.take(index, error)
            continue
        job.take(index)
        clips.append(TrackedClip(capture_job, track.times, face, audio, alignment))
    return clips


def _too_few(good: int, needed: int, job: Job) -> dict[str, Any]:
    failed = [
        {"take": int(index), **take["error"]}
        for index, take in sorted(job.takes.items(), key=lambda item: int(item[0]))
        if take["error"] is not None
    ]
    listed = "; ".join(
        f"take {item['take']}: {item['code']} ({item['message']})" for item in failed
    )
    return {
        "code": TOO_FEW_TAKES,
        "message": f"{good} good recording(s), at least {needed} needed"
        + (f"; failed: {listed}" if listed else ""),
        "where": "takes",
        "takes": failed,
    }


def _train(session: Session, clips: Sequence[Any], job: Job) -> Path:
    """The recipe's engines trained on ``clips`` into the session's staging directory."""
    from ..capture.pipeline import clips_corpus
    from ..corpus import write_corpus
    from ..engines import load_model
    from ..server.catalog import warm_kernels
    from ..training import train_engine

    job.write(TRAINING, "building the corpus", 0.0)
    corpus = clips_corpus(clips, session.name)
    shutil.rmtree(session.corpus_dir, ignore_errors=True)
    write_corpus(corpus, session.corpus_dir)
    staging = session.staging_dir
    shutil.rmtree(staging, ignore_errors=True)
    for number, engine in enumerate(ENGINES):
        job.write(TRAINING, f"training {engine}", number / len(ENGINES))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            train_engine(corpus, engine, staging / engine)
        warm_kernels(load_model(staging / engine))
    return staging


def main(argv: Sequence[str]) -> int:
    session_dir, models_dir, min_takes, job_id = argv
    directory = Path(session_dir)
    document = read_json(directory / SESSION_FILE) or {}
    session = Session(directory, str(document["name"]), tuple(document["sentences"]))
    job = Job(session, job_id)
    try:
        run(session, Path(models_dir), int(min_takes), job)
    except Exception as error:  # the job ends with its state written, whatever fails
        job.fail(error_json(error, None))
        raise
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
