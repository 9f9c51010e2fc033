"""The twelve languages issue 25 names, with espeak-ng's own speech and events as the truth.

For each: the text front end speaks a sentence in the language; the same speech spoken by a
fresh espeak-ng worker gives the events (IPA name, start ms) espeak-ng itself reports, and the
espeak-ng program's ``--ipa`` transcription is a second, independent channel for the names. Every
phoneme espeak-ng spoke becomes a span starting exactly at its event, no spoken phoneme is
silence, a hand-picked sound of the language lands on the phoneme a phonetician would pick, and
an engine voices the spans frame for frame. Over a real server on loopback, a text request in
each language streams that speech and those frames."""

from __future__ import annotations

import shutil
import subprocess
import unicodedata
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from lipstream.corpus import Corpus
from lipstream.engines.base import Model, frame_count
from lipstream.frontends.espeak_languages import resolve_language
from lipstream.phonemes import SILENCE
from lipstream.speech.text_frontend import speak_text
from lipstream.speech.worker import SpeechRequest, speak_in_worker
from lipstream.training import train_engine
from lipstream_client import Client
from tests.helpers import return_frames
from tests.lipstream.server.harness import Served, serving

pytestmark = [
    pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing"),
    pytest.mark.slow,  # trains viseme-lerp on the small demo corpus
]

FPS = 30.0

# (lang, sentence, [(espeak-ng's IPA name of a sound in it, the phoneme expected for it)])
LANGUAGES = [
    ("de", "Über die Brücke fahren schöne Züge.", [("yː", "UW"), ("øː", "OW"), ("ts", "CH")]),
    ("fr", "Un bon vin blanc, s'il vous plaît.", [("ɑ̃", "AA"), ("œ̃", "AO"), ("ɛ̃", "EH")]),
    ("es", "El perro de Rosa corre rápido.", [("r", "R"), ("ð", "DH")]),
    ("it", "Gli gnocchi della nonna sono buoni.", [("ʎ", "L"), ("ɲ", "N")]),
    ("pt", "O pão de queijo é muito bom.", [("ɐ̃ʊ̃", "AW"), ("ʒ", "ZH")]),
    ("nl", "De gezellige kat slaapt in de zon.", [("ɣ", "G")]),
    ("pl", "Cześć, szczęście i źdźbło trawy.", [("ɕ", "SH"), ("tɕ", "CH"), ("ʑ", "ZH")]),
    ("ru", "Привет, мир! Щука живёт в реке.", [("ɕ", "SH"), ("ʲ", "Y"), ("ɵ", "OW")]),
    ("ja", "わたしはにほんごをはなします。", [("ɯᵝ", "UW"), ("ä", "AE"), ("ɕ", "SH")]),
    ("cmn", "我是十月生，爱吃，少说。", [("s.", "SH"), ("ts.h", "CH"), ("ai", "AY")]),
    ("hi", "मैं हिंदी बोलता हूँ।", [("ɛ̃", "EH"), ("ũ", "UW")]),
    ("ar", "أنا أتكلم العربية قليلا.", [("ʕ", "HH"), ("q", "K")]),
]
IDS = [lang for lang, _, _ in LANGUAGES]
_TRANSCRIPT_MARKS = set("ˈˌː _-\n0123456789")


@pytest.fixture(scope="module")
def lerp(small_demo_corpus: Corpus) -> Model:
    train, _ = small_demo_corpus.split()
    return train_engine(train, "viseme-lerp")


def _espeak_events(text: str, lang: str) -> tuple[bytes, int, list[tuple[str, int]]]:
    voice = resolve_language(lang).voice()
    return speak_in_worker([SpeechRequest(text, voice, ipa_names=True)])[0]


def _transcript(text: str, lang: str) -> str:
    voice = resolve_language(lang).voice()
    finished = subprocess.run(
        ["espeak-ng", "-q", "--ipa", "-v", voice, text], capture_output=True, check=True
    )
    return finished.stdout.decode("utf-8")


def _nfc(text: str) -> str:
    return unicodedata.normalize("NFC", text)


def _in_order(needle: str, haystack: str) -> bool:
    """Every character of ``needle`` in ``haystack``, in order (the rest are marks)."""
    position = 0
    for char in needle:
        position = haystack.find(char, position)
        if position < 0:
            return False
        position += 1
    return True


def _spoken(events: list[tuple[str, int]], duration: float) -> list[tuple[str, float]]:
    """(name, start s) of the events that hold a spoken phoneme for some time."""
    timed = [(name, ms / 1000.0) for name, ms in events]
    ends = [start for _, start in timed[1:]] + [duration]
    return [
        (name, start)
        for (name, start), end in zip(timed, ends)
        if name and not name.startswith(("_", "(")) and min(end, duration) > start
    ]


@pytest.mark.parametrize(("lang", "text", "expected"), LANGUAGES, ids=IDS)
def test_every_phoneme_espeak_ng_spoke_is_mapped_at_its_own_event_time(
    lerp: Model, lang: str, text: str, expected: list[tuple[str, str]]
) -> None:
    spoken = speak_text(text, lang=lang)
    pcm, rate, events = _espeak_events(text, lang)
    assert pcm == spoken.pcm16  # a fresh worker speaks the same samples
    names = [name for name, _ in events if name and not name.startswith(("_", "("))]
    transcript = _transcript(text, lang)
    assert _in_order("".join(names), transcript)
    assert set(transcript) - set("".join(names)) <= _TRANSCRIPT_MARKS | set("ɜ")  # cmn tone 3
    duration = len(pcm) / 2 / rate
    spans = spoken.spans
    assert spans[0].start == 0.0 and spans[-1].end == pytest.approx(duration)
    assert all(a.end == b.start for a, b in zip(spans, spans[1:]))
    by_start = {round(span.start, 9): span.phoneme for span in spans}
    for name, start in _spoken(events, duration):
        assert round(start, 9) in by_start, f"{name!r} at {start} s starts no span"
        assert by_start[round(start, 9)] != SILENCE, f"{name!r} at {start} s became silence"
    for name, phoneme in expected:
        start = next(
            start for event, start in _spoken(events, duration) if _nfc(event) == _nfc(name)
        )
        assert by_start[round(start, 9)] == phoneme, name
    frames = lerp.synthesize(spans, fps=FPS).frames
    assert len(frames) == frame_count(duration, FPS) and np.isfinite(frames).all()
    assert np.ptp(frames, axis=0).max() > 0.1  # the mouth moves


@pytest.fixture(scope="module")
def served(lerp: Model, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Served]:
    directory: Path = tmp_path_factory.mktemp("languages-models")
    lerp.save(directory / "viseme-lerp")
    with serving(directory) as server:
        yield server


def test_a_text_request_in_each_language_streams_its_speech_and_frames(
    served: Served, lerp: Model
) -> None:
    with Client(served.ws) as client:
        for lang, text, _ in LANGUAGES:
            stream = client.start("viseme-lerp", "demo", fps=FPS)
            stream.send_text(text, lang=lang)
            stream.end()
            result = stream.collect(timeout=60)
            spoken = speak_text(text, lang=lang)
            assert result.speech_pcm16() == spoken.pcm16, lang
            offline = lerp.synthesize(spoken.spans, fps=FPS).frames
            served_rows = np.asarray(result.rows())[: -return_frames(FPS)]
            assert np.allclose(served_rows, offline, atol=1e-6), lang
