"""``lipstream.loadtest.cpu``: finding a port's server processes in ``/proc``, and their CPU."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from lipstream.loadtest.cpu import ServerCpu, cpu_seconds, listening_inodes, pids_holding

HEADER = (
    "  sl  local_address rem_address   st tx_queue rx_queue tr tm->when retrnsmt   uid  "
    "timeout inode\n"
)
TICKS = os.sysconf("SC_CLK_TCK")


def _socket_line(port: int, state: str, inode: int) -> str:
    return (
        f"   0: 0100007F:{port:04X} 00000000:0000 {state} 00000000:00000000 00:00000000 "
        f"00000000  1000        0 {inode} 1 0000000000000000 100 0 0 10 0\n"
    )


def _stat(pid: int, utime: int, stime: int) -> str:
    # A command name with spaces and a parenthesis, as the kernel allows.
    return (
        f"{pid} (lip stream) worker) S 1 {pid} {pid} 0 -1 4194560 100 0 0 0 {utime} {stime} "
        "0 0 20 0 3 0 100 1000000 1000 18446744073709551615\n"
    )


def _process(proc: Path, pid: int, sockets: list[int], utime: int, stime: int) -> None:
    (proc / str(pid) / "fd").mkdir(parents=True)
    for number, inode in enumerate(sockets):
        os.symlink(f"socket:[{inode}]", proc / str(pid) / "fd" / str(number + 3))
    os.symlink("/dev/null", proc / str(pid) / "fd" / "0")
    (proc / str(pid) / "stat").write_text(_stat(pid, utime, stime))


@pytest.fixture
def proc(tmp_path: Path) -> Path:
    (tmp_path / "net").mkdir()
    (tmp_path / "net" / "tcp").write_text(
        HEADER
        + _socket_line(8000, "0A", 111)  # listening on 8000
        + _socket_line(8000, "01", 222)  # an established connection to it
        + _socket_line(9000, "0A", 333)
    )  # another server
    (tmp_path / "net" / "tcp6").write_text(HEADER + _socket_line(8000, "0A", 444))
    _process(tmp_path, 10, [111], utime=300, stime=100)  # uvicorn supervisor
    _process(tmp_path, 11, [444, 222], utime=50, stime=25)  # a worker
    _process(tmp_path, 12, [333], utime=999, stime=999)  # unrelated
    (tmp_path / "self").mkdir()  # not a PID
    return tmp_path


def test_the_listening_sockets_of_a_port_and_their_holders_are_found(proc: Path) -> None:
    assert listening_inodes(8000, proc) == {"111", "444"}
    assert listening_inodes(9000, proc) == {"333"}
    assert listening_inodes(7000, proc) == set()
    assert pids_holding({"111", "444"}, proc) == [10, 11]
    assert pids_holding(set(), proc) == []


def test_cpu_seconds_sum_user_and_system_ticks(proc: Path) -> None:
    assert cpu_seconds([10, 11], proc) == pytest.approx((300 + 100 + 50 + 25) / TICKS)
    assert cpu_seconds([10, 99], proc) == pytest.approx(400 / TICKS)  # 99 has exited
    assert cpu_seconds([99], proc) is None


def test_server_cpu_marks_the_time_used_between_calls(proc: Path) -> None:
    server = ServerCpu(8000, proc)
    assert server.pids == [10, 11]
    (proc / "11" / "stat").write_text(_stat(11, utime=50 + 2 * TICKS, stime=25 + TICKS))
    assert server.mark() == pytest.approx(3.0)
    assert server.mark() == pytest.approx(0.0)
    assert ServerCpu(7000, proc).mark() is None


def test_a_missing_proc_gives_none(tmp_path: Path) -> None:
    assert ServerCpu(8000, tmp_path / "absent").mark() is None
