"""The log throttle on a real logger and handler, with a hand-driven clock."""

from __future__ import annotations

import logging

from lipstream.server.log_throttle import LogThrottle


class Collected(logging.Handler):
    def __init__(self) -> None:
        super().__init__()
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())


def throttled_logger(name: str, throttle: LogThrottle) -> tuple[logging.Logger, Collected]:
    logger = logging.getLogger(name)
    logger.propagate = False
    logger.setLevel(logging.INFO)
    handler = Collected()
    logger.handlers = [handler]
    logger.filters = [throttle]
    return logger, handler


def test_a_flood_passes_its_burst_then_one_line_per_period_with_the_count() -> None:
    now = [100.0]
    throttle = LogThrottle(burst=3, period_s=10.0, clock=lambda: now[0])
    logger, handler = throttled_logger("test.throttle.flood", throttle)
    for _ in range(1000):
        logger.error("socket.accept() out of system resource: %s", "EMFILE")
    assert handler.lines == ["socket.accept() out of system resource: EMFILE"] * 3
    logger.warning("a different line")  # another key passes meanwhile
    now[0] += 9.99
    logger.error("socket.accept() out of system resource: %s", "EMFILE")
    assert len(handler.lines) == 4
    now[0] += 0.01
    logger.error("socket.accept() out of system resource: %s", "EMFILE")
    assert handler.lines[-1] == (
        "socket.accept() out of system resource: EMFILE [998 more like this in the last 10 s]"
    )
    logger.error("socket.accept() out of system resource: %s", "EMFILE")
    logger.error("socket.accept() out of system resource: %s", "EMFILE")
    logger.error("socket.accept() out of system resource: %s", "EMFILE")
    assert len(handler.lines) == 7  # a new period: its burst of 3 again, counted from the summary


def test_levels_and_arguments_make_different_lines_and_old_keys_are_forgotten() -> None:
    throttle = LogThrottle(burst=1, period_s=60.0, max_keys=2, clock=lambda: 0.0)
    logger, handler = throttled_logger("test.throttle.keys", throttle)
    logger.info("closing %s", "a")
    logger.warning("closing %s", "a")
    logger.info("closing %s", "b")
    assert handler.lines == ["closing a", "closing a", "closing b"]
    logger.info("closing %s", "a")  # its key was the oldest of three: forgotten, passes
    logger.info("closing %s", "b")  # still remembered: dropped
    assert handler.lines == ["closing a", "closing a", "closing b", "closing a"]
    assert len(throttle.windows) == 2
