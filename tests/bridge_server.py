"""A real ``lipstream serve`` of the demo character's viseme-lerp model, for the bridge's
end-to-end tests, and the frames and speech it serves a request (the expectation)."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from lipstream_client import AsyncClient, OutputProfile, StreamResult
from tests.live_server import LiveServer, live_server

if TYPE_CHECKING:
    from lipstream.corpus import Corpus

TEXT = "Hello there, Ada."
FPS = 60.0


@contextmanager
def bridge_server(corpus: Corpus, directory: Path) -> Iterator[LiveServer]:
    from lipstream.training import train_engine

    train, _ = corpus.split()
    train_engine(train, "viseme-lerp").save(directory / "viseme-lerp")
    with live_server(directory) as server:
        yield server


def served(url: str, preset: str | None, text: str = TEXT) -> StreamResult:
    """What the server answers ``text`` with through ``preset``, collected by the SDK."""

    async def request() -> StreamResult:
        async with AsyncClient(url) as client:
            output = OutputProfile(retarget=preset) if preset else None
            stream = await client.start("viseme-lerp", "demo", fps=FPS, output=output)
            await stream.send_text(text)
            await stream.end()
            return await asyncio.wait_for(stream.collect(), 60)

    return asyncio.run(request())
