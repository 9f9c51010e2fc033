"""Noticing, in every worker, the characters a training job has published.

Sketch: a job moves a character's finished model directories into the models directory
(``models/<name>/<engine>``, one rename) and then rewrites ``models/GENERATION``. Each
worker runs a ``ModelWatcher`` thread that reads that file's stat every ``interval_s``
(a cheap system call, off the event loop) and, when it changed (and once at start, for the
characters trained before), hands the character directories it has not seen to ``load``
on the same thread; a character is handed over once, whether it loads or not.
"""

from __future__ import annotations

import logging
import os
import secrets
import threading
from collections.abc import Callable
from pathlib import Path

logger = logging.getLogger("lipstream.recording")

GENERATION_FILE = "GENERATION"
INTERVAL_S = 1.0


def bump_generation(models_dir: Path) -> None:
    """Tell the watchers that ``models_dir`` has changed."""
    path = models_dir / GENERATION_FILE
    temporary = path.with_name(f".{GENERATION_FILE}.{os.getpid()}.tmp")
    temporary.write_text(secrets.token_hex(8) + "\n")
    os.replace(temporary, path)


class ModelWatcher:
    """Hands each new character directory of ``models_dir`` to ``load``, once."""

    def __init__(
        self,
        models_dir: Path,
        load: Callable[[list[Path]], None],
        interval_s: float = INTERVAL_S,
    ) -> None:
        self.models_dir = models_dir
        self.load = load
        self.interval_s = interval_s
        self.seen: set[str] = set()
        self.stamp: tuple[int, int, int] | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def check(self) -> list[Path]:
        """Hand over the characters published since the last check; those handed over."""
        stamp = self._stamp()
        if stamp is not None and stamp == self.stamp:
            return []
        self.stamp = stamp
        if not self.models_dir.is_dir():
            return []
        new = sorted(
            path
            for path in self.models_dir.iterdir()
            if path.is_dir() and not path.name.startswith(".") and path.name not in self.seen
        )
        self.seen.update(path.name for path in new)
        if new:
            self.load(new)
        return new

    def _stamp(self) -> tuple[int, int, int] | None:
        try:
            status = (self.models_dir / GENERATION_FILE).stat()
        except OSError:
            return None
        return (status.st_mtime_ns, status.st_ino, status.st_size)

    def start(self) -> None:
        self._thread = threading.Thread(
            target=self._run, name="lipstream-model-watcher", daemon=True
        )
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self.check()
            except Exception:  # one bad directory must not stop the watching
                logger.exception("watching %s failed", self.models_dir)
            self._stop.wait(self.interval_s)
