"""Debian's ``chromium`` driven by Playwright's Python package, for the page tests.

``executable_path`` points Playwright at the system browser, so nothing is downloaded
(README command (b) installs it). The flags run it headless in a container, offline and
with sound allowed to start without a user gesture.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

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


@contextmanager
def opened_page(browser: Any, url: str, width: int = 1280, height: int = 800) -> Iterator[Any]:
    """A fresh page at ``url``, once it says ``body[data-ready=true]``; ``page.requested``
    lists every URL it asked for."""
    context = browser.new_context(viewport={"width": width, "height": height})
    page = context.new_page()
    page.requested = []
    page.on("request", lambda request: page.requested.append(request.url))
    page.goto(url)
    page.wait_for_selector("body[data-ready=true]", timeout=WAIT_MS)
    try:
        yield page
    finally:
        context.close()
