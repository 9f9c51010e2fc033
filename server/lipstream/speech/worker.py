"""Speech in a worker process: libespeak-ng's failures end a batch, never the caller.

Sketch: ``speak_in_worker`` runs ``libespeak.py`` as a script under a fresh,
isolated interpreter (``python -I``: standard library only, so it starts in
tens of milliseconds), writes the batch as JSON to its stdin and reads its
reply (a JSON line, then the PCM of each request) under a timeout. A worker
that crashes (libespeak-ng has segfaulted in a busy test process), hangs past
the timeout or answers nonsense is a ``SpeechError`` for that batch; the worker
is killed on timeout. A fresh process also starts from the library's initial
state, so a batch's output depends on the batch alone.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ..errors import SpeechError
from . import libespeak
from .libespeak import RawSpeech, WordEvent

WORKER_SCRIPT = Path(libespeak.__file__).resolve()
STARTUP_TIMEOUT_S = 10.0
TIMEOUT_PER_REQUEST_S = 5.0


@dataclass(frozen=True)
class SpeechRequest:
    """One utterance for the worker: text and an espeak-ng voice setting; ``ipa_names``
    asks for the phoneme events' names in IPA (the same for every request of a batch)."""

    text: str
    voice: str = "en-us"
    rate: int = 175
    pitch: int = 50
    pitch_range: int = 50
    ipa_names: bool = False


@dataclass(frozen=True)
class WordedSpeech:
    """espeak-ng's raw output for one request and the words it spoke (``WordEvent``s)."""

    raw: RawSpeech
    words: list[WordEvent]


def speak_in_worker(
    requests: Sequence[SpeechRequest], timeout_s: float | None = None
) -> list[RawSpeech]:
    """espeak-ng's raw output for each request, spoken in order by one fresh worker process
    (``timeout_s``: default 10 s plus 5 s per request)."""
    return [spoken.raw for spoken in speak_words_in_worker(requests, timeout_s)]


def speak_words_in_worker(
    requests: Sequence[SpeechRequest], timeout_s: float | None = None
) -> list[WordedSpeech]:
    """``speak_in_worker`` with the word events of each request."""
    if not requests:
        return []
    payload = json.dumps([request.__dict__ for request in requests]).encode("utf-8")
    limit = timeout_s or STARTUP_TIMEOUT_S + TIMEOUT_PER_REQUEST_S * len(requests)
    try:
        finished = subprocess.run(
            [sys.executable, "-I", str(WORKER_SCRIPT)],
            input=payload,
            capture_output=True,
            timeout=limit,
            check=False,
        )
    except subprocess.TimeoutExpired:
        raise SpeechError(f"espeak-ng did not finish within {limit:g} s", where="espeak") from None
    except OSError as exc:
        raise SpeechError(f"cannot start the speech worker: {exc}", where="espeak") from None
    if finished.returncode != 0:
        detail = finished.stderr.decode("utf-8", "replace").strip().splitlines()[-3:]
        raise SpeechError(
            f"the espeak-ng worker exited with status {finished.returncode}"
            + (f": {' | '.join(detail)}" if detail else ""),
            where="espeak",
        )
    return _reply(finished.stdout, len(requests))


def _reply(output: bytes, n_requests: int) -> list[WordedSpeech]:
    line, _, pcm = output.partition(b"\n")
    try:
        header = json.loads(line.decode("utf-8"))
        if "error" in header:
            error = header["error"]
            raise SpeechError(str(error["message"]), where=str(error["where"]))
        results = header["results"]
        raws: list[WordedSpeech] = []
        offset = 0
        for result in results:
            size = int(result["n_bytes"])
            events = [(str(name), int(ms)) for name, ms in result["events"]]
            words = [(int(first), int(length), int(ms)) for first, length, ms in result["words"]]
            raw = (pcm[offset : offset + size], int(result["sample_rate"]), events)
            raws.append(WordedSpeech(raw, words))
            offset += size
    except (ValueError, KeyError, TypeError, UnicodeDecodeError) as exc:
        raise SpeechError(
            f"the espeak-ng worker answered nonsense: {exc}", where="espeak"
        ) from None
    if len(raws) != n_requests or offset != len(pcm):
        raise SpeechError("the espeak-ng worker's reply does not match the batch", where="espeak")
    return raws
