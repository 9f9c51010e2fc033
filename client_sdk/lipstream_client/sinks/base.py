"""What every sink does: take a request's channels once, then one frame row at a time."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol


@dataclass(frozen=True, slots=True)
class Delivery:
    """What a sink's transport reported: datagrams (or lines) ``sent``, sends ``refused``
    by an ICMP port unreachable (no receiver listening), and sends that ``failed``
    otherwise."""

    sent: int
    refused: int = 0
    failed: int = 0


class Sink(Protocol):
    """A place frames go. ``open`` once with the request's channels and frame rate, then
    ``send`` each frame row (``index`` from 0, ``time_s`` on the utterance clock), then
    ``close``. ``send`` never raises for a receiver that is gone: it counts it."""

    def open(self, channels: Sequence[str], fps: float) -> None: ...

    def send(self, index: int, time_s: float, row: Sequence[float]) -> None: ...

    def delivery(self) -> Delivery: ...

    def close(self) -> None: ...
