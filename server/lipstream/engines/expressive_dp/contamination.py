"""Contaminated nodes: a set of node ids kept in ``contamination.json`` beside the model.

Method. Marking or restoring nodes rewrites only that small file (written to a
temporary name and renamed over, so a reader never sees half of it), never the
model's arrays. A model re-reads the file whenever its modification time or
size changes, checked when a search starts, so every worker process serving the
model honours a change from the next search on. A model without a directory
(trained in memory) keeps the set in memory. At least one node stays
uncontaminated. A file that is not a JSON object
``{"nodes": [ids]}`` of node ids of this model is a ``model_invalid`` error
naming the file.
"""

from __future__ import annotations

import json
import os
import threading
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from ...errors import InvalidRequestError, ModelStoreError

FILE_NAME = "contamination.json"
MAX_FILE_BYTES = 16 * 1024 * 1024


class Contamination:
    """The contaminated nodes of a model with ``size`` nodes, stored under ``directory``."""

    def __init__(self, size: int, directory: Path | None) -> None:
        self.size = size
        self.path = None if directory is None else directory / FILE_NAME
        self._lock = threading.Lock()
        self._stamp: tuple[int, int] | None = None
        self._mask = np.zeros(size, dtype=bool)

    def mask(self) -> np.ndarray:
        """(N,) true for every contaminated node, as of the file now (a private copy)."""
        with self._lock:
            self._refresh()
            return self._mask.copy()

    def nodes(self) -> list[int]:
        return [int(node) for node in np.flatnonzero(self.mask())]

    def change(self, mark: Iterable[int], restore: Iterable[int]) -> list[int]:
        """Mark ``mark`` and restore ``restore`` (node ids), persist, and return the set."""
        marked, restored = list(mark), list(restore)
        for field, ids in (("mark", marked), ("restore", restored)):
            for position, node in enumerate(ids):
                if isinstance(node, bool) or not isinstance(node, int) or not 0 <= node < self.size:
                    raise InvalidRequestError(
                        f"node {node!r} does not exist: node ids run from 0 to {self.size - 1}",
                        where=f"{field}[{position}]",
                    )
        with self._lock:
            self._refresh()
            mask = self._mask.copy()
            mask[marked] = True
            mask[restored] = False
            if mask.all():
                raise InvalidRequestError(
                    "marking every node contaminated would leave nothing to search",
                    where="mark",
                )
            self._write(mask)
            self._mask = mask
            return [int(node) for node in np.flatnonzero(mask)]

    def _refresh(self) -> None:
        if self.path is None:
            return
        try:
            status = self.path.stat()
        except FileNotFoundError:
            self._stamp, self._mask = None, np.zeros(self.size, dtype=bool)
            return
        stamp = (status.st_mtime_ns, status.st_size)
        if stamp != self._stamp:
            self._mask = self._read()
            self._stamp = stamp

    def _read(self) -> np.ndarray:
        assert self.path is not None
        where = str(self.path)
        try:
            if self.path.stat().st_size > MAX_FILE_BYTES:
                raise ModelStoreError(f"is larger than {MAX_FILE_BYTES} bytes", where=where)
            document = json.loads(self.path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
            raise ModelStoreError(f"cannot be read: {error}", where=where) from error
        nodes = document.get("nodes") if isinstance(document, dict) else None
        if not isinstance(nodes, list) or not all(
            isinstance(node, int) and not isinstance(node, bool) and 0 <= node < self.size
            for node in nodes
        ):
            raise ModelStoreError(
                f'must be {{"nodes": [ids]}} with node ids in [0, {self.size})', where=where
            )
        mask = np.zeros(self.size, dtype=bool)
        mask[nodes] = True
        return mask

    def _write(self, mask: np.ndarray) -> None:
        if self.path is None:
            return
        partial = self.path.with_name(f".{FILE_NAME}.{os.getpid()}.{threading.get_ident()}")
        body = json.dumps({"nodes": [int(node) for node in np.flatnonzero(mask)]})
        partial.write_text(body, encoding="utf-8")
        os.replace(partial, self.path)
        status = self.path.stat()
        self._stamp = (status.st_mtime_ns, status.st_size)
