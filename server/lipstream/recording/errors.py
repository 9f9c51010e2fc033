"""The coded errors of recording sessions and their jobs (a take's capture failures keep
capture's own codes: ``no_face``, ``corrupt_video``, ``alignment_failed``...)."""

from __future__ import annotations

RECORDINGS_DISABLED = "recordings_disabled"
NAME_TAKEN = "name_taken"
INVALID_NAME = "invalid_name"
UNKNOWN_RECORDING = "unknown_recording"
UNKNOWN_TAKE = "unknown_take"
TAKE_TOO_LARGE = "take_too_large"
TOO_MANY_TAKES = "too_many_takes"
JOB_RUNNING = "job_running"
TOO_FEW_TAKES = "too_few_takes"
TRAINING_FAILED = "training_failed"
LOAD_FAILED = "load_failed"
JOB_LOST = "job_lost"
