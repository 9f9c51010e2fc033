"""``lipstream.bench.word_timings`` on a few sentences: every format is measured, phoneme
timestamps land exactly, and word timings beat the even-spreading baseline inside words;
``lipstream bench --word-timings`` refuses options that do not apply."""

from __future__ import annotations

import shutil

import pytest

from lipstream.bench.word_timings import FORMATS, bench
from lipstream.cli import main
from lipstream.demo.sentences import load_sentences
from lipstream.frontends.word_durations import WordDurationModel
from lipstream.speech.spoken_words import speak_words

pytestmark = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing")


def test_every_format_is_measured_against_espeaks_own_phonemes() -> None:
    sentences = load_sentences()
    training = speak_words(sentences[:40])
    heldout = speak_words(sentences[-6:])
    results = bench(WordDurationModel().fit(u.spans for u in training), heldout)
    assert set(FORMATS) <= set(results)
    assert results["ipa"]["median_ms"] == 0.0 and results["ipa"]["p90_ms"] <= 1.0
    baseline = results["words, spread evenly (baseline)"]
    assert results["words"]["inner_median_ms"] < baseline["inner_median_ms"]
    assert all(row["pairs"] > 50 for row in results.values())


def test_word_timings_take_no_corpus(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--word-timings", "--corpus", "somewhere"]) == 2
    assert "error [invalid_request]: --word-timings:" in capsys.readouterr().err
