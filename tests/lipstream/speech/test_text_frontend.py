"""The text front end: espeak-ng's speech and phoneme events, checked against the audio
itself, and its coded errors (a crashing or hanging espeak-ng among them)."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from lipstream.errors import LipstreamError
from lipstream.speech import worker
from lipstream.speech.text_frontend import MAX_TEXT_CHARS, speak_text
from lipstream.speech.worker import SpeechRequest, speak_in_worker

pytestmark = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing")

FRAME_S = 1 / 60
# Every sound after a pause is voiced, so its onset is loud enough to see in the waveform.
VOICED_AFTER_PAUSES = "Ah. Ma, ma. Oh! Eee! No, me."


def test_spans_start_at_the_sounds_onsets_within_a_frame() -> None:
    spoken = speak_text(VOICED_AFTER_PAUSES)
    magnitude = np.abs(spoken.audio.samples.astype(np.float64))
    rate = spoken.sample_rate
    loud = 0.05 * magnitude.max()
    checked = 0
    for pause, sound in zip(spoken.spans, spoken.spans[1:]):
        if pause.phoneme != "sil":
            continue
        # The pause is silent (after a frame for the previous sound's tail) ...
        quiet_from = int((pause.start + FRAME_S) * rate)
        assert magnitude[quiet_from : int(pause.end * rate)].max() < loud
        # ... and the waveform turns loud within a frame of the next phoneme's event.
        onset = (quiet_from + np.flatnonzero(magnitude[quiet_from:] > loud)[0]) / rate
        assert abs(onset - sound.start) <= FRAME_S, (sound, onset)
        checked += 1
    assert checked >= 4


def test_spans_are_espeak_events_mapped_to_the_phoneme_set() -> None:
    text = "Hello there, how are you?"
    spoken = speak_text(text)
    pcm, rate, events = speak_in_worker([SpeechRequest(text)])[0]
    assert spoken.pcm16 == pcm and spoken.sample_rate == rate == 22050
    assert spoken.spans[0].start == 0.0
    assert spoken.spans[-1].end == pytest.approx(len(pcm) / 2 / rate)
    assert all(a.end == b.start for a, b in zip(spoken.spans, spoken.spans[1:]))
    sounds = [s for s in spoken.spans if s.phoneme != "sil"]
    assert [s.phoneme for s in sounds] == [
        "HH",
        "AH",
        "L",
        "OW",
        "DH",
        "EH",
        "HH",
        "AW",
        "AA",
        "Y",
        "UW",
    ]
    event_starts = {ms / 1000 for name, ms in events if not name.startswith("_")}
    assert all(min(abs(s.start - e) for e in event_starts) < 1e-9 for s in sounds)


def test_rate_and_voice_change_the_speech() -> None:
    slow = speak_text("How are you today?", rate=100)
    fast = speak_text("How are you today?", rate=300)
    assert slow.audio.duration > 1.8 * fast.audio.duration
    female = speak_text("How are you today?", voice="en-us+f3")
    assert female.pcm16 != speak_text("How are you today?").pcm16


@pytest.mark.parametrize(
    ("text", "code"),
    [
        ("", "empty_text"),
        ("  \n\t", "empty_text"),
        ("a" * (MAX_TEXT_CHARS + 1), "text_too_long"),
        ("...", "unspeakable_text"),
        ("hi\0there", "unspeakable_text"),
    ],
)
def test_text_that_cannot_be_spoken_is_a_coded_error(text: str, code: str) -> None:
    with pytest.raises(LipstreamError) as raised:
        speak_text(text)
    assert raised.value.code == code and raised.value.where == "text"


def test_longest_text_is_spoken() -> None:
    words = ("ma " * MAX_TEXT_CHARS)[:MAX_TEXT_CHARS]
    assert len(words) == MAX_TEXT_CHARS
    assert speak_text(words, rate=450).audio.duration > 10


def test_bad_voice_and_rate_are_invalid_requests() -> None:
    with pytest.raises(LipstreamError) as raised:
        speak_text("hello", voice="xx-nonexistent")
    assert (raised.value.code, raised.value.where) == ("invalid_request", "voice")
    with pytest.raises(LipstreamError) as raised:
        speak_text("hello", rate=20)
    assert (raised.value.code, raised.value.where) == ("invalid_request", "rate")


def failing_worker(tmp_path: Path, body: str) -> Path:
    script = tmp_path / "worker.py"
    script.write_text(body, encoding="utf-8")
    return script


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("import os\nos.abort()\n", "exited with status"),
        ("import time\ntime.sleep(30)\n", "did not finish within"),
        ("print('not json')\n", "answered nonsense"),
    ],
)
def test_a_failing_espeak_worker_is_speech_failed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, body: str, message: str
) -> None:
    monkeypatch.setattr(worker, "WORKER_SCRIPT", failing_worker(tmp_path, body))
    with pytest.raises(LipstreamError, match=message) as raised:
        speak_text("hello", timeout_s=2.0)
    assert raised.value.code == "speech_failed"


def test_the_worker_imports_only_the_standard_library() -> None:
    source = worker.WORKER_SCRIPT.read_text(encoding="utf-8")
    imported = {
        line.split()[1].split(".")[0]
        for line in source.splitlines()
        if line.startswith(("import ", "from "))
    }
    assert imported <= set(sys.stdlib_module_names) | {"__future__"}
