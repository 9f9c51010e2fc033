"""The open-file limit: raised at start as far as the hard limit allows, and the connection cap it
leaves.

Sketch: every connection holds a file descriptor, and a process usually starts with a soft
``RLIMIT_NOFILE`` of 1024 even where its hard limit is far higher. Once the descriptors run
out, ``accept`` fails with ``EMFILE`` on every turn of the event loop: no new connection, not
even a health probe, gets in, and asyncio logs the failure each time. So ``serve`` raises the
soft limit to the hard one (capped at ``NOFILE_TARGET``: beyond it the kernel's tables, not the
limit, bound the process) before uvicorn starts; the workers inherit it. ``connection_cap``
keeps ``FILE_RESERVE`` descriptors below the soft limit for everything that is not a
connection (model files, logs, the event loop's own, metrics files), so the connection cap
refuses before ``accept`` can fail.
"""

from __future__ import annotations

import resource
from dataclasses import dataclass

NOFILE_TARGET = 1 << 20
FILE_RESERVE = 128


@dataclass(frozen=True)
class OpenFileLimit:
    """The soft and hard ``RLIMIT_NOFILE`` of this process (``RLIM_INFINITY`` as -1)."""

    soft: int
    hard: int


def open_file_limit() -> OpenFileLimit:
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    return OpenFileLimit(soft, hard)


def raise_open_file_limit(target: int = NOFILE_TARGET) -> OpenFileLimit:
    """Raise the soft limit towards ``target``, never above the hard limit; the limit now in
    force (unchanged when the system refuses)."""
    current = open_file_limit()
    wanted = target if current.hard == resource.RLIM_INFINITY else min(target, current.hard)
    if current.soft != resource.RLIM_INFINITY and current.soft < wanted:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (wanted, current.hard))
        except (ValueError, OSError):
            return current
    return open_file_limit()


def connection_cap(max_connections: int, limit: OpenFileLimit) -> int:
    """``max_connections``, lowered to leave ``FILE_RESERVE`` descriptors free (at least 1)."""
    if limit.soft == resource.RLIM_INFINITY:
        return max_connections
    return max(1, min(max_connections, limit.soft - FILE_RESERVE))
