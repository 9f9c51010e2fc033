"""What a client keeps of each request so that it can resume it on a new connection (sans I/O).

Method: a ``RequestLog`` records the request's ``start``, every input message
the caller gave it (``phonemes``, ``audio``, ``text``, ``words``, ``end``) in order, the
rung its ``ready`` named, the frames received so far (one past the highest
frame index, and the next block ``seq``) and how many ``audio`` messages of
the server's speech arrived. While the connection lives, ``unsent``
hands out each input once, as it is recorded. When the connection is lost,
``rewind`` marks everything unsent again and ``replay`` gives what the new
connection needs: the ``start`` with ``resume`` (the frames, blocks and speech
chunks held, the rung), then the whole input: a ``text`` is sent again, and
the server, whose espeak-ng speaks it the same way, sends only the speech
chunks and frames the client lacks; ``words`` are sent again as they were, and give
the same spans. Consecutive ``phonemes`` (and ``audio``)
messages are merged into a few large ones, since a server answers the same
frames however its input is chunked and a burst of many small messages could
meet its message-rate limit. A request that was cancelled or interrupted is
not resumable: its remaining frames depend on when the server read those
messages. ``ResumePolicy`` says how hard
the client tries to reconnect.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from typing import TypeAlias

from .messages import (
    AudioChunk,
    Cancel,
    ClientMessage,
    End,
    Frames,
    Interrupt,
    Phonemes,
    Ready,
    Resume,
    Start,
    Text,
    Words,
)

RequestInput: TypeAlias = Phonemes | AudioChunk | Text | Words | End | Cancel | Interrupt

MAX_REPLAY_ITEMS = 512
"""Phonemes per replayed ``phonemes`` message (about 20 KB of msgpack, far below 1 MiB)."""
MAX_REPLAY_AUDIO_BYTES = 256 << 10
"""PCM16 bytes per replayed ``audio`` message (as base64 JSON, about 350 KB)."""
DEFAULT_RESUME_ATTEMPTS = 8
DEFAULT_RESUME_BACKOFF_S = 0.1
MAX_RESUME_BACKOFF_S = 5.0


@dataclass(frozen=True)
class ResumePolicy:
    """Reconnect after a lost connection and resume its open requests: at most ``attempts``
    connection attempts, each after ``retry_delay_s(error, attempt, backoff_s,
    max_backoff_s)`` (the server's ``retry_after_ms`` when it gave one, else exponential
    backoff with full jitter)."""

    attempts: int = DEFAULT_RESUME_ATTEMPTS
    backoff_s: float = DEFAULT_RESUME_BACKOFF_S
    max_backoff_s: float = MAX_RESUME_BACKOFF_S

    def __post_init__(self) -> None:
        if self.attempts < 1:
            raise ValueError(f"attempts must be at least 1, got {self.attempts}")
        if not 0 <= self.backoff_s <= self.max_backoff_s:
            raise ValueError("need 0 <= backoff_s <= max_backoff_s")


class RequestLog:
    """One request's start, input and progress, as its client saw them."""

    def __init__(self, start: Start) -> None:
        self.start = start
        self.inputs: list[RequestInput] = []
        self.sent = 0
        self.frames = 0
        self.seq = 0
        self.fidelity: str | None = None
        self.audio = 0
        self.resumes = 0

    @property
    def resumable(self) -> bool:
        """False once ``cancel`` or ``interrupt`` was recorded."""
        return not any(isinstance(message, (Cancel, Interrupt)) for message in self.inputs)

    def record(self, message: RequestInput) -> None:
        self.inputs.append(message)

    def unsent(self) -> list[RequestInput]:
        """The input recorded since the last call (or since ``rewind``), now counted sent."""
        fresh = self.inputs[self.sent :]
        self.sent = len(self.inputs)
        return fresh

    def on_ready(self, ready: Ready) -> None:
        if self.fidelity is None:
            self.fidelity = ready.fidelity

    def on_frames(self, block: Frames) -> None:
        self.frames = max(self.frames, block.end_frame)
        self.seq = block.seq + 1

    def on_audio(self) -> None:
        """One more chunk of the server's speech arrived."""
        self.audio += 1

    def rewind(self) -> None:
        """The connection was lost: nothing recorded has reached a server that still runs."""
        self.sent = 0

    def replay(self) -> list[ClientMessage]:
        """The ``start`` that resumes the request, then its whole input, merged; counts
        everything sent."""
        self.resumes += 1
        resume = Resume(self.frames, self.seq, self.fidelity, self.audio)
        start = replace(self.start, resume=resume)
        return [start, *merged(self.unsent())]


def merged(inputs: Sequence[RequestInput]) -> Iterator[RequestInput]:
    """``inputs`` with each run of ``phonemes`` (and of ``audio`` at one sample rate)
    merged into messages of at most ``MAX_REPLAY_ITEMS`` items (``MAX_REPLAY_AUDIO_BYTES``)."""
    index = 0
    while index < len(inputs):
        message = inputs[index]
        index += 1
        if isinstance(message, Phonemes):
            items = list(message.items)
            while (
                index < len(inputs)
                and isinstance(following := inputs[index], Phonemes)
                and len(items) + len(following.items) <= MAX_REPLAY_ITEMS
            ):
                items.extend(following.items)
                index += 1
            yield replace(message, items=tuple(items))
        elif isinstance(message, AudioChunk):
            pcm = bytearray(message.pcm16)
            while (
                index < len(inputs)
                and isinstance(following := inputs[index], AudioChunk)
                and following.sample_rate == message.sample_rate
                and len(pcm) + len(following.pcm16) <= MAX_REPLAY_AUDIO_BYTES
            ):
                pcm.extend(following.pcm16)
                index += 1
            yield replace(message, pcm16=bytes(pcm))
        else:
            yield message
