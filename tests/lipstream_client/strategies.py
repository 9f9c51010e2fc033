"""Hypothesis strategies for valid protocol messages.

Sketch: one strategy per message type builds values that satisfy every rule
of ``validate`` (so ``decode(encode(m)) == m`` must hold for them), drawing
ids, names, finite numbers, ordered phoneme timelines, float32 frame blocks,
PCM16 audio and small free-form JSON maps. ``messages()`` draws any message.
It lives with the tests, so hypothesis stays a test dependency of the SDK;
server tests use it to fuzz sessions too.
"""

from __future__ import annotations

from hypothesis import strategies as st

from lipstream_client.errors import ERROR_CODES
from lipstream_client.float32 import pack_float32
from lipstream_client.messages import (
    DONE_REASONS,
    MAX_FPS,
    MAX_INTEGER,
    MAX_LATENCY_BUDGET_MS,
    MAX_RATE_WPM,
    MAX_RETURN_MS,
    MAX_SAMPLE_RATE,
    MAX_SEQ,
    MIN_FPS,
    MIN_RATE_WPM,
    MIN_SAMPLE_RATE,
    NAMINGS,
    TIMING_FORMATS,
    VISEME_SETS,
    AudioChunk,
    Cancel,
    ChannelTransform,
    ClientMessage,
    Done,
    DoneStats,
    End,
    ErrorMessage,
    Frames,
    Interrupt,
    JsonValue,
    Message,
    OutputProfile,
    PhonemeItem,
    Phonemes,
    Ready,
    Resume,
    ServerMessage,
    Start,
    Text,
    Words,
)

_PRINTABLE = st.characters(exclude_categories=("Cc", "Cs"))
_UNICODE = st.characters(exclude_categories=("Cs", "Co"))
ids = st.text(_PRINTABLE, min_size=1, max_size=24)
names = st.text(_PRINTABLE, min_size=1, max_size=24)
phoneme_labels = st.text(_PRINTABLE, min_size=1, max_size=6)
emotions = st.sampled_from(("neutral", "happy", "angry", "sad"))
phoneme_sources = st.sampled_from(("arpabet", "mfa", "timit", "mocha", "espeak", "ipa", "auto"))
fps_values = st.floats(min_value=MIN_FPS, max_value=MAX_FPS)
non_negative_ms = st.floats(min_value=0.0, max_value=1e6)
counts = st.integers(min_value=0, max_value=2**53 - 1)
finite_floats = st.floats(allow_nan=False, allow_infinity=False)

_json_scalars: st.SearchStrategy[JsonValue] = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**63), max_value=2**64 - 1),
    finite_floats,
    st.text(_PRINTABLE, max_size=12),
)
json_values: st.SearchStrategy[JsonValue] = st.recursive(
    _json_scalars,
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(names, inner, max_size=3),
    max_leaves=8,
)
json_maps = st.dictionaries(names, json_values, max_size=4)
channel_lists = st.lists(names, min_size=1, max_size=6, unique=True).map(tuple)


@st.composite
def phoneme_items(draw: st.DrawFn, max_items: int = 8) -> tuple[PhonemeItem, ...]:
    """An ordered, non-overlapping timeline: gaps >= 0 s and durations >= 1 ms."""
    steps = draw(
        st.lists(
            st.tuples(
                st.floats(0.0, 2.0), st.floats(1e-3, 2.0), phoneme_labels, st.none() | emotions
            ),
            min_size=1,
            max_size=max_items,
        )
    )
    cursor = draw(st.floats(0.0, 100.0))
    items: list[PhonemeItem] = []
    for gap, duration, label, emotion in steps:
        start = cursor + gap
        cursor = start + duration
        items.append(PhonemeItem(label, start, cursor, emotion))
    return tuple(items)


channel_transforms = st.builds(
    ChannelTransform,
    multiplier=finite_floats,
    offset=finite_floats,
    clamp=st.none() | st.tuples(finite_floats, finite_floats).map(lambda pair: tuple(sorted(pair))),
)


@st.composite
def output_profiles(draw: st.DrawFn) -> OutputProfile:
    retarget = draw(st.none() | names)
    visemes = None if retarget else draw(st.none() | st.sampled_from(VISEME_SETS))
    return OutputProfile(
        naming=None if visemes or retarget else draw(st.none() | st.sampled_from(NAMINGS)),
        channels=draw(st.none() | channel_lists),
        transforms=draw(st.dictionaries(names, channel_transforms, max_size=3)),
        visemes=visemes,
        retarget=retarget,
    )


