"""The sinks and the bridge are the client SDK's: they import and work with numpy blocked."""

from __future__ import annotations

import subprocess
import sys

from tests.helpers import REPO

WITHOUT_NUMPY = """
import sys
sys.modules["numpy"] = None
from lipstream_client.bridge import Bridge, BridgeInput
from lipstream_client.sinks import LiveLinkEncoder, LinesSink, parse_target
from lipstream_client.sinks.vmc import bundle_datagrams, frame_messages
encoder = LiveLinkEncoder("face")
encoder.open(["jawOpen"], 60.0)
assert len(encoder.packet(0, [0.5])) == 306 + 4
assert bundle_datagrams(frame_messages(["A"], 0.0, [0.5]))
assert parse_target("vmc://127.0.0.1").port == 39539
print("ok")
"""


def test_the_sinks_and_the_bridge_need_no_numpy() -> None:
    done = subprocess.run(
        [sys.executable, "-c", WITHOUT_NUMPY],
        capture_output=True,
        text=True,
        cwd=REPO / "client_sdk",
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "ok"
