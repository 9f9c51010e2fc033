"""lipstream on Ray Serve: a local Ray cluster, two replicas, streamed through with the SDK.

Ray is a test dependency (``ray``, ``grpcio``, ``grpcio-reflection``: the
parts of ``ray[serve]`` that Serve needs), so this module always runs. The
Serve application of ``build_app`` runs on one local Ray instance for the
whole module (2 CPUs) with 2 replicas behind Ray's HTTP proxy on a free
loopback port. Through the proxy, the client SDK streams the same utterance
on several connections, WebSocket and all: every request must get exactly
the offline synthesis's frames; ``/readyz`` answers from the app's lifespan
state; and the deployment's settings come from the session cap and the drain
timeout. Last, the application is deleted while two requests are in flight:
the stopping replicas drain as ``lipstream serve`` does on SIGTERM. A new
``start`` is refused with ``shutting_down``, the request that goes on
receives all its frames and its connection closes with 1001, and the request
that never ends is closed with 1001 at the drain timeout.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest
import ray
from ray import serve

from lipstream.config import ServerSettings
from lipstream.deploy.ray import (
    APPLICATION_NAME,
    DEPLOYMENT_NAME,
    HTTP_ROOM,
    SHUTDOWN_MARGIN_S,
    build_app,
)
from lipstream.engines.base import Model
from lipstream_client import (
    AsyncClient,
    ConnectionClosed,
    Frames,
    LipstreamServerError,
    StreamResult,
)
from lipstream_client.errors import SHUTTING_DOWN
from tests.helpers import free_port, return_frames

FPS = 60.0
SPANS = [("sil", 0.0, 0.1), ("HH", 0.1, 0.18), ("AY", 0.18, 0.45), ("M", 0.45, 0.55)]
SPANS += [("sil", 0.55, 0.8)]
CONNECTIONS = 6
SETTINGS = ServerSettings(max_sessions=40, drain_timeout_s=12.0)
REPLICAS = 2
TIMEOUT_S = 120.0  # bounds on a busy machine, not speeds
PROBES = 600
PROBE_PAUSE_S = 0.1

pytestmark = pytest.mark.alone


@pytest.fixture(scope="module")
def proxy(lerp_dir: Path) -> Iterator[str]:
    """The application on a local Ray instance; the base URL of its HTTP proxy."""
    port = free_port()
    ray.init(num_cpus=2, include_dashboard=False, configure_logging=False)
    try:
        serve.start(http_options={"host": "127.0.0.1", "port": port})
        application = build_app(lerp_dir, SETTINGS, REPLICAS)
        serve.run(application, name=APPLICATION_NAME, route_prefix="/")
        yield f"http://127.0.0.1:{port}"
    finally:
        # unannotated in ray; absent (so Any) where ray is not installed, as in lipstream.deploy.ray
        serve.shutdown()  # type: ignore[no-untyped-call, unused-ignore]
        ray.shutdown()


def stream_url(proxy: str) -> str:
    return proxy.replace("http://", "ws://") + "/v1/stream"


async def one_request(url: str) -> StreamResult:
    async with AsyncClient(url, open_timeout=TIMEOUT_S) as client:
        stream = await client.start("viseme-lerp", "demo", fps=FPS)
        await stream.send_phonemes(SPANS[:2])
        await stream.send_phonemes(SPANS[2:])
        await stream.end()
        return await asyncio.wait_for(stream.collect(), TIMEOUT_S)


async def many(url: str) -> list[StreamResult]:
    return list(await asyncio.gather(*(one_request(url) for _ in range(CONNECTIONS))))


def test_streams_through_the_ray_proxy_get_the_offline_frames(
    proxy: str, trained_models: dict[str, Model]
) -> None:
    offline = trained_models["viseme-lerp"].synthesize(SPANS, fps=FPS).frames.astype("<f4")
    results = asyncio.run(many(stream_url(proxy)))
    assert len(results) == CONNECTIONS
    for result in results:
        assert result.done.reason == "end" and result.ready.fidelity == "lerp"
        rows = np.asarray(result.rows(), dtype="<f4")
        assert len(rows) == len(offline) + return_frames(FPS)  # then the return to rest
        np.testing.assert_array_equal(rows[: len(offline)], offline)
    ready = httpx.get(f"{proxy}/readyz", timeout=TIMEOUT_S)
    assert ready.status_code == 200 and ready.json()["ready"] is True


def test_the_deployment_takes_its_limits_from_the_server_settings(proxy: str) -> None:
    status = serve.status().applications[APPLICATION_NAME].deployments[DEPLOYMENT_NAME]
    assert status.status == "HEALTHY"
    config = serve.get_app_handle(APPLICATION_NAME)  # the application is running
    assert config is not None
    serve_client = serve.context._get_global_client()
    assert serve_client is not None
    details = serve_client.get_serve_details()
    deployment = details["applications"][APPLICATION_NAME]["deployments"][DEPLOYMENT_NAME]
    options = deployment["deployment_config"]
    assert options["num_replicas"] == REPLICAS
    assert options["max_ongoing_requests"] == SETTINGS.max_sessions + HTTP_ROOM
    assert options["graceful_shutdown_timeout_s"] == SETTINGS.drain_timeout_s + SHUTDOWN_MARGIN_S
    assert len(deployment["replicas"]) == REPLICAS


async def first_refusal(client: AsyncClient) -> LipstreamServerError:
    """Start empty requests on ``client`` until one is refused; that refusal."""
    for attempt in range(PROBES):
        probe = await client.start("viseme-lerp", "demo", id=f"probe-{attempt}", fps=FPS)
        await probe.end()
        try:
            await asyncio.wait_for(probe.done(), TIMEOUT_S)
        except LipstreamServerError as refusal:
            return refusal
        await asyncio.sleep(PROBE_PAUSE_S)
    raise AssertionError(f"none of {PROBES} starts was refused while the replicas stopped")


async def drain_while_deleting(
    url: str,
) -> tuple[LipstreamServerError, list[Frames], ConnectionClosed, ConnectionClosed]:
    """Two requests in flight on two connections, then the application is deleted: the
    refusal of a new start, the blocks of the request that went on to its end, the close of
    its connection, and the close that ended the request that never ended."""
    async with (
        AsyncClient(url, open_timeout=TIMEOUT_S) as finishing,
        AsyncClient(url, open_timeout=TIMEOUT_S) as lingering,
    ):
        utterance = await finishing.start("viseme-lerp", "demo", fps=FPS)
        open_ended = await lingering.start("viseme-lerp", "demo", fps=FPS)
        for stream in (utterance, open_ended):
            await stream.send_phonemes(SPANS[:2])
        first = await asyncio.wait_for(utterance.next_block(), TIMEOUT_S)
        assert first is not None
        await asyncio.wait_for(open_ended.next_block(), TIMEOUT_S)
        deleting = asyncio.create_task(asyncio.to_thread(serve.delete, APPLICATION_NAME))
        refusal = await first_refusal(finishing)
        await utterance.send_phonemes(SPANS[2:])
        await utterance.end()
        result = await asyncio.wait_for(utterance.collect(), TIMEOUT_S)
        finished_closed = await asyncio.wait_for(finishing.wait_closed(), TIMEOUT_S)
        with pytest.raises(ConnectionClosed) as cut:
            await asyncio.wait_for(open_ended.collect(), TIMEOUT_S)
        await asyncio.wait_for(deleting, TIMEOUT_S)
        assert result.done.reason == "end"
        return refusal, [first, *result.frames], finished_closed, cut.value


def test_a_stopping_replica_drains_like_lipstream_serve(
    proxy: str, trained_models: dict[str, Model]
) -> None:
    """Runs last: it deletes the application."""
    offline = trained_models["viseme-lerp"].synthesize(SPANS, fps=FPS).frames.astype("<f4")
    refusal, blocks, finished_closed, cut = asyncio.run(drain_while_deleting(stream_url(proxy)))
    assert (refusal.code, refusal.fatal) == (SHUTTING_DOWN, True)
    assert refusal.id is not None and refusal.id.startswith("probe-")
    assert [b.seq for b in blocks] == list(range(len(blocks)))
    rows = np.concatenate([np.frombuffer(b.data, "<f4").reshape(-1, b.n_channels) for b in blocks])
    assert len(rows) == len(offline) + return_frames(FPS)  # then the return to rest
    np.testing.assert_array_equal(rows[: len(offline)], offline)
    assert (finished_closed.code, cut.code) == (1001, 1001)
    assert APPLICATION_NAME not in serve.status().applications
