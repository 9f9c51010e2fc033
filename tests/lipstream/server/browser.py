"""Debian's ``chromium`` driven by Playwright's Python package, for the page tests.

``executable_path`` points Playwright at the system browser, so nothing is downloaded
(README command (b) installs it). The flags run it headless in a container, offline and
with sound allowed to start without a user gesture.
"""

from __future__ import annotations

from pathlib import Path

CHROMIUM = Path("/usr/bin/chromium")
LAUNCH_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--autoplay-policy=no-user-gesture-required",
]
WAIT_MS = 30_000  # a bound on a busy machine, not a speed claim
