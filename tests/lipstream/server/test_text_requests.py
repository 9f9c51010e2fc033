"""``text`` requests end to end: the real client against a real uvicorn server on loopback.
The server speaks with espeak-ng, streams the speech as ``audio`` messages with their start
times and the frames of what was said; bad text and a failing espeak-ng end that request
only. A text request whose connection the server closes mid-utterance (as a drain that timed
out does) is resumed by the SDK with no speech chunk or frame lost or repeated."""

from __future__ import annotations

import asyncio
import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from lipstream.engines.base import Model, frame_count
from lipstream.speech import worker
from lipstream.speech.text_frontend import MAX_TEXT_CHARS, speak_text
from lipstream_client import (
    AsyncClient,
    AudioChunk,
    Client,
    Encoding,
    Frames,
    LipstreamServerError,
    ResumePolicy,
    StreamResult,
)
from tests.helpers import return_frames
from tests.lipstream.server.harness import Served, serving

pytestmark = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing")

FPS = 60.0
SENTENCE = "Hello there, how are you?"


@pytest.fixture(scope="module")
def served(lerp_dir: Path) -> Iterator[Served]:
    with serving(lerp_dir) as server:
        yield server


def say(client: Client, *texts: str) -> StreamResult:
    stream = client.start("viseme-lerp", "demo", fps=FPS)
    for text in texts:
        stream.send_text(text)
    stream.end()
    return stream.collect(timeout=30)


@pytest.mark.parametrize("encoding", ["msgpack", "json"])
def test_text_streams_the_speech_and_the_frames_of_what_was_said(
    served: Served, trained_models: dict[str, Model], encoding: Encoding
) -> None:
    with Client(served.ws, encoding=encoding) as client:
        result = say(client, SENTENCE)
    spoken = speak_text(SENTENCE)  # a fresh worker speaks the same bytes
    assert result.speech_pcm16() == spoken.pcm16
    starts = [chunk.start for chunk in result.audio]
    ends = [chunk.end for chunk in result.audio]
    assert starts[0] == 0.0 and len(starts) >= 3
    assert starts[1:] == pytest.approx(ends[:-1], abs=1e-9)  # contiguous, in order
    assert {chunk.sample_rate for chunk in result.audio} == {22050}
    duration = len(spoken.pcm16) / 2 / 22050
    assert result.done.stats.frames == frame_count(duration, FPS) + return_frames(FPS)
    offline = trained_models["viseme-lerp"].synthesize(spoken.spans, fps=FPS).frames
    assert np.allclose(np.asarray(result.rows())[: -return_frames(FPS)], offline, atol=1e-6)


def test_a_second_text_continues_where_the_first_ended(served: Served) -> None:
    with Client(served.ws) as client:
        result = say(client, "One.", "Two.")
    first = speak_text("One.")
    first_end = len(first.pcm16) / 2 / first.sample_rate
    later = [
        chunk
        for chunk in result.audio
        if chunk.start is not None and chunk.start >= first_end - 1e-9
    ]
    assert later and later[0].start == pytest.approx(first_end)
    assert result.speech_pcm16() == first.pcm16 + speak_text("Two.").pcm16
    speech_s = len(result.speech_pcm16()) / 2 / 22050
    assert result.done.stats.frames == frame_count(speech_s, FPS) + return_frames(FPS)


@pytest.mark.parametrize(
    ("text", "code"),
    [
        ("   ", "empty_text"),
        ("x" * (MAX_TEXT_CHARS + 1), "text_too_long"),
        ("?!", "unspeakable_text"),
    ],
)
def test_bad_text_ends_its_request_and_the_connection_serves_on(
    served: Served, text: str, code: str
) -> None:
    with Client(served.ws) as client:
        with pytest.raises(LipstreamServerError) as raised:
            say(client, text)
        assert raised.value.code == code and raised.value.fatal
        if code == "text_too_long":
            assert raised.value.details == {"max_text_chars": MAX_TEXT_CHARS}
        assert say(client, "Fine.").done.reason == "end"


def test_a_crashing_espeak_is_speech_failed_and_the_server_serves_on(
    served: Served, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    crashing = tmp_path / "crash.py"
    crashing.write_text("import os\nos.abort()\n", encoding="utf-8")
    with Client(served.ws) as bystander, Client(served.ws) as client:
        monkeypatch.setattr(worker, "WORKER_SCRIPT", crashing)
        with pytest.raises(LipstreamServerError) as raised:
            say(client, SENTENCE)
        assert raised.value.code == "speech_failed" and "exited with status" in raised.value.message
        monkeypatch.undo()
        assert say(client, "Fine.").done.reason == "end"
        assert say(bystander, "Me too.").done.reason == "end"


async def abort_every_connection(served: Served) -> None:
    """On the server's loop: close this test's connection (and any still closing)."""
    for connection in list(served.app.state.lifecycle.connections):
        connection.abort()


async def speak_two_texts(served: Served, cut: bool) -> tuple[list[Frames], list[AudioChunk], int]:
    """Blocks, speech chunks and resumes of a request that says two texts; with ``cut``, the
    server closes the connection (1001, as at a drain's timeout) after the first block."""
    async with AsyncClient(served.ws, resume=ResumePolicy(attempts=5, backoff_s=0.05)) as client:
        stream = await client.start("viseme-lerp", "demo", fps=FPS)
        await stream.send_text(SENTENCE)
        first = await asyncio.wait_for(stream.next_block(), 30)
        assert first is not None
        if cut:
            await asyncio.wrap_future(served.call_soon(abort_every_connection(served)))
            await asyncio.sleep(0.2)  # the second text is sent while the connection is down
        await stream.send_text("Fine, thank you.")
        await stream.end()
        result = await asyncio.wait_for(stream.collect(), 30)
        return [first, *result.frames], list(result.audio), stream.resumes


def test_a_text_request_cut_off_mid_utterance_resumes_with_nothing_lost_or_repeated(
    served: Served,
) -> None:
    calm_blocks, calm_audio, calm_resumes = asyncio.run(speak_two_texts(served, cut=False))
    blocks, audio, resumes = asyncio.run(speak_two_texts(served, cut=True))
    assert (calm_resumes, resumes) == (0, 1)
    assert [b.seq for b in blocks] == list(range(len(blocks)))
    assert [b.first_frame for b in blocks] == [0] + [b.end_frame for b in blocks[:-1]]
    assert blocks[-1].end_frame == calm_blocks[-1].end_frame
    rows = [np.frombuffer(b.data, "<f4") for b in blocks]
    assert np.array_equal(
        np.concatenate(rows), np.concatenate([np.frombuffer(b.data, "<f4") for b in calm_blocks])
    )
    assert [(c.start, c.pcm16) for c in audio] == [(c.start, c.pcm16) for c in calm_audio]
    spoken = speak_text(SENTENCE).pcm16 + speak_text("Fine, thank you.").pcm16
    assert b"".join(c.pcm16 for c in audio) == spoken
