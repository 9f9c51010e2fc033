"""Hypothesis: any sequence of client input gives only documented, well-ordered answers.

Input mixes plausible traffic (a few ids, known and unknown engines, good and
bad phonemes, times that sometimes overlap, every ending) with arbitrary
valid messages and arbitrary bytes through the codec. After every step the
answers must be valid protocol messages, errors must carry documented codes
with their documented scope, and each request must follow ready, frames with
seq 0, 1, 2 (contiguous except where an interrupt restarts), then exactly
one done or fatal error.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from lipstream.server.catalog import Catalog
from lipstream.server.request import RequestLimits
from lipstream.server.session import Session, SessionLimits
from lipstream_client import (
    ERROR_CODES,
    AudioChunk,
    Cancel,
    Done,
    End,
    ErrorMessage,
    Frames,
    Interrupt,
    Message,
    OutputProfile,
    PhonemeItem,
    Phonemes,
    ProtocolError,
    Ready,
    ServerMessage,
    Start,
    decode,
    encode,
)
from tests.lipstream_client import strategies as protocol

IDS = ("a", "b", "c")
ids = st.sampled_from(IDS)
labels = st.sampled_from(("AA1", "B", "sil", "HH", "ɪ", "OW0", "M", "S", "XQ"))


@st.composite
def starts(draw: st.DrawFn) -> Start:
    if draw(st.integers(0, 9)) == 0:  # anything the codec accepts
        return replace(draw(protocol.starts()), id=draw(ids))
    profile = draw(
        st.sampled_from(
            (
                None,
                None,
                OutputProfile(naming="livelink"),
                OutputProfile(visemes="oculus15", channels=("ih", "PP")),
            )
        )
    )
    return Start(
        draw(ids),
        draw(st.sampled_from(("viseme-lerp",) * 3 + ("anime-graph", "nope"))),
        draw(st.sampled_from(("demo",) * 5 + ("nobody",))),
        fps=draw(st.sampled_from((10.0, 30.0, 60.0))),
        output=profile,
        emotion=draw(st.sampled_from((None,) * 4 + ("happy", "bored"))),
        latency_budget_ms=draw(st.sampled_from((None,) * 4 + (5.0, 5000.0))),
    )


@st.composite
def phonemes(draw: st.DrawFn) -> Phonemes:
    start = draw(st.sampled_from((0.0, 0.5, 1.0, 2.0)))
    items = []
    for _ in range(draw(st.integers(1, 4))):
        end = start + draw(st.floats(0.01, 0.3))
        items.append(
            PhonemeItem(
                draw(labels), start, end, draw(st.sampled_from((None,) * 6 + ("sad", "bored")))
            )
        )
        start = end + draw(st.sampled_from((0.0, 0.0, 0.05)))
    return Phonemes(draw(ids), tuple(items))


garbage = st.binary(max_size=40).map(lambda raw: decode(raw, "msgpack", sender="client"))
inputs = st.one_of(
    starts(),
    starts(),
    phonemes(),
    phonemes(),
    phonemes(),
    phonemes(),
    st.builds(End, ids),
    st.builds(End, ids),
    st.builds(Cancel, ids),
    st.builds(Interrupt, ids, st.floats(0.0, 4.0), st.none() | st.floats(0.0, 300.0)),
    st.builds(AudioChunk, ids, st.sampled_from((16000, 22050)), st.just(b"\x01\x00" * 64)),
    protocol.client_messages(),
    garbage,
)


@dataclass
class Track:
    """What a client has seen of one request."""

    seq: int = 0
    next_frame: int = 0
    frames_seen: int = 0
    interrupted: bool = False


@dataclass
class ClientView:
    open: dict[str, Track] = field(default_factory=dict)

    def check(self, answer: ServerMessage) -> None:
        assert decode(encode(answer, "msgpack"), "msgpack", sender="server") == answer
        assert not isinstance(
            decode(encode(answer, "json"), "json", sender="server"), ProtocolError
        )
        if isinstance(answer, Ready):
            assert answer.id not in self.open
            self.open[answer.id] = Track()
        elif isinstance(answer, Frames):
            track = self.open[answer.id]
            assert answer.seq == track.seq
            assert answer.first_frame == track.next_frame or track.interrupted
            track.seq += 1
            track.next_frame = answer.end_frame
            track.frames_seen = max(track.frames_seen, answer.end_frame)
        elif isinstance(answer, Done):
            track = self.open.pop(answer.id)
            if answer.reason == "end":
                assert answer.stats.frames == track.frames_seen
        elif isinstance(answer, ErrorMessage):
            self.check_error(answer)

    def check_error(self, error: ErrorMessage) -> None:
        info = ERROR_CODES[error.code]
        assert error.code != "internal_error", error.message
        if info.scope == "message":
            assert not error.fatal
        elif info.scope == "request" and error.id is not None:
            assert error.fatal
        if error.fatal and error.id is not None:
            self.open.pop(error.id, None)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(inputs, min_size=3, max_size=24))
def test_any_input_gets_only_documented_well_ordered_answers(
    catalog: Catalog, sequence: list[Message | ProtocolError]
) -> None:
    session = Session(catalog, SessionLimits(2, RequestLimits(12, 400, 100.0)))
    view = ClientView()
    opening = Start("a", "viseme-lerp", "demo", fps=30)
    for step, received in enumerate([opening, *sequence]):
        if isinstance(received, Interrupt) and received.id in view.open:
            view.open[received.id].interrupted = True
        answers = [item.stamp(step + 0.5).message for item in session.handle(received, step)]
        for answer in answers:
            view.check(answer)
        event(", ".join(sorted({type(answer).__name__ for answer in answers})) or "silence")
        assert session.active_requests == len(view.open)
