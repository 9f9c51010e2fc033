"""CPU time of the processes serving a loopback port, read from Linux's ``/proc``.

Sketch: a load test shares the machine with the server it measures, so an
honest figure says how much CPU each side used. The server's processes are
found without asking for a PID: the kernel lists listening TCP sockets with
their inode in ``/proc/net/tcp`` and ``/proc/net/tcp6``, and every process
holding one of those inodes has a ``socket:[inode]`` link in
``/proc/<pid>/fd`` (uvicorn's workers inherit the listening socket from
their supervisor, so all of them are found). Their CPU time is the user plus
system clock ticks in ``/proc/<pid>/stat``. Where ``/proc`` is missing or
unreadable (another OS, another user's server), the answer is None.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

PROC = Path("/proc")
_LISTEN_STATE = "0A"
_TICKS_PER_S = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def listening_inodes(port: int, proc: Path = PROC) -> set[str]:
    """Inodes of the TCP sockets listening on ``port`` (IPv4 and IPv6)."""
    inodes: set[str] = set()
    for table in ("tcp", "tcp6"):
        try:
            lines = (proc / "net" / table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if len(fields) < 10 or fields[3] != _LISTEN_STATE:
                continue
            local_port = int(fields[1].rsplit(":", 1)[1], 16)
            if local_port == port and fields[9] != "0":
                inodes.add(fields[9])
    return inodes


def pids_holding(inodes: set[str], proc: Path = PROC) -> list[int]:
    """PIDs of the processes that have a file descriptor on one of the socket ``inodes``."""
    if not inodes:
        return []
    wanted = {f"socket:[{inode}]" for inode in inodes}
    found: list[int] = []
    for entry in proc.iterdir():
        if not entry.name.isdigit():
            continue
        if any(_link(fd) in wanted for fd in _descriptors(entry)):
            found.append(int(entry.name))
    return sorted(found)


def _descriptors(process: Path) -> list[Path]:
    try:
        return list((process / "fd").iterdir())
    except OSError:
        return []


def _link(descriptor: Path) -> str | None:
    # A descriptor closed between listing and reading must not hide its process's others.
    try:
        return os.readlink(descriptor)
    except OSError:
        return None


def cpu_seconds(pids: Iterable[int], proc: Path = PROC) -> float | None:
    """User + system CPU seconds of ``pids``; None if none of them can be read."""
    total_ticks, read = 0, False
    for pid in pids:
        try:
            stat = (proc / str(pid) / "stat").read_text()
        except OSError:
            continue
        # Fields after the parenthesised command name; utime and stime are fields 14 and 15.
        fields = stat[stat.rindex(")") + 2 :].split()
        total_ticks += int(fields[11]) + int(fields[12])
        read = True
    return total_ticks / _TICKS_PER_S if read else None


class ServerCpu:
    """CPU seconds used by the processes listening on a port, between ``mark`` calls."""

    def __init__(self, port: int, proc: Path = PROC) -> None:
        self.proc = proc
        self.pids = pids_holding(listening_inodes(port, proc), proc)
        self._last = self.total()

    def total(self) -> float | None:
        return cpu_seconds(self.pids, self.proc) if self.pids else None

    def mark(self) -> float | None:
        """CPU seconds since the previous mark (or since construction); None if unknown."""
        now = self.total()
        used = None if now is None or self._last is None else now - self._last
        self._last = now
        return used
