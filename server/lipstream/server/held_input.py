"""The audio input every request of the process holds, counted against the memory ceiling.

Sketch: the resident-memory check at ``start`` cannot see what a request takes
in afterwards, and a request may send 1000 s of audio at 192 kHz. Engines that
read audio keep only its features and a window of samples
(``engines.streamed_features``), and each request's ``Holding`` reports what its
synthesizer holds (``Synthesizer.held_input_bytes``) after every message. Before
a chunk is taken in, ``admit`` asks whether the process's total, plus the chunk
while it is decoded and analysed, stays within ``budget_bytes`` (the
``max_input_mb`` setting, by default a share of the memory ceiling); if not,
that request alone ends with ``input_too_large``. Sessions run in several
threads (the synthesis pools), so the totals change under a lock.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from lipstream_client.errors import INPUT_TOO_LARGE

from ..config import ServerSettings
from .request import RequestError

AUTO_INPUT_SHARE = 0.25
"""Of the memory ceiling, what held input may take when ``max_input_mb`` is 0."""
MIB = 1 << 20
UNLIMITED_INPUT = 1 << 62


class InputLedger:
    """Bytes held by every request's input (``held``), and the most ever held (``peak``)."""

    def __init__(
        self, budget_bytes: int, observe: Callable[[int, int], None] | None = None
    ) -> None:
        """``observe(held, peak)`` after every change (the metrics)."""
        self.budget_bytes = budget_bytes
        self.observe = observe
        self.held = 0
        self.peak = 0
        self.refused = 0
        self.lock = threading.Lock()

    def holding(self) -> Holding:
        return Holding(self)

    def change(self, delta: int) -> None:
        with self.lock:
            self.add(delta)

    def add(self, delta: int) -> None:
        """Under the lock."""
        self.held += delta
        self.peak = max(self.peak, self.held)
        if self.observe is not None:
            self.observe(self.held, self.peak)


class Holding:
    """What one request holds in its ledger."""

    def __init__(self, ledger: InputLedger) -> None:
        self.ledger = ledger
        self.bytes = 0

    def admit(self, needed: int) -> None:
        """Count ``needed`` bytes as this request's if the process may hold them, else
        ``RequestError`` (``input_too_large``)."""
        ledger = self.ledger
        with ledger.lock:
            others = ledger.held - self.bytes
            fits = others + needed <= ledger.budget_bytes
            if fits:
                ledger.add(needed - self.bytes)
                self.bytes = needed
            else:
                ledger.refused += 1
        if fits:
            return
        raise RequestError(
            f"taking in this audio, the request would hold up to {needed} bytes of input "
            f"beside the {others} the server's other requests hold, past the limit of "
            f"{ledger.budget_bytes} (LIPSTREAM_MAX_INPUT_MB); this request has ended",
            code=INPUT_TOO_LARGE,
            where="audio",
            details={
                "needed_bytes": needed,
                "held_bytes": others,
                "max_input_bytes": ledger.budget_bytes,
            },
        )

    def update(self, held: int) -> None:
        """The request now holds ``held`` bytes."""
        if held != self.bytes:
            self.ledger.change(held - self.bytes)
            self.bytes = held

    def release(self) -> None:
        self.update(0)


def input_budget_bytes(settings: ServerSettings, memory_ceiling_mb: float) -> int:
    """``max_input_mb``, or when 0, ``AUTO_INPUT_SHARE`` of the memory ceiling, in bytes."""
    megabytes = settings.max_input_mb or AUTO_INPUT_SHARE * memory_ceiling_mb
    return int(megabytes * MIB)
