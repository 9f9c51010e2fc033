"""Resumed requests (``start.resume``) on the sans-I/O session: only the frames the client lacks.

Each engine's request runs once uninterrupted, in small messages; then a
fresh session (another worker) gets the same ``start`` with ``resume`` and
the whole input in one message. The resumed blocks must continue the
uninterrupted run exactly: the rows from ``resume.frames`` on, bit for bit,
blocks numbered from ``resume.seq``, nothing before. The rung is pinned by
name, the unknown rung is refused, and an interrupt's return to rest, which
supersedes frames, goes out whole. A request that sent ``text`` is cut in the
middle of its second text's speech: the resumed run sends the rest of that
transcript, speech chunks and blocks alike, and nothing the client held.
"""

from __future__ import annotations

import shutil
from dataclasses import replace

import numpy as np
import pytest

from lipstream.server.catalog import Catalog
from lipstream.server.request import RequestLimits
from lipstream.server.session import Session, SessionLimits
from lipstream_client import (
    AudioChunk,
    Done,
    End,
    ErrorMessage,
    Frames,
    Interrupt,
    Message,
    PhonemeItem,
    Phonemes,
    Ready,
    Resume,
    ServerMessage,
    Start,
    Text,
)
from lipstream_client.errors import RESUME_MISMATCH
from tests.helpers import return_frames

FPS = 30.0
SPANS = [
    ("sil", 0.0, 0.1),
    ("HH", 0.1, 0.18),
    ("AH", 0.18, 0.3),
    ("L", 0.3, 0.38),
    ("OW", 0.38, 0.6),
    ("M", 0.6, 0.7),
    ("AY", 0.7, 0.95),
    ("F", 0.95, 1.05),
    ("R", 1.05, 1.12),
    ("EH", 1.12, 1.3),
    ("N", 1.3, 1.4),
    ("D", 1.4, 1.46),
    ("sil", 1.46, 1.7),
]
ITEMS = tuple(PhonemeItem(label, start, end) for label, start, end in SPANS)


def new_session(catalog: Catalog) -> Session:
    """A session whose speech synthesis takes no time by its clock, so that two runs of a
    text request report the same ``speech_synthesis_ms``."""
    limits = SessionLimits(2, RequestLimits(100, 10_000, 100.0))
    return Session(catalog, limits, timer=lambda: 0.0)


def play(session: Session, messages: list[Message]) -> list[ServerMessage]:
    return [
        item.stamp(0.0).message for message in messages for item in session.handle(message, 0.0)
    ]


def blocks(messages: list[ServerMessage]) -> list[Frames]:
    return [message for message in messages if isinstance(message, Frames)]


def rows(frames: list[Frames]) -> np.ndarray:
    return np.concatenate([np.frombuffer(b.data, "<f4").reshape(-1, b.n_channels) for b in frames])


def uninterrupted(catalog: Catalog, start: Start) -> list[ServerMessage]:
    """The request with its phonemes two at a time."""
    chunks = [Phonemes(start.id, ITEMS[i : i + 2]) for i in range(0, len(ITEMS), 2)]
    return play(new_session(catalog), [start, *chunks, End(start.id)])


@pytest.mark.parametrize("engine", ["viseme-lerp", "anime-graph", "dam", "cohen-massaro"])
def test_a_resumed_request_sends_exactly_the_frames_the_client_lacks(
    catalog: Catalog, engine: str
) -> None:
    start = Start("a", engine, "demo", fps=FPS)
    first = uninterrupted(catalog, start)
    first_blocks = blocks(first)
    [ready] = [m for m in first if isinstance(m, Ready)]
    expected = rows(first_blocks)
    assert len(first_blocks) >= 3
    assert len(expected) == int(1.7 * FPS) + 1 + return_frames(FPS, 100.0)
    # The client held the first two blocks when the connection broke.
    held = first_blocks[1].end_frame
    resume = Resume(frames=held, seq=2, fidelity=ready.fidelity)
    answers = play(
        new_session(catalog),
        [replace(start, resume=resume), Phonemes("a", ITEMS), End("a")],
    )
    resumed = blocks(answers)
    assert [m.type for m in answers if not isinstance(m, Frames)] == ["ready", "done"]
    assert [b.seq for b in resumed] == list(range(2, 2 + len(resumed)))
    assert resumed[0].first_frame == held
    assert all(b.first_frame == a.end_frame for a, b in zip(resumed, resumed[1:], strict=False))
    np.testing.assert_array_equal(rows(resumed), expected[held:])
    done = answers[-1]
    assert isinstance(done, Done) and done.stats.frames == len(expected)


def test_the_resumed_rung_is_the_named_one_not_the_budgets(fixed_cost_catalog: Catalog) -> None:
    # Without resume, no budget means the first rung (lerp); resume pins the causal one. At a
    # fixed compute cost, 20 ms buys the causal rung on any machine.
    catalog = fixed_cost_catalog
    start = Start("a", "viseme-lerp", "demo", fps=FPS, latency_budget_ms=20.0)
    original = uninterrupted(catalog, start)
    [ready] = [m for m in original if isinstance(m, Ready)]
    assert ready.fidelity == "causal"
    unbudgeted = replace(start, latency_budget_ms=None)
    resume = Resume(frames=5, seq=1, fidelity="causal")
    answers = play(
        new_session(catalog), [replace(unbudgeted, resume=resume), Phonemes("a", ITEMS), End("a")]
    )
    [resumed_ready] = [m for m in answers if isinstance(m, Ready)]
    assert resumed_ready.fidelity == "causal"
    np.testing.assert_array_equal(rows(blocks(answers)), rows(blocks(original))[5:])


