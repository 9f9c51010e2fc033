"""``POST /v1/synthesize`` with ``audio`` and its ``transcript`` against a real uvicorn
server on loopback: the aligned phonemes' frames stay as close to those of espeak-ng's own
phoneme events as the aligner's measured onset error allows, the answer carries the
alignment's confidence, and each refusal has its code while /healthz keeps answering; the
SDK's ``RestClient.synthesize_transcript`` gets the same answer and the same codes."""

from __future__ import annotations

import base64
import json
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from lipstream.config import ServerSettings
from lipstream.speech.text_frontend import SpokenText, speak_text
from lipstream.timeline import PhonemeSpan
from lipstream_client import EncodeError
from lipstream_client.messages import Encoding
from lipstream_client.rest import RestClient, RestServerError
from tests.helpers import delayed_spans
from tests.lipstream.server.harness import Served, serving

pytestmark = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing")

FPS = 50.0
TEXT = "Please call Stella and ask her to bring these things with her from the store."
# tests/lipstream/frontends/test_align.py holds the aligner's phone onsets to a p90 error
# of 50 ms against espeak-ng's events: the aligned frames must be closer to the true ones
# than the true ones delayed by that much.
P90_ONSET_ERROR_S = 0.05
BODY = {"engine": "viseme-lerp", "character": "demo", "fps": FPS}


@pytest.fixture(scope="module")
def served(words_models: Path) -> Iterator[Served]:
    with serving(words_models) as server:
        yield server


@pytest.fixture(scope="module")
def spoken() -> SpokenText:
    return speak_text(TEXT)


def audio_field(spoken: SpokenText) -> dict[str, Any]:
    return {"sample_rate": spoken.sample_rate, "pcm16": base64.b64encode(spoken.pcm16).decode()}


def items(spans: list[PhonemeSpan]) -> list[dict[str, Any]]:
    return [{"phoneme": s.phoneme, "start": s.start, "end": s.end} for s in spans]


def post(served: Served, body: dict[str, Any]) -> httpx.Response:
    return httpx.post(
        f"{served.http}/v1/synthesize",
        content=json.dumps(body),
        headers={"Content-Type": "application/json"},
        timeout=60,
    )


def rms(a: list[list[float]], b: list[list[float]]) -> float:
    rows = min(len(a), len(b))
    return float(np.sqrt(np.mean((np.asarray(a[:rows]) - np.asarray(b[:rows])) ** 2)))


def test_a_transcript_of_the_audio_gives_frames_within_the_aligners_error(
    served: Served, spoken: SpokenText
) -> None:
    aligned = post(served, {**BODY, "audio": audio_field(spoken), "transcript": TEXT})
    assert aligned.status_code == 200, aligned.text
    answer = aligned.json()
    assert 0.25 <= answer["alignment"]["confidence"] <= 1.0
    truth = post(served, {**BODY, "items": items(spoken.spans)}).json()["data"]
    late = post(served, {**BODY, "items": items(delayed_spans(spoken.spans, P90_ONSET_ERROR_S))})
    assert abs(len(answer["data"]) - len(truth)) <= 1
    assert rms(answer["data"], truth) < rms(late.json()["data"], truth)
    assert "alignment" not in post(served, {**BODY, "items": items(spoken.spans)}).json()


@pytest.mark.parametrize(
    ("extra", "status", "code"),
    [
        ({"transcript": TEXT}, 400, "invalid_message"),  # no audio
        ({"transcript": TEXT, "audio": None, "items": []}, 400, "invalid_message"),
        ({"transcript": 7, "audio": None}, 400, "invalid_message"),
        ({"transcript": TEXT, "audio": None, "phoneme_source": "ipa"}, 400, "invalid_message"),
        ({"transcript": " .! ", "audio": None}, 400, "empty_transcript"),
        (
            {"transcript": "Seven green apples sat in a bowl.", "audio": None},
            422,
            "transcript_mismatch",
        ),
    ],
)
def test_bad_transcript_requests_are_refused_with_their_code(
    served: Served, spoken: SpokenText, extra: dict[str, Any], status: int, code: str
) -> None:
    body = {**BODY, **extra}
    if "audio" in body:
        body["audio"] = audio_field(spoken)
    answer = post(served, body)
    assert (answer.status_code, answer.json()["error"]["code"]) == (status, code), answer.text
    assert httpx.get(f"{served.http}/healthz").status_code == 200


def test_audio_longer_than_a_request_may_be_is_refused_before_aligning(
    words_models: Path, spoken: SpokenText
) -> None:
    with serving(words_models, ServerSettings(max_request_s=1.0)) as short:
        answer = post(short, {**BODY, "audio": audio_field(spoken), "transcript": TEXT})
        assert (answer.status_code, answer.json()["error"]["code"]) == (400, "invalid_audio")
        assert "1 s" in answer.json()["error"]["message"]
        assert httpx.get(f"{short.http}/healthz").status_code == 200


@pytest.mark.parametrize("encoding", ["msgpack", "json"])
def test_the_sdk_sends_audio_and_transcript_and_gets_the_rest_answer(
    served: Served, spoken: SpokenText, encoding: Encoding
) -> None:
    raw = post(served, {**BODY, "audio": audio_field(spoken), "transcript": TEXT}).json()
    result = RestClient(served.http, encoding=encoding).synthesize_transcript(
        "viseme-lerp", "demo", (spoken.pcm16, spoken.sample_rate), TEXT, fps=FPS
    )
    assert result.alignment_confidence == raw["alignment"]["confidence"]
    assert (result.channels, result.ready.fps) == (tuple(raw["channels"]), FPS)
    assert np.array_equal(
        np.asarray(result.rows(), np.float32), np.asarray(raw["data"], np.float32)
    )
    phonemes = RestClient(served.http).synthesize(
        "viseme-lerp", "demo", items(spoken.spans), fps=FPS
    )
    assert phonemes.alignment_confidence is None


@pytest.mark.parametrize(
    ("transcript", "status", "code"),
    [
        (" .! ", 400, "empty_transcript"),
        ("Seven green apples sat in a bowl.", 422, "transcript_mismatch"),
    ],
)
def test_the_sdk_raises_the_servers_code_for_a_bad_transcript(
    served: Served, spoken: SpokenText, transcript: str, status: int, code: str
) -> None:
    with pytest.raises(RestServerError) as raised:
        RestClient(served.http).synthesize_transcript(
            "viseme-lerp", "demo", (spoken.pcm16, spoken.sample_rate), transcript, fps=FPS
        )
    assert (raised.value.status, raised.value.code) == (status, code)
    assert httpx.get(f"{served.http}/healthz").status_code == 200


def test_the_sdk_refuses_a_transcript_that_is_not_text_before_sending() -> None:
    client = RestClient("http://127.0.0.1:9")  # nothing listens: the refusal comes first
    with pytest.raises(EncodeError) as raised:
        client.synthesize_transcript("viseme-lerp", "demo", (b"\0\0", 16000), 7)  # type: ignore[arg-type]
    assert raised.value.error.where == "transcript"
