"""The forced aligner against espeak-ng's own phoneme events on its own speech, and its
coded errors; ``lipstream align`` writes a TextGrid the corpus reader takes."""

from __future__ import annotations

import difflib
import shutil
from pathlib import Path

import numpy as np
import pytest
from praatio import textgrid

from lipstream.audio import Audio, write_wav
from lipstream.cli import main
from lipstream.corpus import read_textgrid_phones
from lipstream.errors import LipstreamError
from lipstream.frontends.align import align
from lipstream.speech.text_frontend import speak_text

pytestmark = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing")

SENTENCES = (
    "The quick brown fox jumps over the lazy dog.",
    "Please call Stella and ask her to bring these things with her from the store.",
    "My name is Zorblax and I am 42 years old.",  # a word no dictionary has, and a number
)


def onset_errors_ms(text: str) -> tuple[np.ndarray, float]:
    """|aligned onset - espeak-ng's event| of every phone the two sequences share."""
    spoken = speak_text(text)
    alignment = align(spoken.audio, text, where="espeak-ng speech")
    truth = [span for span in spoken.spans if span.phoneme != "sil"]
    found = [span for span in alignment.phones if span.phoneme != "sil"]
    matcher = difflib.SequenceMatcher(
        a=[s.phoneme for s in truth], b=[s.phoneme for s in found], autojunk=False
    )
    errors = [
        found[block.b + k].start - truth[block.a + k].start
        for block in matcher.get_matching_blocks()
        for k in range(block.size)
    ]
    assert len(errors) >= 0.85 * len(truth)  # the pronunciations mostly agree
    return 1000 * np.abs(errors), alignment.confidence


def test_phone_onsets_are_close_to_espeak_ngs_own_events() -> None:
    errors, confidences = [], []
    for text in SENTENCES:
        found, confidence = onset_errors_ms(text)
        errors.append(found)
        confidences.append(confidence)
    pooled = np.concatenate(errors)
    assert np.median(pooled) <= 25.0
    assert np.percentile(pooled, 90) <= 50.0
    assert all(0.25 <= confidence <= 1.0 for confidence in confidences)


def test_words_come_back_in_order_with_times_inside_the_audio() -> None:
    spoken = speak_text(SENTENCES[2])
    alignment = align(spoken.audio, SENTENCES[2], where="x")
    assert [w.word for w in alignment.words] == [
        "my",
        "name",
        "is",
        "zorblax",
        "and",
        "i",
        "am",
        "42",
        "years",
        "old",
    ]
    starts = [w.start for w in alignment.words]
    assert starts == sorted(starts) and alignment.words[-1].end <= spoken.audio.duration
    assert alignment.phones[0].start == 0.0
    assert alignment.phones[-1].end == pytest.approx(spoken.audio.duration)
    assert all(a.end == b.start for a, b in zip(alignment.phones, alignment.phones[1:]))


def test_a_transcript_of_other_words_is_refused_naming_the_file() -> None:
    spoken = speak_text(SENTENCES[0])
    with pytest.raises(LipstreamError) as raised:
        align(spoken.audio, "Seven green apples sat in a wooden bowl all day.", where="a.wav")
    assert raised.value.code == "transcript_mismatch"
    assert raised.value.where == "a.wav"


def test_an_empty_transcript_and_silent_audio_are_coded_errors() -> None:
    spoken = speak_text("Hello there.")
    with pytest.raises(LipstreamError) as empty:
        align(spoken.audio, " .,! ", where="a.wav")
    assert empty.value.code == "empty_transcript"
    silence = Audio(np.zeros(16000, np.float32), 16000)
    with pytest.raises(LipstreamError) as quiet:
        align(silence, "hello there", where="b.wav")
    assert (quiet.value.code, quiet.value.where) == ("not_speech", "b.wav")


def test_the_align_command_writes_phones_and_words_tiers(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = "Hello there, how are you?"
    spoken = speak_text(text)
    write_wav(tmp_path / "hello.wav", spoken.audio)
    out = tmp_path / "hello.TextGrid"
    assert (
        main(["align", str(tmp_path / "hello.wav"), "--transcript", text, "--out", str(out)]) == 0
    )
    assert "alignment confidence" in capsys.readouterr().out
    phones = read_textgrid_phones(out)
    assert [s.phoneme for s in phones if s.phoneme != "sil"][:3] == ["HH", "AH", "L"]
    grid = textgrid.openTextgrid(str(out), includeEmptyIntervals=False)
    assert [entry.label for entry in grid.getTier("words").entries] == [
        "hello",
        "there",
        "how",
        "are",
        "you",
    ]


def test_the_align_command_refuses_a_wrong_transcript_with_a_coded_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_wav(tmp_path / "a.wav", speak_text("The quick brown fox.").audio)
    code = main(
        [
            "align",
            str(tmp_path / "a.wav"),
            "--transcript",
            "",
            "--out",
            str(tmp_path / "a.TextGrid"),
        ]
    )
    assert code == 2
    assert capsys.readouterr().err.startswith(f"error [empty_transcript]: {tmp_path / 'a.wav'}:")
    assert not (tmp_path / "a.TextGrid").exists()


def test_a_confidence_under_the_threshold_is_a_mismatch_saying_by_how_much() -> None:
    spoken = speak_text("Hello there, how are you?")
    passed = align(spoken.audio, "Hello there, how are you?", where="a.wav")
    with pytest.raises(LipstreamError) as raised:
        align(spoken.audio, "Hello there, how are you?", where="a.wav", min_confidence=1.01)
    assert raised.value.code == "transcript_mismatch"
    assert f"only {passed.confidence:.0%} of its phones" in raised.value.message


def test_a_word_nobody_can_pronounce_is_alignment_failed() -> None:
    spoken = speak_text("Hello there.")
    with pytest.raises(LipstreamError) as raised:
        align(spoken.audio, "hello qzxv", where="a.wav", pronounce=lambda words: {})
    assert raised.value.code == "alignment_failed" and "'qzxv'" in raised.value.message