resumes = st.builds(
    Resume,
    frames=st.integers(0, MAX_INTEGER),
    seq=st.integers(0, MAX_SEQ),
    fidelity=st.none() | names,
    audio=st.integers(0, MAX_INTEGER),
)


@st.composite
def starts(draw: st.DrawFn) -> Start:
    selection = draw(st.sampled_from(("none", "channels", "output")))
    return Start(
        id=draw(ids),
        engine=draw(names),
        character=draw(names),
        fps=draw(fps_values),
        channels=draw(channel_lists) if selection == "channels" else None,
        output=draw(output_profiles()) if selection == "output" else None,
        emotion=draw(st.none() | emotions),
        latency_budget_ms=draw(st.none() | st.floats(1e-3, MAX_LATENCY_BUDGET_MS)),
        options=draw(json_maps),
        phoneme_source=draw(st.none() | phoneme_sources),
        resume=draw(st.none() | resumes),
    )


phonemes_messages = st.builds(Phonemes, id=ids, items=phoneme_items())
audio_chunks = st.builds(
    AudioChunk,
    id=ids,
    sample_rate=st.integers(MIN_SAMPLE_RATE, MAX_SAMPLE_RATE),
    pcm16=st.binary(min_size=1, max_size=32).map(lambda raw: raw + raw[:1] * (len(raw) % 2)),
    start=st.none() | st.floats(0.0, 3600.0),
)
texts = st.builds(
    Text,
    id=ids,
    text=st.text(_UNICODE, max_size=80),
    voice=st.none() | st.from_regex(r"[A-Za-z0-9_.+-]{1,64}", fullmatch=True),
    rate=st.none() | st.integers(MIN_RATE_WPM, MAX_RATE_WPM),
    lang=st.none() | st.from_regex(r"[A-Za-z0-9_.+-]{1,64}", fullmatch=True),
)
words_messages = st.builds(
    Words,
    id=ids,
    timings=st.lists(json_values, max_size=3)
    | st.dictionaries(names, json_values, max_size=3)
    | st.text(_UNICODE, max_size=40),
    format=st.sampled_from(TIMING_FORMATS),
    offset=st.just(0.0) | st.floats(1e-6, 3600.0),
    voice=st.none() | st.from_regex(r"[A-Za-z0-9_.+-]{1,64}", fullmatch=True),
)
ends = st.builds(End, id=ids)
cancels = st.builds(Cancel, id=ids)
interrupts = st.builds(
    Interrupt,
    id=ids,
    at=st.floats(0.0, 3600.0),
    return_ms=st.none() | st.floats(0.0, MAX_RETURN_MS),
)
readies = st.builds(
    Ready,
    id=ids,
    engine=names,
    character=names,
    fps=fps_values,
    channels=channel_lists,
    lookahead_ms=st.floats(0.0, 10_000.0),
    fidelity=names,
    emotion=st.none() | emotions,
    latency_budget_ms=st.none() | st.floats(1e-3, MAX_LATENCY_BUDGET_MS),
    options=json_maps,
    phoneme_source=st.none() | phoneme_sources,
)
float32_values = st.floats(width=32, allow_nan=False, allow_infinity=False)


@st.composite
def frames_messages(draw: st.DrawFn) -> Frames:
    n_channels = draw(st.integers(1, 8))
    n_frames = draw(st.integers(1, 8))
    values = draw(
        st.lists(float32_values, min_size=n_channels * n_frames, max_size=n_channels * n_frames)
    )
    return Frames(
        draw(ids),
        draw(st.integers(0, MAX_SEQ)),
        draw(counts),
        draw(fps_values),
        n_channels,
        pack_float32(values),
    )


done_stats = st.builds(
    DoneStats,
    frames=counts,
    first_frame_latency_ms=st.none() | non_negative_ms,
    max_lag_ms=st.none() | non_negative_ms,
    budget_met=st.none() | st.booleans(),
    engine=json_maps,
)
dones = st.builds(Done, id=ids, stats=done_stats, reason=st.sampled_from(DONE_REASONS))
error_messages = st.builds(
    ErrorMessage,
    code=st.sampled_from(sorted(ERROR_CODES)),
    message=st.text(_UNICODE, min_size=1, max_size=80),
    id=st.none() | ids,
    fatal=st.booleans(),
    details=json_maps,
)


def client_messages() -> st.SearchStrategy[ClientMessage]:
    return st.one_of(
        starts(), phonemes_messages, audio_chunks, texts, words_messages, ends, cancels, interrupts
    )


def server_messages() -> st.SearchStrategy[ServerMessage]:
    return st.one_of(readies, frames_messages(), audio_chunks, dones, error_messages)


def messages() -> st.SearchStrategy[Message]:
    return st.one_of(client_messages(), server_messages())
