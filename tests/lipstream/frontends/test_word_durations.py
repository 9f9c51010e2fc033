"""The duration model: on held-out espeak-ng speech, given each word's true time, it
places phoneme boundaries closer to espeak-ng's own than spreading evenly within the word;
it survives a save and load, and a damaged file is a coded error naming it."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from lipstream.errors import LipstreamError
from lipstream.frontends.spreading import PronouncedWord, share, spread_words
from lipstream.frontends.word_durations import ARRAYS_FILE, MANIFEST_FILE, WordDurationModel
from lipstream.speech.spoken_words import SpokenUtterance


def _boundary_errors(
    model: WordDurationModel, heldout: list[SpokenUtterance]
) -> tuple[np.ndarray, np.ndarray]:
    """|model - true| and |even - true| of every phoneme onset inside a word, in ms."""
    model_errors, even_errors = [], []
    for utterance in heldout:
        words = [
            PronouncedWord(tuple(p.phoneme for p in word.phonemes), word.start, word.end)
            for word in utterance.words
        ]
        derived = [span for span in spread_words(model, words) if span.phoneme != "sil"]
        truth = [p for word in utterance.words for p in word.phonemes]
        assert [s.phoneme for s in derived] == [p.phoneme for p in truth]
        derived_by_word = iter(derived)
        for word in utterance.words:
            n = len(word.phonemes)
            step = (word.end - word.start) / n
            for k, true in enumerate(word.phonemes):
                guess = next(derived_by_word)
                if k:  # a word's first onset is given, not estimated
                    model_errors.append(abs(guess.start - true.start))
                    even_errors.append(abs(word.start + k * step - true.start))
    return np.array(model_errors) * 1000, np.array(even_errors) * 1000


def test_the_model_beats_even_spreading_on_held_out_speech(
    espeak_spoken: tuple[list[SpokenUtterance], list[SpokenUtterance]],
    espeak_durations: WordDurationModel,
) -> None:
    model_ms, even_ms = _boundary_errors(espeak_durations, espeak_spoken[1])
    assert len(model_ms) > 300
    assert np.median(model_ms) < 0.8 * np.median(even_ms), (np.median(model_ms), np.median(even_ms))
    assert np.mean(model_ms) < 0.8 * np.mean(even_ms)
    assert np.percentile(model_ms, 90) < np.percentile(even_ms, 90)


def test_share_fills_the_time_and_stretches_the_variable_phoneme_most() -> None:
    durations = share(np.log([0.05, 0.10]), np.array([0.01, 0.25]), 0.30)
    assert durations.sum() == pytest.approx(0.30)
    # Stretched by 0.15 s, nearly all of it taken by the phoneme whose spread is larger.
    assert durations[0] == pytest.approx(0.05, abs=0.01)
    assert durations[1] > 0.23


def test_pauses_between_words_are_silence(espeak_durations: WordDurationModel) -> None:
    words = [PronouncedWord(("HH", "AY"), 0.2, 0.5), PronouncedWord(("M", "AA", "M"), 0.9, 1.4)]
    spans = spread_words(espeak_durations, words)
    assert (spans[0].phoneme, spans[0].start, spans[0].end) == ("sil", 0.0, 0.2)
    assert [s.phoneme for s in spans] == ["sil", "HH", "AY", "sil", "M", "AA", "M"]
    assert (spans[3].start, spans[3].end) == (0.5, 0.9)
    assert spans[-1].end == 1.4
    assert all(a.end == b.start for a, b in zip(spans, spans[1:]))


def test_saved_and_loaded_it_spreads_the_same(
    espeak_durations: WordDurationModel, tmp_path: Path
) -> None:
    espeak_durations.save(tmp_path)
    loaded = WordDurationModel.load(tmp_path)
    words = [PronouncedWord(("S", "IY", "Z"), 0.1, 0.6)]
    assert spread_words(loaded, words) == spread_words(espeak_durations, words)
    assert b"pickle" not in (tmp_path / ARRAYS_FILE).read_bytes()
    assert loaded.window == espeak_durations.window


@pytest.mark.parametrize(
    ("damage", "file"),
    [
        (lambda d: (d / ARRAYS_FILE).write_bytes(b"not a zip"), ARRAYS_FILE),
        (lambda d: (d / MANIFEST_FILE).write_text("{", encoding="utf-8"), MANIFEST_FILE),
        (lambda d: (d / MANIFEST_FILE).unlink(), MANIFEST_FILE),
        (
            lambda d: np.savez(
                d / ARRAYS_FILE, log_mean=np.full(40, np.nan), coef=np.zeros(58), spread=np.ones(40)
            ),
            ARRAYS_FILE,
        ),
    ],
)
def test_a_damaged_duration_model_is_model_invalid_naming_the_file(
    espeak_durations: WordDurationModel, tmp_path: Path, damage: Callable[[Path], object], file: str
) -> None:
    espeak_durations.save(tmp_path)
    damage(tmp_path)
    with pytest.raises(LipstreamError) as caught:
        WordDurationModel.load(tmp_path)
    assert caught.value.code == "model_invalid"
    assert str(tmp_path / file) in (caught.value.where or "")
