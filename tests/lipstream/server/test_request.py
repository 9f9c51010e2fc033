"""A request's memory, through the sans-I/O session: the rows it keeps after sending them,
what ``interrupt`` returns from, and the request timeout."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from lipstream.server.catalog import Catalog
from lipstream.server.request import SENT_TAIL_VALUES, ActiveRequest, RequestLimits, SentTail
from lipstream.server.session import Session, SessionLimits
from lipstream_client import (
    Done,
    ErrorMessage,
    Frames,
    Interrupt,
    Message,
    PhonemeItem,
    Phonemes,
    Ready,
    ServerMessage,
    Start,
)

FPS = 1000.0
PHONEME_S = 0.1
RETURN_MS = 100.0


def new_session(catalog: Catalog, request_timeout_s: float | None = None) -> Session:
    limits = RequestLimits(10_000, 10_000_000, RETURN_MS)
    return Session(catalog, SessionLimits(4, limits, request_timeout_s=request_timeout_s))


def handle(session: Session, message: Message, now: float = 0.0) -> list[ServerMessage]:
    return [item.message for item in session.handle(message, now)]


def rows_of(messages: list[ServerMessage]) -> np.ndarray:
    blocks = [m for m in messages if isinstance(m, Frames)]
    for previous, block in zip(blocks, blocks[1:], strict=False):
        assert block.first_frame == previous.first_frame + previous.n_frames
    return np.concatenate([np.frombuffer(b.data, "<f4").reshape(-1, b.n_channels) for b in blocks])


def array_bytes(node: Any, depth: int = 0) -> int:
    """Bytes of the numpy arrays reachable from ``node`` through attributes, lists, tuples
    and dicts (a few levels deep)."""
    if isinstance(node, np.ndarray):
        return node.nbytes
    if depth > 4:
        return 0
    if isinstance(node, (list, tuple)):
        return sum(array_bytes(item, depth + 1) for item in node)
    if isinstance(node, dict):
        return sum(array_bytes(item, depth + 1) for item in node.values())
    if hasattr(node, "__dict__"):
        return sum(array_bytes(item, depth + 1) for item in vars(node).values())
    return 0


def streamed(catalog: Catalog, phonemes: int) -> tuple[Session, ActiveRequest, np.ndarray, int]:
    """A request at 1000 fps fed ``phonemes`` phonemes of 0.1 s one message at a time: the
    session, the request, the rows sent so far and the channel count."""
    session = new_session(catalog)
    [ready] = handle(session, Start("a", "viseme-lerp", "demo", fps=FPS))
    assert isinstance(ready, Ready)
    sent: list[ServerMessage] = []
    for index in range(phonemes):
        label = "AA" if index % 2 else "M"
        item = PhonemeItem(label, index * PHONEME_S, (index + 1) * PHONEME_S)
        sent += handle(session, Phonemes("a", (item,)))
    return session, session.requests["a"].active, rows_of(sent), len(ready.channels)


def test_a_request_keeps_a_bounded_tail_of_what_it_sent(catalog: Catalog) -> None:
    session, request, short_rows, width = streamed(catalog, 5)
    short_bytes = array_bytes({k: v for k, v in vars(request).items() if k != "synthesizer"})
    session, request, rows, width = streamed(catalog, 60)
    # 59 phonemes are final (viseme-lerp waits for one more): 5900 frames were sent.
    assert len(rows) == 5900 and len(short_rows) == 400
    held = array_bytes({k: v for k, v in vars(request).items() if k != "synthesizer"})
    tail_bytes = (SENT_TAIL_VALUES // width) * width * 4
    assert len(rows) * width * 4 > 2 * tail_bytes  # far more was sent than may be kept
    assert held <= short_bytes + tail_bytes
    # A longer stream keeps no more.
    session, request, rows, width = streamed(catalog, 90)
    assert len(rows) == 8900
    assert array_bytes({k: v for k, v in vars(request).items() if k != "synthesizer"}) == held


def test_an_interrupt_in_the_tail_returns_from_the_frame_the_client_has(
    catalog: Catalog,
) -> None:
    session, _, rows, width = streamed(catalog, 60)
    cut_frame = len(rows) - 100
    answers = handle(session, Interrupt("a", cut_frame / FPS, RETURN_MS))
    first = next(m for m in answers if isinstance(m, Frames))
    assert first.first_frame == cut_frame
    returned = np.frombuffer(first.data, "<f4").reshape(-1, width)
    np.testing.assert_array_equal(returned[0], rows[cut_frame])
    done = answers[-1]
    assert isinstance(done, Done)
    assert done.stats.frames == cut_frame + math.ceil(RETURN_MS / 1000 * FPS) + 1


def test_an_interrupt_before_the_tail_cuts_at_its_oldest_frame(catalog: Catalog) -> None:
    session, _, rows, width = streamed(catalog, 60)
    oldest = len(rows) - SENT_TAIL_VALUES // width  # 5900 - 2340 = 3560 with 28 channels
    answers = handle(session, Interrupt("a", 1.0, RETURN_MS))
    blocks = [m for m in answers if isinstance(m, Frames)]
    assert blocks[0].first_frame == oldest
    returned = np.frombuffer(blocks[0].data, "<f4").reshape(-1, width)
    np.testing.assert_array_equal(returned[0], rows[oldest])
    done = answers[-1]
    assert isinstance(done, Done)
    assert done.stats.frames == oldest + math.ceil(RETURN_MS / 1000 * FPS) + 1


def test_requests_without_a_message_for_the_timeout_end(catalog: Catalog) -> None:
    session = new_session(catalog, request_timeout_s=5.0)
    assert session.next_expiry() is None
    handle(session, Start("a", "viseme-lerp", "demo"), now=0.0)
    handle(session, Start("b", "viseme-lerp", "demo"), now=1.0)
    assert session.next_expiry() == 5.0
    handle(session, Phonemes("a", (PhonemeItem("M", 0.0, 0.1),)), now=4.0)
    assert session.next_expiry() == 6.0  # b's start at 1 s is now the oldest message
    assert session.expire(5.9) == []
    [expired] = [item.message for item in session.expire(6.0)]
    assert isinstance(expired, ErrorMessage)
    assert (expired.code, expired.id, expired.fatal) == ("request_timeout", "b", True)
    assert expired.details == {"request_timeout_s": 5.0}
    assert list(session.requests) == ["a"] and session.next_expiry() == 9.0
    [unknown] = handle(session, Phonemes("b", (PhonemeItem("M", 0.0, 0.1),)), now=6.5)
    assert isinstance(unknown, ErrorMessage) and unknown.code == "unknown_request"
    assert [item.message.id for item in session.expire(9.0)] == ["a"]
    assert session.active_requests == 0 and session.next_expiry() is None


def test_the_sent_tail_holds_exactly_the_last_frames_sent_whatever_the_chunking() -> None:
    rng = np.random.default_rng(3)
    tail = SentTail(capacity=37, width=2)
    sent: list[np.ndarray] = []
    for _ in range(60):
        rows = rng.random((int(rng.integers(0, 12)), 2)).astype(np.float32)
        tail.extend(rows)
        sent.extend(rows)
        assert tail.stop == len(sent) and tail.oldest == max(0, len(sent) - 37)
        for index in range(tail.oldest, tail.stop):
            assert np.array_equal(tail.row(index), sent[index])
