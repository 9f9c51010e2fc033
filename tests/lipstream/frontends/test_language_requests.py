"""``lang`` through every door (WebSocket, REST, CLI) and its errors: an unknown language, a
voice variant espeak-ng lacks and a phoneme the feature table cannot read are coded errors that
say what and where, end that request only, and /healthz keeps answering."""

from __future__ import annotations

import base64
import csv
import shutil
import wave
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest

from lipstream import phonemes
from lipstream.corpus import Corpus
from lipstream.engines.base import Model, frame_count
from lipstream.phonetics import ipa_features, ipa_segments, nearest_phoneme
from lipstream.speech.text_frontend import speak_text
from lipstream.training import train_engine
from lipstream_client import Client, LipstreamServerError
from lipstream_client.rest import RestClient, RestServerError
from tests.helpers import return_frames, run_cli
from tests.lipstream.server.harness import Served, serving

pytestmark = [
    pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing"),
    pytest.mark.slow,  # trains viseme-lerp on the small demo corpus
]

FPS = 30.0
GERMAN = "Grüße aus München."


@pytest.fixture(scope="module")
def lerp(small_demo_corpus: Corpus) -> Model:
    train, _ = small_demo_corpus.split()
    return train_engine(train, "viseme-lerp")


@pytest.fixture(scope="module")
def models(lerp: Model, tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory: Path = tmp_path_factory.mktemp("language-requests")
    lerp.save(directory / "viseme-lerp")
    return directory


@pytest.fixture(scope="module")
def served(models: Path) -> Iterator[Served]:
    with serving(models) as server:
        yield server


def say(client: Client, text: str, lang: str | None, voice: str | None = None) -> object:
    stream = client.start("viseme-lerp", "demo", fps=FPS)
    stream.send_text(text, voice=voice, lang=lang)
    stream.end()
    return stream.collect(timeout=30)


def healthy(served: Served) -> bool:
    return httpx.get(f"{served.http}/healthz").status_code == 200


@pytest.mark.parametrize(
    ("lang", "voice", "code", "where", "named"),
    [
        ("tlh-nope", None, "unknown_language", "lang", "'tlh-nope'"),
        ("de", "en-us", "invalid_request", "voice", "'en-us'"),
        ("de", "nosuchvariant", "invalid_request", "voice", "'nosuchvariant'"),
    ],
)
def test_a_bad_language_or_variant_ends_its_request_and_the_server_serves_on(
    served: Served, lang: str, voice: str | None, code: str, where: str, named: str
) -> None:
    with Client(served.ws) as client:
        with pytest.raises(LipstreamServerError) as raised:
            say(client, GERMAN, lang, voice)
        assert raised.value.code == code and raised.value.fatal
        assert named in raised.value.message and raised.value.message.startswith(f"{where}:")
        assert healthy(served)
        say(client, GERMAN, "de", "f3")  # the connection serves on, a real variant speaks


@pytest.fixture
def table_without_y(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """A feature table that lacks [y], so German ü cannot be read."""
    lacking = {k: v for k, v in ipa_features.BASE_SYMBOLS.items() if k != "y"}
    monkeypatch.setattr(ipa_segments, "BASE_SYMBOLS", lacking)
    nearest_phoneme.phonemes_by_features.cache_clear()
    yield
    monkeypatch.undo()
    nearest_phoneme.phonemes_by_features.cache_clear()
    phonemes._lookup.cache_clear()


def test_a_phoneme_that_does_not_map_is_named_with_its_language(
    served: Served, table_without_y: None
) -> None:
    with Client(served.ws) as client:
        with pytest.raises(LipstreamServerError) as raised:
            say(client, GERMAN, "de")
        assert raised.value.code == "unmapped_phoneme" and raised.value.fatal
        assert raised.value.details == {"phoneme": "yː", "lang": "de"}
        assert "'yː'" in raised.value.message and "'de'" in raised.value.message
        assert raised.value.message.startswith("text:")
        assert healthy(served)
        say(client, "Hello.", None)  # English reads its own table: unaffected


def test_rest_speaks_a_text_in_its_language(served: Served, lerp: Model) -> None:
    body = {"engine": "viseme-lerp", "character": "demo", "fps": FPS, "text": GERMAN, "lang": "de"}
    answer = httpx.post(f"{served.http}/v1/synthesize", json=body, timeout=60)
    assert answer.status_code == 200, answer.text
    result = answer.json()
    spoken = speak_text(GERMAN, lang="de")
    assert result["speech"]["sample_rate"] == spoken.sample_rate
    assert base64.b64decode(result["speech"]["pcm16"]) == spoken.pcm16
    offline = lerp.synthesize(spoken.spans, fps=FPS).frames
    rows = np.asarray(result["data"], dtype=np.float32)[: -return_frames(FPS)]
    assert np.allclose(rows, offline, atol=1e-6)
    sdk = RestClient(served.http).synthesize_text(
        "viseme-lerp", "demo", GERMAN, lang="de", voice="m1", fps=FPS
    )
    assert sdk.speech is not None and sdk.speech[1] == spoken.sample_rate
    assert sdk.speech[0] != spoken.pcm16  # variant m1 is another voice of the same words


@pytest.mark.parametrize(
    ("extra", "status", "code", "named"),
    [
        ({"text": GERMAN, "lang": "xx-none"}, 422, "unknown_language", "'xx-none'"),
        ({"text": GERMAN, "items": []}, 400, "invalid_message", "items"),
        ({"items": [], "lang": "de"}, 400, "invalid_message", "lang"),
        ({"text": GERMAN, "lang": "de de"}, 400, "invalid_message", "lang"),
    ],
)
def test_rest_language_errors(
    served: Served, extra: dict[str, object], status: int, code: str, named: str
) -> None:
    body = {"engine": "viseme-lerp", "character": "demo", **extra}
    answer = httpx.post(f"{served.http}/v1/synthesize", json=body, timeout=60)
    assert answer.status_code == status
    error = answer.json()["error"]
    assert error["code"] == code and named in error["message"]
    assert healthy(served)


def test_the_rest_client_raises_the_servers_code(served: Served) -> None:
    with pytest.raises(RestServerError) as raised:
        RestClient(served.http).synthesize_text("viseme-lerp", "demo", GERMAN, lang="xx-none")
    assert raised.value.code == "unknown_language" and raised.value.status == 422


def test_cli_synth_speaks_a_language(models: Path, lerp: Model, tmp_path: Path) -> None:
    out = tmp_path / "de.csv"
    wav = tmp_path / "de.wav"
    ran = run_cli(
        "synth",
        "--model",
        str(models / "viseme-lerp"),
        "--text",
        GERMAN,
        "--lang",
        "de",
        "--fps",
        str(FPS),
        "--wav",
        str(wav),
        "--out",
        str(out),
    )
    assert ran.returncode == 0, ran.stderr
    spoken = speak_text(GERMAN, lang="de")
    with out.open(newline="") as handle:
        rows = list(csv.reader(handle))[1:]
    assert len(rows) == frame_count(len(spoken.pcm16) / 2 / spoken.sample_rate, FPS)
    with wave.open(str(wav), "rb") as saved:
        assert saved.getnframes() == len(spoken.pcm16) // 2
        assert saved.getframerate() == spoken.sample_rate
    unknown = run_cli(
        "synth",
        "--model",
        str(models / "viseme-lerp"),
        "--text",
        GERMAN,
        "--lang",
        "xx-none",
        "--out",
        str(tmp_path / "x.csv"),
    )
    assert unknown.returncode != 0 and "unknown_language" in unknown.stderr
    assert "lang: " in unknown.stderr
    stray = run_cli(
        "synth",
        "--model",
        str(models / "viseme-lerp"),
        "--phones",
        str(tmp_path / "p.lab"),
        "--lang",
        "de",
        "--out",
        str(tmp_path / "y.csv"),
    )
    assert stray.returncode != 0 and "--lang goes with --text" in stray.stderr
