"""Which jobs run, and which died: the job file's state and its process, over workers."""

from __future__ import annotations

import os
import subprocess
import sys

from lipstream.recording.runner import job_document, lost, running


def dead_pid() -> int:
    process = subprocess.Popen([sys.executable, "-c", "pass"])
    process.wait()
    return process.pid


def test_a_job_runs_while_its_process_lives_or_it_is_queued() -> None:
    gone = dead_pid()
    assert running(job_document("j", "capturing", pid=os.getpid()))
    assert not running(job_document("j", "capturing", pid=gone))
    assert running(job_document("j", "queued"))
    for state in ("loading", "done", "failed"):
        assert not running(job_document("j", state, pid=os.getpid()))
    assert not running(None)


def test_a_job_whose_process_died_at_work_is_failed_as_lost() -> None:
    gone = dead_pid()
    died = lost(job_document("j", "training", pid=gone, progress=0.5))
    assert (died["state"], died["error"]["code"]) == ("failed", "job_lost")
    for state in ("queued", "loading", "done"):
        kept = job_document("j", state, pid=gone)
        assert lost(kept) == kept
    alive = job_document("j", "aligning", pid=os.getpid())
    assert lost(alive) == alive