def test_a_rung_the_model_lacks_is_a_resume_mismatch(catalog: Catalog) -> None:
    start = Start("a", "viseme-lerp", "demo", resume=Resume(3, 1, "greedy_tile10"))
    answers = play(new_session(catalog), [start])
    [error] = answers
    assert isinstance(error, ErrorMessage)
    assert (error.code, error.id, error.fatal) == (RESUME_MISMATCH, "a", True)
    assert error.message.startswith("resume.fidelity: ")
    assert "lerp, damped_lead, causal" in error.message


def test_an_interrupts_return_to_rest_goes_out_whole(catalog: Catalog) -> None:
    start = Start("a", "viseme-lerp", "demo", fps=FPS)
    interrupt = Interrupt("a", at=0.5, return_ms=100.0)
    first = play(new_session(catalog), [start, Phonemes("a", ITEMS), interrupt])
    first_blocks = blocks(first)
    return_block = first_blocks[-1]
    assert return_block.first_frame == 15 < first_blocks[-2].end_frame
    held = first_blocks[-2].end_frame
    answers = play(
        new_session(catalog),
        [replace(start, resume=Resume(held, 1)), Phonemes("a", ITEMS), interrupt],
    )
    resumed = blocks(answers)
    assert [(b.seq, b.first_frame, b.n_frames) for b in resumed] == [
        (1, return_block.first_frame, return_block.n_frames)
    ]
    assert resumed[0].data == return_block.data


@pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing")
def test_a_resumed_text_request_sends_the_speech_and_frames_the_client_lacks(
    catalog: Catalog,
) -> None:
    start = Start("a", "viseme-lerp", "demo", fps=FPS)
    texts = [Text("a", "Hello there."), Text("a", "How are you today, my friend?")]
    first = play(new_session(catalog), [start, *texts, End("a")])
    speech = [i for i, m in enumerate(first) if isinstance(m, AudioChunk)]
    second_text = next(
        i for i in speech if i > speech[0] and not isinstance(first[i - 1], AudioChunk)
    )
    cut = second_text + 1  # the client held the first text's output and one chunk of the second's
    held = first[:cut]
    [ready] = [m for m in held if isinstance(m, Ready)]
    held_blocks = blocks(held)
    held_audio = sum(isinstance(m, AudioChunk) for m in held)
    assert len(held_blocks) >= 1 and held_audio >= 2 and len(speech) > held_audio + 1
    resume = Resume(held_blocks[-1].end_frame, held_blocks[-1].seq + 1, ready.fidelity, held_audio)
    answers = play(new_session(catalog), [replace(start, resume=resume), *texts, End("a")])
    assert answers[0] == ready
    assert answers[1:] == first[cut:]


MAX_SEQ = 2**31 - 1  # the protocol's bound on a block's seq, stated independently here


def test_a_resume_seq_without_room_for_the_requests_blocks_is_refused_before_ready(
    catalog: Catalog,
) -> None:
    # The session's requests may send 10,000 frames; an interrupt's return to rest at most
    # 10 s x 1000 fps + 1 rows: a resumed request may need that many block numbers from seq.
    most_blocks = 10_000 + 1 + 10_001
    last_fitting = MAX_SEQ + 1 - most_blocks
    for seq in (MAX_SEQ, last_fitting + 1):
        start = Start("a", "viseme-lerp", "demo", fps=FPS, resume=Resume(0, seq))
        [error] = play(new_session(catalog), [start])
        assert isinstance(error, ErrorMessage)
        assert (error.code, error.id, error.fatal) == (RESUME_MISMATCH, "a", True)
        assert error.message.startswith("resume.seq: ")
        assert str(MAX_SEQ) in error.message
    start = Start("a", "viseme-lerp", "demo", fps=FPS, resume=Resume(0, last_fitting))
    answers = play(new_session(catalog), [start, Phonemes("a", ITEMS), End("a")])
    resumed = blocks(answers)
    assert [b.seq for b in resumed] == list(range(last_fitting, last_fitting + len(resumed)))
    assert answers[-1].type == "done"


def test_the_server_never_numbers_a_block_past_the_bound(catalog: Catalog) -> None:
    session = new_session(catalog)
    start = Start("a", "viseme-lerp", "demo", fps=FPS, resume=Resume(0, 0))
    assert isinstance(play(session, [start])[0], Ready)
    cursor = session.requests["a"].resume
    assert cursor is not None
    cursor.seq = MAX_SEQ  # as if the request had sent that many blocks
    answers = play(session, [Phonemes("a", ITEMS[:6]), Phonemes("a", ITEMS[6:])])
    seqs = [b.seq for b in blocks(answers)]
    assert seqs == [MAX_SEQ]
    [error] = [m for m in answers if isinstance(m, ErrorMessage)]
    assert (error.code, error.id, error.fatal) == (RESUME_MISMATCH, "a", True)
    assert session.active_requests == 0
    request = Start("b", "viseme-lerp", "demo", fps=FPS)
    assert isinstance(play(session, [request])[0], Ready)
    session.requests["b"].active.seq = MAX_SEQ
    answers = play(session, [Phonemes("b", ITEMS[:6]), Phonemes("b", ITEMS[6:])])
    assert [b.seq for b in blocks(answers)] == [MAX_SEQ]
    [error] = [m for m in answers if isinstance(m, ErrorMessage)]
    assert (error.code, error.id, error.fatal) == ("output_too_large", "b", True)
