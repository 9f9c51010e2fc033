"""A load-test session that the server refuses for load retries when it was told to."""

from __future__ import annotations

from pathlib import Path

from lipstream.config import ServerSettings
from lipstream.loadtest.load import LoadTestConfig, loadtest
from tests.lipstream.server.harness import serving


def test_a_refused_session_waits_retry_after_and_completes(lerp_dir: Path) -> None:
    # One session at a time: of two 2 s clips started within the same second, one is
    # refused with server_busy while the other runs, and gets in on a later try.
    with serving(lerp_dir, ServerSettings(max_sessions=1)) as served:
        config = LoadTestConfig(
            url=served.ws,
            streams=2,
            requests=2,
            clips_s=(2.0,),
            fps=30.0,
            engine="viseme-lerp",
            character="demo",
            pause_s=0.0,
            max_duration_s=40.0,
        )
        clip = loadtest(config)["clips"][0]
    assert clip["requests"] == 2 and clip["successful_requests"] == 2
    assert clip["errors"] == {}
    assert clip["busy_retries"] >= 1
    assert clip["peak_sessions"] == 1  # the cap held them one at a time


def test_an_upgrade_refused_with_503_waits_retry_after_and_completes(lerp_dir: Path) -> None:
    # One connection at a time: the second session's upgrade gets HTTP 503 with
    # Retry-After while the first holds the cap, and gets in on a later try.
    with serving(lerp_dir, ServerSettings(max_connections=1)) as served:
        config = LoadTestConfig(
            url=served.ws,
            streams=2,
            requests=2,
            clips_s=(1.0,),
            fps=30.0,
            engine="viseme-lerp",
            character="demo",
            pause_s=0.0,
            max_duration_s=40.0,
        )
        clip = loadtest(config)["clips"][0]
    assert clip["requests"] == 2 and clip["successful_requests"] == 2
    assert clip["errors"] == {}
    assert clip["busy_retries"] >= 1


def test_a_probe_refused_for_load_reconnects_and_measures(lerp_dir: Path) -> None:
    # Two session slots, both taken by the load when the probe first connects: it is
    # refused, and gets in once the session with one request leaves (after about 4 s)
    # while the other runs its second request (until 6 s or later); it retries at most
    # 2 s apart, so one retry falls in that window.
    with serving(lerp_dir, ServerSettings(max_sessions=2)) as served:
        config = LoadTestConfig(
            url=served.ws,
            streams=2,
            requests=3,
            clips_s=(3.0,),
            fps=30.0,
            engine="viseme-lerp",
            character="demo",
            pause_s=0.0,
            max_duration_s=60.0,
            probe_phonemes=5,
        )
        clip = loadtest(config)["clips"][0]
    assert clip["successful_requests"] == 3
    probe = clip["probe"]
    assert probe["errors"] == {}
    assert probe["requests"] >= 1 and probe["first_frame_latency_ms"]["p50"] is not None
