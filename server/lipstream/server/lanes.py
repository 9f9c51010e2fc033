"""Fair lanes: thread pools that take turns between their clients instead of serving first
come, first served.

Sketch: a long job (a PQ-Matching search, a speech synthesis, a REST answer) holds a lane's
thread for as long as it runs, and a plain pool's one FIFO queue makes every job submitted
after it wait for it and for every job queued before it, whoever sent them: five
connections' searches once delayed another client's ``text`` request by 53.6 s. So a
``FairLane`` keeps one FIFO queue per client key (a WebSocket connection, a REST client's
address), and its threads take the next job from the keys in turn (``FairQueue``,
round-robin): a key with work queued is put at the back of the round after each of its
jobs starts. However many jobs one key queues, a job of another key waits, once it is
queued, for at most one job of each other key with work queued before its own turn (and the
jobs already running); a key's own jobs still run in the order it submitted them. Kinds of
work that must not wait behind each other at all get lanes of their own (``ServerState``:
``heavy`` for costly engine messages, ``speech`` for speech synthesis and REST).

So what one connection's queue may cost another's job is bounded in jobs (one per other
key with work queued), and each job in time: an engine call by the request's CPU budget
(``LIPSTREAM_REQUEST_CPU_S``), speech synthesis and REST by their own limits. The lane
reports, per job, how many jobs started between its submission and its own start
(``on_wait``, with the job's key: the ``lipstream_lane_jobs_ahead`` histogram).

``FairLane`` is a ``concurrent.futures.Executor``, so ``loop.run_in_executor`` takes it;
``client(key)`` is the executor submitting under ``key``, and ``submit`` without one uses a
key shared by all such callers.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable, Hashable
from concurrent.futures import Executor, Future
from typing import Any, Generic, TypeVar

K = TypeVar("K", bound=Hashable)
T = TypeVar("T")
SHARED_KEY = ("shared",)


class FairQueue(Generic[K, T]):
    """Items queued per key, taken from the keys in turn: ``pop`` takes the oldest item of
    the key whose turn it is, then puts that key at the back of the round if it has more.
    A key that had no items joins the round at its back."""

    def __init__(self) -> None:
        self._queues: dict[K, deque[T]] = {}
        self._turns: deque[K] = deque()
        self._size = 0

    def push(self, key: K, item: T) -> None:
        queue = self._queues.get(key)
        if queue is None:
            queue = self._queues[key] = deque()
            self._turns.append(key)
        queue.append(item)
        self._size += 1

    def pop(self) -> T | None:
        """The next item in turn, or None when nothing is queued."""
        if not self._turns:
            return None
        key = self._turns.popleft()
        queue = self._queues[key]
        item = queue.popleft()
        self._size -= 1
        if queue:
            self._turns.append(key)
        else:
            del self._queues[key]
        return item

    def ahead(self, key: K) -> int:
        """How many items are taken before ``key``'s next item would be: one of each key
        ahead of it in the round (a key not queued joins at the back)."""
        if key not in self._queues:
            return len(self._turns)
        return self._turns.index(key)

    @property
    def keys(self) -> int:
        """How many keys have items queued."""
        return len(self._turns)

    def __len__(self) -> int:
        return self._size


_Job = tuple[Future[Any], Callable[[], Any], int, Hashable]


class FairLane(Executor):
    """Up to ``threads`` daemon threads named ``name-N``, started as work arrives, taking
    jobs from a ``FairQueue``; ``on_wait`` gets, as each job starts, its key and how many
    jobs started while it waited; each thread calls ``initializer`` first, as a
    ``ThreadPoolExecutor``'s do."""

    def __init__(
        self,
        threads: int,
        name: str,
        on_wait: Callable[[Hashable, int], None] | None = None,
        initializer: Callable[[], None] | None = None,
    ) -> None:
        self.max_threads = threads
        self.name = name
        self.on_wait = on_wait
        self.initializer = initializer
        self.started = 0
        self._queue: FairQueue[Hashable, _Job] = FairQueue()
        self._changed = threading.Condition()
        self._threads: list[threading.Thread] = []
        self._idle = 0
        self._closed = False

    def client(self, key: Hashable) -> Executor:
        """The executor that submits to this lane under ``key``."""
        return _Client(self, key)

    def submit(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> Future[T]:
        return self.submit_as(SHARED_KEY, fn, *args, **kwargs)

    def submit_as(
        self, key: Hashable, fn: Callable[..., T], /, *args: Any, **kwargs: Any
    ) -> Future[T]:
        """Queue ``fn(*args, **kwargs)`` under ``key``; its result arrives in the future."""
        future: Future[T] = Future()
        with self._changed:
            if self._closed:
                raise RuntimeError(f"the {self.name} lane is shut down")
            self._queue.push(key, (future, lambda: fn(*args, **kwargs), self.started, key))
            if len(self._queue) > self._idle and len(self._threads) < self.max_threads:
                thread = threading.Thread(
                    target=self._work, name=f"{self.name}-{len(self._threads)}", daemon=True
                )
                self._threads.append(thread)
                thread.start()
            self._changed.notify()
        return future

    @property
    def queued(self) -> int:
        """Jobs waiting for a thread."""
        with self._changed:
            return len(self._queue)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        with self._changed:
            self._closed = True
            if cancel_futures:
                while (job := self._queue.pop()) is not None:
                    job[0].cancel()
            self._changed.notify_all()
        if wait:
            for thread in list(self._threads):
                if thread is not threading.current_thread():
                    thread.join()

    def _work(self) -> None:
        if self.initializer is not None:
            self.initializer()
        while True:
            with self._changed:
                job = self._queue.pop()
                while job is None:
                    if self._closed:
                        return
                    self._idle += 1
                    self._changed.wait()
                    self._idle -= 1
                    job = self._queue.pop()
                future, call, started_before, key = job
                if not future.set_running_or_notify_cancel():
                    continue
                ahead = self.started - started_before
                self.started += 1
            if self.on_wait is not None:
                self.on_wait(key, ahead)
            try:
                result = call()
            except BaseException as error:  # handed to the waiting caller, as a pool does
                future.set_exception(error)
            else:
                future.set_result(result)
            del future, call, job, key


class _Client(Executor):
    def __init__(self, lane: FairLane, key: Hashable) -> None:
        self.lane = lane
        self.key = key

    def submit(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> Future[T]:
        return self.lane.submit_as(self.key, fn, *args, **kwargs)
