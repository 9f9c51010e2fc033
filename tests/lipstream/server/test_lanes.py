"""The fair lanes: round-robin order between keys, the bound on what one key's queue delays
another's job (sans-I/O, on ``FairQueue``), and the lane's threads taking jobs in that order."""

from __future__ import annotations

import random
import threading
from collections import Counter, defaultdict
from concurrent.futures import CancelledError

import pytest

from lipstream.server.lanes import FairLane, FairQueue


def drain(queue: FairQueue[str, str]) -> list[str]:
    taken = []
    while (item := queue.pop()) is not None:
        taken.append(item)
    return taken


def test_keys_take_turns_and_each_keeps_its_own_order() -> None:
    queue: FairQueue[str, str] = FairQueue()
    for item in ("a1", "a2", "a3", "a4"):
        queue.push("a", item)
    queue.push("b", "b1")
    queue.push("b", "b2")
    queue.push("c", "c1")
    assert (len(queue), queue.keys) == (7, 3)
    assert drain(queue) == ["a1", "b1", "c1", "a2", "b2", "a3", "a4"]
    assert (len(queue), queue.keys, queue.pop()) == (0, 0, None)


def test_a_key_that_ran_dry_rejoins_at_the_back_of_the_round() -> None:
    queue: FairQueue[str, str] = FairQueue()
    queue.push("a", "a1")
    queue.push("b", "b1")
    queue.push("b", "b2")
    assert queue.pop() == "a1"  # a has nothing more: it leaves the round
    queue.push("a", "a2")  # ... and rejoins behind b
    assert drain(queue) == ["b1", "a2", "b2"]


def test_a_long_queue_delays_another_keys_job_by_one_of_its_jobs() -> None:
    queue: FairQueue[str, str] = FairQueue()
    for index in range(1000):
        queue.push("flood", f"f{index}")
    assert queue.pop() == "f0"
    queue.push("late", "late")
    assert queue.ahead("late") == 1
    assert [queue.pop(), queue.pop()] == ["f1", "late"]


def test_the_bound_holds_under_random_pushes_and_pops() -> None:
    """Brute force over random schedules: between the moment a job becomes the oldest of its
    key and the moment it is taken, every other key has at most one job taken, and
    ``ahead`` counted exactly the jobs taken in between."""
    rng = random.Random(29)
    for _ in range(200):
        queue: FairQueue[str, tuple[str, int]] = FairQueue()
        pending: dict[str, list[int]] = defaultdict(list)  # the model: per-key FIFO
        taken_since: dict[str, Counter[str]] = {}  # key -> other keys' jobs taken since its head
        predicted: dict[str, int] = {}
        serial = 0
        for _ in range(rng.randrange(1, 120)):
            if rng.random() < 0.55:
                key = rng.choice("abcdef")
                if not pending[key]:
                    predicted[key] = queue.ahead(key)
                    taken_since[key] = Counter()
                queue.push(key, (key, serial))
                pending[key].append(serial)
                serial += 1
                continue
            item = queue.pop()
            if item is None:
                assert not any(pending.values())
                continue
            key, number = item
            assert pending[key].pop(0) == number  # each key's own order
            waited = taken_since.pop(key)
            assert all(count <= 1 for count in waited.values()), waited
            assert sum(waited.values()) == predicted.pop(key)
            for other in taken_since:
                taken_since[other][key] += 1
            if pending[key]:  # its next job is now the oldest: its wait starts
                predicted[key] = queue.ahead(key)
                taken_since[key] = Counter()


def held(gate: threading.Event, started: threading.Event) -> bool:
    started.set()
    return gate.wait()


def test_a_lane_thread_takes_the_jobs_in_turn() -> None:
    waits: list[tuple[object, int]] = []
    lane = FairLane(1, "test-lane", lambda key, ahead: waits.append((key, ahead)))
    gate, started = threading.Event(), threading.Event()
    order: list[str] = []
    try:
        first = lane.submit_as("a", held, gate, started)
        assert started.wait(timeout=30)  # its thread holds it: the rest queue behind
        futures = [lane.submit_as("a", order.append, f"a{i}") for i in (2, 3, 4)]
        futures.append(lane.submit_as("b", order.append, "b1"))
        futures.append(lane.client("c").submit(order.append, "c1"))
        gate.set()
        assert first.result(timeout=30)
        for future in futures:
            future.result(timeout=30)
        assert order == ["a2", "b1", "c1", "a3", "a4"]
        # The jobs started while each waited: all of them were queued while "a"'s first ran.
        assert waits == [("a", 0), ("a", 0), ("b", 1), ("c", 2), ("a", 3), ("a", 4)]
    finally:
        gate.set()
        lane.shutdown()


def test_a_lane_hands_back_errors_skips_cancelled_jobs_and_cancels_the_queue_on_shutdown() -> None:
    lane = FairLane(1, "test-lane")
    gate, started = threading.Event(), threading.Event()
    ran: list[str] = []
    running = lane.submit(held, gate, started)
    assert started.wait(timeout=30)
    skipped = lane.submit_as("a", ran.append, "skipped")
    failing = lane.submit_as("b", lambda: 1 // 0)
    queued = [lane.submit_as("c", ran.append, "c1"), lane.submit_as("c", ran.append, "c2")]
    assert skipped.cancel()
    gate.set()
    with pytest.raises(ZeroDivisionError):
        failing.result(timeout=30)
    for future in queued:
        future.result(timeout=30)
    assert ran == ["c1", "c2"] and skipped.cancelled() and running.result()
    gate.clear()
    started.clear()
    blocker = lane.submit(held, gate, started)
    assert started.wait(timeout=30)
    left = lane.submit_as("d", ran.append, "never")
    lane.shutdown(wait=False, cancel_futures=True)
    gate.set()
    assert blocker.result(timeout=30)
    with pytest.raises(CancelledError):
        left.result(timeout=30)
    assert "never" not in ran
    with pytest.raises(RuntimeError):
        lane.submit(ran.append, "late")
