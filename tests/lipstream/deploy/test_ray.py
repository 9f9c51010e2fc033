"""lipstream on Ray Serve: a local Ray cluster, two replicas, streamed through with the SDK.

Needs the ``ray`` extra (``pip install -e ".[ray,test]"``); without Ray the
test is skipped, saying so. The Serve application of ``build_app`` runs on
a local Ray instance (2 CPUs) with 2 replicas behind Ray's HTTP proxy on a
free loopback port. Through the proxy, the client SDK streams the same
utterance on several connections, WebSocket and all: every request must
get exactly the offline synthesis's frames; ``/readyz`` answers from the
app's lifespan state; and the deployment's settings come from the session
cap and the drain timeout.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest

from lipstream.config import ServerSettings
from lipstream.engines.base import Model
from lipstream_client import AsyncClient, StreamResult
from tests.helpers import free_port

ray = pytest.importorskip("ray", reason='Ray Serve is an extra: pip install -e ".[ray,test]"')
serve = pytest.importorskip("ray.serve")

from lipstream.deploy.ray import (  # noqa: E402  (after the skip)
    DEPLOYMENT_NAME,
    HTTP_ROOM,
    SHUTDOWN_MARGIN_S,
    build_app,
)

FPS = 60.0
SPANS = [("sil", 0.0, 0.1), ("HH", 0.1, 0.18), ("AY", 0.18, 0.45), ("M", 0.45, 0.55)]
SPANS += [("sil", 0.55, 0.8)]
CONNECTIONS = 6
SETTINGS = ServerSettings(max_sessions=40, drain_timeout_s=20.0)
REPLICAS = 2
TIMEOUT_S = 120.0  # bounds on a busy machine, not speeds


@pytest.fixture(scope="module")
def proxy(lerp_dir: Path) -> Iterator[str]:
    """The application on a local Ray instance; the base URL of its HTTP proxy."""
    port = free_port()
    ray.init(num_cpus=2, include_dashboard=False, configure_logging=False)
    try:
        serve.start(http_options={"host": "127.0.0.1", "port": port})
        serve.run(build_app(lerp_dir, SETTINGS, REPLICAS), name="lipstream", route_prefix="/")
        yield f"http://127.0.0.1:{port}"
    finally:
        serve.shutdown()
        ray.shutdown()


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
    results = asyncio.run(many(proxy.replace("http://", "ws://") + "/v1/stream"))
    assert len(results) == CONNECTIONS
    for result in results:
        assert result.done.reason == "end" and result.ready.fidelity == "lerp"
        np.testing.assert_array_equal(np.asarray(result.rows(), dtype="<f4"), offline)
    ready = httpx.get(f"{proxy}/readyz", timeout=TIMEOUT_S)
    assert ready.status_code == 200 and ready.json()["ready"] is True


def test_the_deployment_takes_its_limits_from_the_server_settings(proxy: str) -> None:
    status = serve.status().applications["lipstream"].deployments[DEPLOYMENT_NAME]
    assert status.status == "HEALTHY"
    config = serve.get_app_handle("lipstream")  # the application is running
    assert config is not None
    details = serve.context._get_global_client().get_serve_details()
    deployment = details["applications"]["lipstream"]["deployments"][DEPLOYMENT_NAME]
    options = deployment["deployment_config"]
    assert options["num_replicas"] == REPLICAS
    assert options["max_ongoing_requests"] == SETTINGS.max_sessions + HTTP_ROOM
    assert options["graceful_shutdown_timeout_s"] == SETTINGS.drain_timeout_s + SHUTDOWN_MARGIN_S
    assert len(deployment["replicas"]) == REPLICAS
