"""The server's pool threads run nicer than the thread that made them, and only they do."""

from __future__ import annotations

import os
import sys
import threading
from concurrent.futures import ThreadPoolExecutor

import pytest

from lipstream.server.lanes import FairLane
from lipstream.server.thread_priority import MAX_NICENESS, POOL_NICENESS, lower_this_thread

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="per-thread niceness is Linux's")


def niceness() -> int:
    return os.getpriority(os.PRIO_PROCESS, threading.get_native_id())


def expected(base: int) -> int:
    return min(MAX_NICENESS, base + POOL_NICENESS)


def test_a_lanes_threads_and_a_pools_threads_are_lowered_and_this_one_is_not() -> None:
    base = niceness()
    lane = FairLane(2, "test-lane", initializer=lower_this_thread)
    try:
        assert lane.submit(niceness).result(timeout=10) == expected(base)
    finally:
        lane.shutdown()
    with ThreadPoolExecutor(1, initializer=lower_this_thread) as pool:
        assert pool.submit(niceness).result(timeout=10) == expected(base)
    plain = FairLane(1, "plain-lane")
    try:
        assert plain.submit(niceness).result(timeout=10) == base
    finally:
        plain.shutdown()
    assert niceness() == base  # the calling thread keeps its priority


def test_a_thread_already_at_the_bottom_stays_there() -> None:
    def lowered_twice() -> int:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), MAX_NICENESS - 1)
        lower_this_thread()
        return niceness()

    with ThreadPoolExecutor(1) as pool:
        assert pool.submit(lowered_twice).result(timeout=10) == MAX_NICENESS
