"""Audio input counted against the server's memory as it arrives, on a real server.

Requests of ``hmm`` (driven by audio alone) and ``anime-graph`` once kept all
their audio, and the memory ceiling was checked only at ``start``. Now each request holds its speech
features and a window of samples, the process counts what they hold, and a
chunk that would take the total past ``LIPSTREAM_MAX_INPUT_MB`` ends only its
request with ``input_too_large``. One connection streams 60 s of audio into
each of four requests, far more than the 0.25 MiB allowed (60 s of features
alone are 672 kB for ``hmm``, 312 kB for ``anime-graph``): each request ends
with the code; the connection
then serves a new request, another connection's request finishes, and the
held-input gauges show the peak within the limit and nothing held at the end.
"""

from __future__ import annotations

import re
from pathlib import Path

import httpx
import numpy as np
import pytest

from lipstream.config import ServerSettings
from lipstream.engines.base import Model
from lipstream_client import (
    AudioChunk,
    Done,
    End,
    ErrorMessage,
    PhonemeItem,
    Phonemes,
    Ready,
    Start,
)
from lipstream_client.errors import INPUT_TOO_LARGE
from tests.lipstream.server.harness import client, serving

BUDGET_BYTES = 262_144  # LIPSTREAM_MAX_INPUT_MB = 0.25
RATE = 16_000
SECONDS = 60
ITEMS = (PhonemeItem("HH", 0.0, 0.1), PhonemeItem("AY1", 0.1, 0.3), PhonemeItem("sil", 0.3, 0.5))
HEAVY = {"a": "hmm", "b": "anime-graph", "c": "hmm", "e": "hmm"}


@pytest.fixture(scope="module")
def audio_models_dir(
    trained_models: dict[str, Model], tmp_path_factory: pytest.TempPathFactory
) -> Path:
    directory = tmp_path_factory.mktemp("server-models-audio")
    for name in ("hmm", "anime-graph", "viseme-lerp"):
        trained_models[name].save(directory / name)
    return directory


def gauge(text: str, name: str) -> float:
    [value] = re.findall(rf"^{name} (\S+)$", text, flags=re.MULTILINE)
    return float(value)


def test_audio_past_the_input_limit_ends_only_its_request(audio_models_dir: Path) -> None:
    rng = np.random.default_rng(7)
    second = (rng.normal(scale=3000.0, size=RATE)).astype("<i2").tobytes()
    settings = ServerSettings(max_input_mb=BUDGET_BYTES / (1 << 20))
    with (
        serving(audio_models_dir, settings) as served,
        client(served.ws, max_queue=None) as heavy,
        client(served.ws) as other,
    ):
        heavy.send(*(Start(identifier, engine, "demo") for identifier, engine in HEAVY.items()))
        assert [type(heavy.recv()) for _ in HEAVY] == [Ready] * len(HEAVY)
        other.send(Start("o", "viseme-lerp", "demo"), Phonemes("o", ITEMS[:1]))
        for _ in range(SECONDS):
            heavy.send(*(AudioChunk(identifier, RATE, second) for identifier in HEAVY))
        heavy.send(*(End(identifier) for identifier in HEAVY))
        for identifier in HEAVY:
            last = heavy.until_done(identifier, limit=100_000)[-1]
            assert isinstance(last, ErrorMessage), last
            assert (last.code, last.id, last.fatal) == (INPUT_TOO_LARGE, identifier, True)
            assert last.details["max_input_bytes"] == BUDGET_BYTES
            needed, others = last.details["needed_bytes"], last.details["held_bytes"]
            assert isinstance(needed, int) and isinstance(others, int)
            assert needed >= 4 * RATE  # at least the chunk as float32
            assert others + needed > BUDGET_BYTES
        heavy.send(Start("d", "viseme-lerp", "demo"), Phonemes("d", ITEMS), End("d"))
        assert isinstance(heavy.until_done("d")[-1], Done)
        other.send(Phonemes("o", ITEMS[1:]), End("o"))
        assert isinstance(other.until_done("o")[-1], Done)
        metrics = httpx.get(f"{served.http}/metrics", timeout=10.0).text
    peak = gauge(metrics, "lipstream_input_held_peak_bytes")
    # More than a second of features (100 rows of 28 float32) was held, never past the limit.
    assert 100 * 28 * 4 < peak <= BUDGET_BYTES
    assert gauge(metrics, "lipstream_input_held_bytes") == 0.0
    assert gauge(metrics, 'lipstream_errors_total{code="input_too_large"}') == len(HEAVY)
