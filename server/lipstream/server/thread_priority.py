"""The server's pool threads below its event loop in the CPU scheduler's eyes.

Sketch: a pool thread busy with a long job (a JSON flood's frames, an audio flood's
features, a search) shares a core with the event loop by the scheduler's fair share: with
two such threads the loop gets a third of the core, and everything it does, every session's
frames and every health probe, takes three times as long (a soak on one core measured loop
turns of 100-330 ms of wall time for 50-140 ms of the loop's own CPU). Linux lets a thread
raise its own niceness (``setpriority`` on its thread id), so each worker thread of the
server's pools lowers itself by ``POOL_NICENESS`` when it starts: the loop thread, at the
process's priority, runs whenever it has work, and the pools take the rest of the core.
Elsewhere, or where the call is refused, nothing changes.
"""

from __future__ import annotations

import os
import threading

POOL_NICENESS = 10
MAX_NICENESS = 19


def lower_this_thread() -> None:
    """Make the calling thread ``POOL_NICENESS`` nicer than it is (Linux; else nothing)."""
    try:
        thread = threading.get_native_id()
        niceness = os.getpriority(os.PRIO_PROCESS, thread)
        os.setpriority(os.PRIO_PROCESS, thread, min(MAX_NICENESS, niceness + POOL_NICENESS))
    except (AttributeError, OSError):
        pass
