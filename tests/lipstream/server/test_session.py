"""The sans-I/O session: message flows, endings, errors and timing stats, with exact values."""

from __future__ import annotations

import math
from itertools import pairwise

import numpy as np
import pytest

from lipstream.audio import Audio
from lipstream.engines.anime_graph import AnimeGraphModel
from lipstream.server.catalog import Catalog
from lipstream.server.outgoing import Outgoing
from lipstream.server.request import RequestLimits
from lipstream.server.session import Session, SessionLimits
from lipstream_client import (
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
from lipstream_client.channels import OCULUS15_VISEMES
from tests.helpers import rest_pose, return_frames

SPANS = [("HH", 0.0, 0.1), ("AY1", 0.1, 0.4), ("sil", 0.4, 0.6)]
ITEMS = tuple(PhonemeItem(label, start, end) for label, start, end in SPANS)
RETURN_MS = 100.0


def returning(fps: float) -> int:
    """The frames after the input's end that return the face to rest (``RETURN_MS``)."""
    return return_frames(fps, RETURN_MS)


def new_session(
    catalog: Catalog, max_requests: int = 3, max_phonemes: int = 20, max_frames: int = 1000
) -> Session:
    return Session(
        catalog, SessionLimits(max_requests, RequestLimits(max_phonemes, max_frames, RETURN_MS))
    )


def play(
    session: Session,
    *messages: Message | ProtocolError,
    now: float = 0.0,
    sent: float | None = None,
) -> list[ServerMessage]:
    """Handle messages at ``now``; stamp (send) the answers at ``sent`` (default ``now``)."""
    answers: list[Outgoing] = []
    for message in messages:
        answers += session.handle(message, now)
    stamped = [item.stamp(now if sent is None else sent).message for item in answers]
    for message in stamped:  # every answer is a valid protocol message
        assert decode(encode(message, "msgpack"), "msgpack", sender="server") == message
    return stamped


def frames_of(messages: list[ServerMessage], identifier: str = "a") -> np.ndarray:
    blocks = [m for m in messages if isinstance(m, Frames) and m.id == identifier]
    assert [block.seq for block in blocks] == list(range(len(blocks)))
    for previous, block in pairwise(blocks):
        assert block.first_frame == previous.end_frame
    return (
        np.concatenate([np.frombuffer(b.data, "<f4").reshape(-1, b.n_channels) for b in blocks])
        if blocks
        else np.zeros((0, 0))
    )


def last_done(messages: list[ServerMessage]) -> Done:
    """The request's closing ``Done``, which must be the last message."""
    done = messages[-1]
    assert isinstance(done, Done), messages
    return done


def errors(messages: list[ServerMessage]) -> list[tuple[str, str | None, bool]]:
    return [(m.code, m.id, m.fatal) for m in messages if isinstance(m, ErrorMessage)]


def test_ready_reports_the_resolved_request(catalog: Catalog) -> None:
    session = new_session(catalog)
    [ready] = play(session, Start("a", "viseme-lerp", "demo", fps=50, emotion="happy"))
    model = catalog.model("viseme-lerp", "demo")
    assert ready == Ready(
        id="a",
        engine="viseme-lerp",
        character="demo",
        fps=50,
        channels=model.channels,
        lookahead_ms=200.0,
        fidelity="lerp",
        emotion="happy",
        options={"mode": "lerp"},
        phoneme_source="auto",
    )


def test_streamed_frames_equal_the_offline_synthesis(catalog: Catalog) -> None:
    session = new_session(catalog)
    out = play(
        session,
        Start("a", "viseme-lerp", "demo", fps=60),
        Phonemes("a", ITEMS[:1]),
        Phonemes("a", ITEMS[1:2]),
        Phonemes("a", ITEMS[2:]),
        End("a"),
    )
    expected = catalog.model("viseme-lerp", "demo").synthesize(SPANS, fps=60).frames
    np.testing.assert_array_equal(frames_of(out)[: -returning(60)], expected)
    done = out[-1]
    assert isinstance(done, Done) and done.reason == "end"
    assert done.stats.frames == len(expected) + returning(60) == math.floor(0.6 * 60) + 1 + 6
    assert session.active_requests == 0


def test_requests_multiplex_independently(catalog: Catalog) -> None:
    session = new_session(catalog)
    other = [("M", 0.0, 0.2), ("AA1", 0.2, 0.5)]
    out = play(
        session,
        Start("a", "viseme-lerp", "demo", fps=60),
        Start("b", "anime-graph", "demo", fps=30, channels=("jawOpen", "mouthClose")),
        Phonemes("a", ITEMS[:2]),
        Phonemes("b", tuple(PhonemeItem(*span) for span in other)),
        Phonemes("a", ITEMS[2:]),
        End("b"),
        End("a"),
    )
    lerp = catalog.model("viseme-lerp", "demo").synthesize(SPANS, fps=60).frames
    graph = catalog.model("anime-graph", "demo").synthesize(other, fps=30).frames[:, :2]
    np.testing.assert_array_equal(frames_of(out, "a")[: -returning(60)], lerp)
    np.testing.assert_array_equal(frames_of(out, "b")[: -returning(30)], graph)
    for identifier in "ab":
        mine = [m for m in out if getattr(m, "id", None) == identifier]
        assert isinstance(mine[0], Ready) and isinstance(mine[-1], Done)


def test_cancel_reports_the_frames_sent_and_frees_the_id(catalog: Catalog) -> None:
    session = new_session(catalog)
    out = play(
        session, Start("a", "viseme-lerp", "demo", fps=10), Phonemes("a", ITEMS), Cancel("a")
    )
    sent = len(frames_of(out))
    assert sent == 4  # lookahead of one phoneme: final before 0.4 s, frames 0..3 at 10 fps
    done = out[-1]
    assert isinstance(done, Done) and done == Done("a", done.stats, "cancel")
    assert done.stats.frames == sent
    assert errors(play(session, Phonemes("a", ITEMS))) == [("unknown_request", "a", False)]
    assert isinstance(play(session, Start("a", "viseme-lerp", "demo"))[0], Ready)


def test_interrupt_blends_from_the_face_at_the_cut_to_rest(catalog: Catalog) -> None:
    session = new_session(catalog)
    model = catalog.model("viseme-lerp", "demo")
    out = play(
        session,
        Start("a", "viseme-lerp", "demo", fps=100),
        Phonemes("a", ITEMS),
        Interrupt("a", at=0.25, return_ms=50),
    )
    offline = model.synthesize(SPANS, fps=100).frames
    rest = catalog.rest_pose(model, None).astype(np.float64)
    rows: dict[int, np.ndarray] = {}
    for block in (m for m in out if isinstance(m, Frames)):
        data = np.frombuffer(block.data, "<f4").reshape(-1, block.n_channels)
        rows.update({block.first_frame + r: data[r] for r in range(len(data))})
    done = out[-1]
    assert isinstance(done, Done) and (done.reason, done.stats.frames) == ("interrupt", 31)
    last = [m for m in out if isinstance(m, Frames)][-1]
    assert (last.first_frame, last.n_frames) == (25, 6)  # supersedes frames sent before
    assert set(range(31)) <= set(rows)  # the final timeline: frames 0..30
    for index in range(25):
        np.testing.assert_array_equal(rows[index], offline[index])
    face = offline[25].astype(np.float64)
    for step in range(6):
        u = step / 5
        expected = face + (rest - face) * (3 * u * u - 2 * u * u * u)
        np.testing.assert_allclose(rows[25 + step], expected.astype(np.float32), atol=1e-7)
    np.testing.assert_array_equal(rows[30], rest.astype(np.float32))
    assert play(session, Phonemes("a", ITEMS), End("a")) == []  # later input is ignored


def test_interrupt_after_the_input_cuts_at_its_end_with_the_default_return(
    catalog: Catalog,
) -> None:
    session = new_session(catalog)
    out = play(
        session,
        Start("a", "viseme-lerp", "demo", fps=10),
        Phonemes("a", ITEMS[:2]),
        Interrupt("a", at=30.0),
    )
    blocks = [m for m in out if isinstance(m, Frames)]
    # The cut is at the input's end, 0.4 s = frame 4; 100 ms at 10 fps is one step.
    assert blocks[-1].first_frame == 4 and blocks[-1].n_frames == 2
    assert last_done(out).stats.frames == 6


@pytest.mark.parametrize(
    "engine", ["viseme-lerp", "anime-graph", "dam", "cohen-massaro", "hmm", "expressive-dp"]
)
def test_a_request_ended_or_interrupted_before_any_input_is_done_with_the_rest_pose(
    catalog: Catalog, engine: str
) -> None:
    # anime-graph once answered internal_error (negative dimensions) at every fps from 120 up.
    session = new_session(catalog)
    model = catalog.model(engine, "demo")
    rest = catalog.rest_pose(model, catalog.default_emotion(model)).astype(np.float32)
    for fps in (1.0, 60.0, 119.0, 120.0, 121.0, 240.0, 999.5, 1000.0):
        out = play(session, Start("a", engine, "demo", fps=fps), End("a"))
        assert isinstance(out[0], Ready)
        done = last_done(out)
        assert out[1:] == [Done("a", done.stats, "end")], (fps, out)
        assert done.stats.frames == 0
        out = play(
            session, Start("a", engine, "demo", fps=fps), Interrupt("a", at=0.0, return_ms=0)
        )
        assert errors(out) == [], (fps, out)
        [block] = [m for m in out if isinstance(m, Frames)]
        assert (block.first_frame, block.n_frames) == (0, 1)
        np.testing.assert_array_equal(np.frombuffer(block.data, "<f4"), rest)
        assert out[-1] == Done("a", last_done(out).stats, "interrupt")


def test_oculus_visemes_through_the_session_are_distributions(catalog: Catalog) -> None:
    session = new_session(catalog)
    out = play(
        session,
        Start("a", "anime-graph", "demo", output=OutputProfile(visemes="oculus15")),
        Phonemes("a", ITEMS),
        End("a"),
    )
    assert isinstance(out[0], Ready) and out[0].channels == OCULUS15_VISEMES
    weights = frames_of(out)
    assert weights.shape == (37 + returning(60), 15) and np.all(weights >= 0)
    np.testing.assert_allclose(weights.sum(axis=1), 1.0, atol=1e-5)


@pytest.mark.parametrize(
    ("start", "code", "where"),
    [
        (Start("a", "nope", "demo"), "unknown_engine", "engine"),
        (Start("a", "viseme-lerp", "nobody"), "unknown_character", "character"),
        (Start("a", "viseme-lerp", "demo", emotion="bored"), "unknown_emotion", "emotion"),
        (
            Start("a", "viseme-lerp", "demo", phoneme_source="klingon"),
            "unknown_phoneme_source",
            "phoneme_source",
        ),
        (
            Start("a", "viseme-lerp", "demo", channels=("jawOpen", "nose")),
            "unknown_channel",
            "channels[1]",
        ),
        (
            Start("a", "anime-graph", "demo", options={"search": "psychic"}),
            "invalid_request",
            "options.search",
        ),
        (
            Start("a", "viseme-lerp", "demo", options={"note": 1}),
            "invalid_request",
            "options.note",
        ),
    ],
)
def test_start_errors_are_fatal_for_the_request_and_name_the_field(
    catalog: Catalog, start: Start, code: str, where: str
) -> None:
    session = new_session(catalog)
    [error] = play(session, start)
    assert isinstance(error, ErrorMessage)
    assert (error.code, error.id, error.fatal) == (code, "a", True)
    assert error.message.startswith(f"{where}: ")
    assert errors(play(session, Phonemes("a", ITEMS))) == [("unknown_request", "a", False)]


def test_budget_infeasible_gives_the_smallest_feasible_budget(catalog: Catalog) -> None:
    session = new_session(catalog)
    # Below the margin, which even the causal rung's worst case includes.
    budget = catalog.settings.compute_margin_ms - 1.0
    [error] = play(session, Start("a", "viseme-lerp", "demo", latency_budget_ms=budget))
    assert isinstance(error, ErrorMessage) and error.code == "budget_infeasible"
    worst = catalog.ladder(catalog.model("viseme-lerp", "demo"))[-1].worst_case_ms
    assert error.details == {"min_budget_ms": math.ceil(worst)}
    [ready] = play(
        session, Start("a", "viseme-lerp", "demo", latency_budget_ms=float(math.ceil(worst)))
    )
    assert isinstance(ready, Ready) and ready.latency_budget_ms == math.ceil(worst)
    assert (ready.fidelity, ready.lookahead_ms) == ("causal", 0.0)


@pytest.mark.parametrize(
    ("items", "code", "where"),
    [
        ((PhonemeItem("XQ", 0.6, 0.7),), "unknown_phoneme", "items[0].phoneme"),
        ((PhonemeItem("AA", 0.5, 0.7),), "non_monotonic_times", "items[0].start"),
        ((PhonemeItem("AA", 0.6, 0.7, emotion="bored"),), "unknown_emotion", "items[0].emotion"),
        ((PhonemeItem("AA", 0.6, 17.0),), "invalid_times", "items[0].end"),
        (
            tuple(PhonemeItem("AA", 1 + i * 0.1, 1.05 + i * 0.1) for i in range(18)),
            "too_many_phonemes",
            "items",
        ),
    ],
)
def test_phoneme_errors_end_the_request(
    catalog: Catalog, items: tuple[PhonemeItem, ...], code: str, where: str
) -> None:
    session = new_session(catalog)
    play(session, Start("a", "viseme-lerp", "demo"), Phonemes("a", ITEMS))
    [error] = [m for m in play(session, Phonemes("a", items)) if isinstance(m, ErrorMessage)]
    assert (error.code, error.id, error.fatal) == (code, "a", True)
    assert error.message.startswith(f"{where}: ")
    assert session.active_requests == 0


def test_message_scope_errors_leave_requests_running(catalog: Catalog) -> None:
    session = new_session(catalog)
    play(session, Start("a", "viseme-lerp", "demo"))
    assert errors(play(session, Start("a", "viseme-lerp", "demo"))) == [
        ("duplicate_request", "a", False)
    ]
    assert errors(play(session, End("zz"))) == [("unknown_request", "zz", False)]
    malformed = decode(b"\xc1", "msgpack", sender="client")
    assert errors(play(session, malformed)) == [("malformed", None, False)]
    out = play(session, Phonemes("a", ITEMS), End("a"))
    assert isinstance(out[-1], Done)
    assert errors(play(session, Phonemes("a", ITEMS))) == [("request_finished", "a", False)]


def test_a_codec_error_naming_an_active_request_ends_it(catalog: Catalog) -> None:
    session = new_session(catalog)
    play(session, Start("a", "viseme-lerp", "demo"))
    bad = decode('{"v":1,"type":"phonemes","id":"a","items":[]}', "json", sender="client")
    assert isinstance(bad, ProtocolError)
    assert errors(play(session, bad)) == [("invalid_message", "a", True)]
    assert session.active_requests == 0


def test_request_and_audio_limits(catalog: Catalog) -> None:
    session = new_session(catalog, max_requests=2)
    play(session, Start("a", "viseme-lerp", "demo"), Start("b", "viseme-lerp", "demo"))
    [error] = play(session, Start("c", "viseme-lerp", "demo"))
    assert isinstance(error, ErrorMessage) and error.code == "too_many_requests"
    assert error.details == {"max_requests": 2}
    assert play(session, AudioChunk("a", 16000, b"\0\0" * 160)) == []  # viseme-lerp ignores it
    assert errors(play(session, AudioChunk("a", 8000, b"\0\0"))) == [("invalid_audio", "a", True)]


def test_audio_streamed_before_phonemes_matches_offline_audio_synthesis(catalog: Catalog) -> None:
    model = catalog.model("anime-graph", "demo")
    rate = 16000
    samples = (8000 * np.sin(np.arange(int(0.6 * rate)) * 0.05)).astype("<i2")
    session = new_session(catalog)
    out = play(
        session,
        Start("a", "anime-graph", "demo"),
        AudioChunk("a", rate, samples[:4000].tobytes()),
        AudioChunk("a", rate, samples[4000:].tobytes()),
        Phonemes("a", ITEMS[:2]),
        Phonemes("a", ITEMS[2:]),
        End("a"),
    )
    offline = model.synthesize(SPANS, fps=60, audio=Audio.from_pcm16(samples.tobytes(), rate))
    np.testing.assert_array_equal(frames_of(out)[: -returning(60)], offline.frames)


def test_draining_refuses_new_requests_but_finishes_running_ones(catalog: Catalog) -> None:
    session = new_session(catalog)
    play(session, Start("a", "viseme-lerp", "demo"))
    session.begin_drain()
    assert errors(play(session, Start("b", "viseme-lerp", "demo"))) == [
        ("shutting_down", "b", True)
    ]
    assert isinstance(play(session, Phonemes("a", ITEMS), End("a"))[-1], Done)


def test_lag_and_first_frame_latency_are_measured_from_receipt_to_send(catalog: Catalog) -> None:
    session = new_session(catalog)
    play(session, Start("a", "viseme-lerp", "demo", fps=10, latency_budget_ms=1000), now=0.0)
    early = play(session, Phonemes("a", ITEMS), now=1.0, sent=1.25)
    assert len(frames_of(early)) == 4  # frames 0..3, covered by the input received at 1.0
    late = play(session, End("a"), now=2.0, sent=2.5)
    done = late[-1]
    assert isinstance(done, Done)
    assert done.stats.first_frame_latency_ms == pytest.approx(1250.0)
    assert done.stats.max_lag_ms == pytest.approx(1500.0)  # frames 4..6 waited for end
    assert done.stats.budget_met is False
    assert done.stats.engine == {"frames": 7}


def test_an_engine_fault_ends_only_its_request(catalog: Catalog) -> None:
    session = new_session(catalog)
    play(session, Start("a", "viseme-lerp", "demo"), Start("b", "viseme-lerp", "demo"))

    def broken(*_args: object, **_kwargs: object) -> None:
        raise RuntimeError("engine bug")

    session.requests["a"].active.synthesizer.feed = broken  # type: ignore[method-assign]  # an engine that fails
    out = play(session, Phonemes("a", ITEMS))
    assert errors(out) == [("internal_error", "a", True)]
    fault = out[0]
    assert isinstance(fault, ErrorMessage) and "engine bug" not in fault.message
    assert isinstance(play(session, Phonemes("b", ITEMS), End("b"))[-1], Done)


def test_work_estimate_prices_phonemes_and_frames_at_the_calibrated_cost(
    catalog: Catalog,
) -> None:
    session = new_session(catalog)
    play(session, Start("a", "viseme-lerp", "demo", fps=60))
    measured = catalog.ladder(catalog.model("viseme-lerp", "demo"))[0]
    # 3 phonemes; they end at 0.6 s, so frames 0..36 (37) may follow.
    expected = 3 * measured.per_phoneme_ms + 37 * measured.per_frame_ms
    assert session.estimated_work_ms(Phonemes("a", ITEMS)) == pytest.approx(expected)
    assert session.estimated_work_ms(Phonemes("zz", ITEMS)) == 0.0
    assert session.estimated_work_ms(Start("b", "viseme-lerp", "demo")) == 0.0
    play(session, Phonemes("a", ITEMS))
    # viseme-lerp waits one phoneme: frames before 0.4 s (24) are out; end decides the last
    # phoneme and releases frames 24..36, then the 6 frames of the return to rest.
    assert session.requests["a"].active.next_frame == 24
    assert session.estimated_work_ms(End("a")) == pytest.approx(
        measured.per_phoneme_ms + (13 + 6) * measured.per_frame_ms
    )


def test_options_outside_the_ladder_are_priced_by_the_engine_not_a_rung(
    catalog: Catalog,
) -> None:
    model = catalog.model("anime-graph", "demo")
    assert isinstance(model, AnimeGraphModel)
    top = catalog.ladder(model)[0]
    # Naming the rung's own defaults still selects it: the measured cost.
    same = catalog.call_cost(model, {**top.rung.options, "graph": model.default_graph})
    assert (same.per_phoneme_ms, same.per_frame_ms) == (top.per_phoneme_ms, top.per_frame_ms)
    session = new_session(catalog)
    play(session, Start("pq", "anime-graph", "demo", options={"search": "pq"}))
    assert session.estimated_work_ms(Phonemes("pq", ITEMS[:1])) == math.inf
    assert session.estimated_work_ms(Cancel("pq")) == 0.0


def test_a_request_over_its_cpu_budget_ends_with_a_coded_error(catalog: Catalog) -> None:
    session = Session(catalog, SessionLimits(3, RequestLimits(20, 1000, 100.0), cpu_budget_s=1e-9))
    out = play(session, Start("a", "viseme-lerp", "demo"), Phonemes("a", ITEMS))
    assert errors(out) == [("cpu_budget_exceeded", "a", True)]
    assert "a" not in session.requests


def test_stopped_work_answers_nothing_until_its_cancel(catalog: Catalog) -> None:
    session = new_session(catalog)
    play(session, Start("a", "viseme-lerp", "demo"), Start("b", "viseme-lerp", "demo"))
    session.stop_work("a")
    assert play(session, Phonemes("a", ITEMS), End("a")) == []
    assert session.stopped_work == 2
    done = play(session, Cancel("a"))
    assert len(done) == 1 and isinstance(done[0], Done) and done[0].reason == "cancel"
    assert isinstance(play(session, Phonemes("b", ITEMS), End("b"))[-1], Done)


@pytest.mark.parametrize("engine", ["viseme-lerp", "anime-graph", "dam", "cohen-massaro"])
def test_end_returns_the_face_to_the_rest_pose(catalog: Catalog, engine: str) -> None:
    # The input stops on an open vowel: the face is mid-word at the last frame.
    spans = [("HH", 0.0, 0.1), ("AA1", 0.1, 0.5)]
    session = new_session(catalog)
    out = play(
        session,
        Start("a", engine, "demo", fps=60),
        Phonemes("a", tuple(PhonemeItem(*span) for span in spans)),
        End("a"),
    )
    assert session.active_requests == 0
    model = catalog.model(engine, "demo")
    rows = frames_of(out)
    spoken = math.floor(0.5 * 60) + 1
    assert rows.shape == (spoken + 6, len(model.channels))  # 100 ms at 60 fps
    rest = rest_pose(model, "neutral")
    last = rows[spoken - 1].astype(np.float64)
    assert np.abs(last - rest).max() > 0.05  # mid-word
    u = np.arange(1, 7) / 6
    expected = last + (rest - last) * (u * u * (3 - 2 * u))[:, None]
    np.testing.assert_allclose(rows[spoken:], expected, atol=1e-6)
    np.testing.assert_array_equal(rows[-1], rest)
    done = out[-1]
    assert isinstance(done, Done) and done.stats.frames == spoken + 6
