"""What the client keeps to resume a request: the log and its replay, against hand-built
expectations (what is replayed, how it is merged, what the resume says). A worker killed
mid-utterance is in tests/lipstream/server/test_resume_workers.py."""

from __future__ import annotations

import pytest

from lipstream_client import (
    AudioChunk,
    Cancel,
    End,
    Frames,
    Interrupt,
    PhonemeItem,
    Phonemes,
    Ready,
    Resume,
    ResumePolicy,
    Start,
    Text,
)
from lipstream_client.resume import MAX_REPLAY_ITEMS, RequestInput, RequestLog, merged

FPS = 60.0
SPANS = [
    (label, round(0.1 * i, 3), round(0.1 * (i + 1), 3))
    for i, label in enumerate(["sil", "HH", "AH", "L", "OW", "W", "ER", "L", "D"] * 3 + ["sil"])
]  # 2.8 s


def items(spans: list[tuple[str, float, float]]) -> tuple[PhonemeItem, ...]:
    return tuple(PhonemeItem(label, start, end) for label, start, end in spans)


def frames_block(seq: int, first: int, n: int) -> Frames:
    return Frames.from_rows("a", seq, first, FPS, [[0.0]] * n)


def test_the_log_replays_the_whole_input_after_a_resume_that_names_what_is_held() -> None:
    log = RequestLog(Start("a", "viseme-lerp", "demo", fps=FPS, latency_budget_ms=300.0))
    audio = [AudioChunk("a", 16000, bytes([i]) * 4) for i in range(3)]
    inputs: list[RequestInput] = [
        audio[0],
        audio[1],
        Phonemes("a", items(SPANS[:2])),
        Phonemes("a", items(SPANS[2:5])),
        audio[2],
        End("a"),
    ]
    for message in inputs[:4]:
        log.record(message)
    assert log.unsent() == inputs[:4] and log.unsent() == []
    log.on_ready(Ready("a", "viseme-lerp", "demo", FPS, ("jawOpen",), 200.0, "lerp"))
    log.on_frames(frames_block(0, 0, 4))
    log.on_frames(frames_block(1, 4, 7))
    log.rewind()
    for message in inputs[4:]:
        log.record(message)
    start, *replayed = log.replay()
    assert start == Start(
        "a", "viseme-lerp", "demo", fps=FPS, latency_budget_ms=300.0, resume=Resume(11, 2, "lerp")
    )
    assert replayed == [
        AudioChunk("a", 16000, bytes([0]) * 4 + bytes([1]) * 4),
        Phonemes("a", items(SPANS[:5])),
        audio[2],
        End("a"),
    ]
    assert log.unsent() == [] and log.resumes == 1 and log.resumable


def test_merging_keeps_order_and_splits_long_runs() -> None:
    many = [Phonemes("a", (PhonemeItem("AA", i, i + 1),)) for i in range(MAX_REPLAY_ITEMS + 3)]
    out = list(merged([*many, End("a")]))
    runs = [m for m in out[:2] if isinstance(m, Phonemes)]
    assert len(runs) == 2 and [len(m.items) for m in runs] == [MAX_REPLAY_ITEMS, 3]
    flat = [item for m in runs for item in m.items]
    assert flat == [m.items[0] for m in many] and out[2] == End("a")
    rates = [AudioChunk("a", 16000, b"\0\0"), AudioChunk("a", 8000, b"\1\1")]
    assert list(merged(rates)) == rates  # a rate change is not merged (the server refuses it)


def test_a_text_request_replays_its_text_and_names_the_speech_chunks_it_holds() -> None:
    log = RequestLog(Start("a", "viseme-lerp", "demo", fps=FPS))
    said = [Text("a", "hello", "en-us", 150), Text("a", "there")]
    log.record(said[0])
    assert log.unsent() == [said[0]]
    for _ in range(3):
        log.on_audio()
    log.on_frames(frames_block(0, 0, 5))
    log.rewind()
    log.record(said[1])
    log.record(End("a"))
    start, *replayed = log.replay()
    assert isinstance(start, Start)
    assert start.resume == Resume(frames=5, seq=1, fidelity=None, audio=3)
    assert replayed == [*said, End("a")] and log.resumable


@pytest.mark.parametrize("ending", [Cancel("a"), Interrupt("a", 0.3)])
def test_a_cancelled_or_interrupted_request_is_not_resumable(
    ending: Cancel | Interrupt,
) -> None:
    log = RequestLog(Start("a", "viseme-lerp", "demo"))
    log.record(Phonemes("a", items(SPANS[:3])))
    assert log.resumable
    log.record(ending)
    assert not log.resumable


def test_the_policy_refuses_nonsense() -> None:
    with pytest.raises(ValueError, match="attempts"):
        ResumePolicy(attempts=0)
    with pytest.raises(ValueError, match="backoff"):
        ResumePolicy(backoff_s=2.0, max_backoff_s=1.0)
