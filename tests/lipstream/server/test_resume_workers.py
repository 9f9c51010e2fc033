"""A worker of ``lipstream serve --workers 2`` killed mid-utterance: the client resumes, no frame lost.

The server runs on loopback; a client with a ``ResumePolicy`` streams an
utterance and, after the first frames arrived and before the input is
complete, the worker holding the session is SIGKILLed (the worker whose
prometheus value file counts the session). The rest of the input is sent
while the connection is down. The client must end with every frame once, in
order (blocks contiguous, ``seq`` 0, 1, 2, …), equal bit for bit to an
uninterrupted run on the same server and to the offline synthesis, having
resumed exactly once. Finally the whole server is killed mid-utterance: the
client gives up after its policy's attempts with ``ResumeFailed``.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
from pathlib import Path

import numpy as np
import pytest

from lipstream.engines.base import Model
from lipstream.server.metrics import MULTIPROCESS_ENV
from lipstream_client import (
    AsyncClient,
    Frames,
    LipstreamClientError,
    ResumeFailed,
    ResumePolicy,
)
from tests.helpers import eventually, return_frames
from tests.live_server import _descendants as descendants
from tests.live_server import lipstream_serve, sessions_by_worker

FPS = 60.0
SPANS = [
    (label, round(0.1 * i, 3), round(0.1 * (i + 1), 3))
    for i, label in enumerate(["sil", "HH", "AH", "L", "OW", "W", "ER", "L", "D"] * 3 + ["sil"])
]  # 2.8 s
HALF = 14
EVENTUALLY_S = 30.0  # bounds on a busy machine, not speeds
GIVE_UP_AFTER = 3


def rows(blocks: list[Frames]) -> np.ndarray:
    return np.concatenate([np.frombuffer(b.data, "<f4").reshape(-1, b.n_channels) for b in blocks])


async def stream_utterance(url: str, kill: Path | None) -> tuple[list[Frames], int]:
    """The utterance's blocks and the number of resumes; with ``kill`` (the prometheus
    directory), the worker holding the session is killed halfway."""
    async with AsyncClient(url, resume=ResumePolicy(attempts=20, backoff_s=0.05)) as client:
        stream = await client.start("viseme-lerp", "demo", fps=FPS)
        await stream.send_phonemes(SPANS[:HALF])
        first = await asyncio.wait_for(stream.next_block(), EVENTUALLY_S)
        received = [first] if first is not None else []
        if kill is not None:
            await asyncio.to_thread(
                eventually,
                lambda: sum(sessions_by_worker(kill).values()) == 1,
                "the session in the workers' files",
            )
            [victim] = [pid for pid, n in sessions_by_worker(kill).items() if n == 1]
            os.kill(victim, signal.SIGKILL)
            await asyncio.sleep(0.2)  # the rest is sent while the connection is down
        await stream.send_phonemes(SPANS[HALF:])
        await stream.end()
        result = await asyncio.wait_for(stream.collect(), EVENTUALLY_S)
        return received + list(result.frames), stream.resumes


async def stream_until_everything_dies(url: str, supervisor: int) -> ResumeFailed:
    """The error of a request whose server (supervisor and workers) is killed mid-utterance.

    The supervisor is stopped before its workers are listed: it may still be
    starting the replacement of the worker killed earlier, and a worker it
    starts after the listing would survive and serve the resumed request."""
    policy = ResumePolicy(attempts=GIVE_UP_AFTER, backoff_s=0.01, max_backoff_s=0.05)
    async with AsyncClient(url, resume=policy) as client:
        stream = await client.start("viseme-lerp", "demo", fps=FPS)
        await stream.send_phonemes(SPANS[:HALF])
        await asyncio.wait_for(stream.next_block(), EVENTUALLY_S)
        os.kill(supervisor, signal.SIGSTOP)
        for pid in [supervisor, *descendants(supervisor)]:
            with contextlib.suppress(ProcessLookupError):  # a helper that exited by itself
                os.kill(pid, signal.SIGKILL)
        with pytest.raises(ResumeFailed) as failed:
            await asyncio.wait_for(stream.collect(), EVENTUALLY_S)
        with pytest.raises(ResumeFailed):
            await stream.send_phonemes(SPANS[HALF:])
        return failed.value


def test_killing_the_worker_mid_utterance_loses_no_frame(
    lerp_dir: Path, trained_models: dict[str, Model], tmp_path: Path
) -> None:
    directory = tmp_path / "prometheus"
    directory.mkdir()
    offline = trained_models["viseme-lerp"].synthesize(SPANS, fps=FPS).frames.astype("<f4")
    with lipstream_serve(
        lerp_dir, 2, {MULTIPROCESS_ENV: str(directory)}, tmp_path / "serve.log"
    ) as (process, base):
        url = base.replace("http://", "ws://") + "/v1/stream"
        calm, calm_resumes = asyncio.run(stream_utterance(url, None))
        killed, resumes = asyncio.run(stream_utterance(url, directory))
        # With no worker left, the client gives up after its attempts.
        gave_up = asyncio.run(stream_until_everything_dies(url, process.pid))
    assert gave_up.attempts == GIVE_UP_AFTER and gave_up.code in (None, 1006)
    assert isinstance(gave_up.last, LipstreamClientError)
    assert (calm_resumes, resumes) == (0, 1)
    for blocks in (calm, killed):
        assert [b.seq for b in blocks] == list(range(len(blocks)))
        assert [b.first_frame for b in blocks] == [0] + [b.end_frame for b in blocks[:-1]]
    np.testing.assert_array_equal(rows(killed), rows(calm))
    assert len(rows(killed)) == len(offline) + return_frames(FPS)
    np.testing.assert_array_equal(rows(killed)[: len(offline)], offline)
