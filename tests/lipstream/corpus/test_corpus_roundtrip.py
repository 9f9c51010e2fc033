"""write_corpus -> load_corpus preserves frames, phones, audio, metadata and corpus settings."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from lipstream.audio import Audio
from lipstream.corpus import (
    Corpus,
    Utterance,
    load_corpus,
    read_frames_csv,
    write_corpus,
    write_frames_csv,
)
from lipstream.errors import CorpusError
from lipstream.timeline import PhonemeSpan

CHANNELS = ("jawOpen", "mouthClose", "headYaw")


def phones(offset: float) -> list[PhonemeSpan]:
    return [
        PhonemeSpan("sil", 0.0, 0.12),
        PhonemeSpan("HH", 0.12, 0.31 + offset),
        PhonemeSpan("AY", 0.31 + offset, 0.5625),
        PhonemeSpan("sil", 0.5625, 0.8),
    ]


def exact_corpus(audio: bool = False) -> Corpus:
    """Values on a 1/1000 lattice at 50 fps survive %.6f text exactly."""
    rng = np.random.default_rng(11)
    utterances = []
    for index, (emotion, speaker) in enumerate(
        [("happy", "anna"), ("sad", None), ("neutral", "bo")]
    ):
        frames = rng.integers(-1500, 1500, size=(41 + index, len(CHANNELS))) / 1000
        sound = None
        if audio and index == 0:
            samples = (0.6 * np.sin(np.arange(8000) * 0.05)).astype(np.float32)
            sound = Audio(samples, 16000)
        utterances.append(
            Utterance(
                stem=f"utt{index:02d}",
                frames=frames,
                phones=phones(0.01 * index),
                fps=50.0,
                audio=sound,
                emotion=emotion,
                speaker=speaker,
            )
        )
    return Corpus("tiny", 50.0, CHANNELS, utterances, heldout=("utt01",))


def assert_same(loaded: Corpus, original: Corpus, phone_tolerance: float = 0.0) -> None:
    assert (loaded.name, loaded.fps, loaded.channels) == (
        original.name,
        original.fps,
        original.channels,
    )
    assert loaded.heldout == original.heldout
    assert loaded.stems == original.stems
    for got, want in zip(loaded.utterances, original.utterances):
        np.testing.assert_array_equal(got.frames, want.frames)
        assert (got.emotion, got.speaker, got.fps) == (want.emotion, want.speaker, want.fps)
        assert [span.phoneme for span in got.phones] == [span.phoneme for span in want.phones]
        for got_span, want_span in zip(got.phones, want.phones):
            assert got_span.start == pytest.approx(want_span.start, abs=phone_tolerance)
            assert got_span.end == pytest.approx(want_span.end, abs=phone_tolerance)


@pytest.mark.parametrize(
    ("phones_format", "tolerance"), [("textgrid", 0.0), ("lab", 0.0), ("htk", 5e-8)]
)
def test_round_trip(tmp_path: Path, phones_format: str, tolerance: float) -> None:
    original = exact_corpus()
    write_corpus(original, tmp_path / "out", phones_format=phones_format)
    loaded = load_corpus(tmp_path / "out")
    assert_same(loaded, original, tolerance)
    if tolerance == 0.0:
        assert loaded.digest() == original.digest()


def test_lab_files_use_the_requested_units(tmp_path: Path) -> None:
    write_corpus(exact_corpus(), tmp_path / "s", phones_format="lab")
    write_corpus(exact_corpus(), tmp_path / "h", phones_format="htk")
    assert (tmp_path / "s" / "utt00.lab").read_text().splitlines()[1] == "0.12 0.31 HH"
    assert (tmp_path / "h" / "utt00.lab").read_text().splitlines()[1] == "1200000 3100000 HH"


def test_written_files(tmp_path: Path) -> None:
    write_corpus(exact_corpus(audio=True), tmp_path)
    names = sorted(path.name for path in tmp_path.iterdir())
    assert names == [
        "corpus.json",
        "utt00.TextGrid",
        "utt00.csv",
        "utt00.json",
        "utt00.wav",
        "utt01.TextGrid",
        "utt01.csv",
        "utt01.json",
        "utt02.TextGrid",
        "utt02.csv",
        "utt02.json",
    ]
    csv_lines = (tmp_path / "utt00.csv").read_text().splitlines()
    assert csv_lines[0] == "time,jawOpen,mouthClose,headYaw"
    assert csv_lines[2].startswith("0.020000,")
    config = json.loads((tmp_path / "corpus.json").read_text())
    assert config == {"name": "tiny", "fps": 50.0, "channels": list(CHANNELS), "heldout": ["utt01"]}
    assert json.loads((tmp_path / "utt01.json").read_text()) == {"emotion": "sad"}


def test_audio_survives_as_16_bit(tmp_path: Path) -> None:
    original = exact_corpus(audio=True)
    write_corpus(original, tmp_path)
    loaded = load_corpus(tmp_path)
    got, want = loaded.utterances[0].audio, original.utterances[0].audio
    assert got is not None and want is not None
    assert got.sample_rate == 16000
    np.testing.assert_allclose(got.samples, want.samples, atol=1e-4)
    assert loaded.utterances[1].audio is None


def test_60_fps_floats_survive_to_writer_precision(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    times = np.arange(90) / 60
    frames = np.stack([np.sin(3 * times), np.cos(2 * times), rng.normal(0, 1e-3, 90)], axis=1)
    utterance = Utterance("x", frames, [PhonemeSpan("AA", 0.0, 1.48)], fps=60.0)
    original = Corpus("c", 60.0, CHANNELS, [utterance])
    write_corpus(original, tmp_path)
    loaded = load_corpus(tmp_path)
    assert loaded.utterances[0].frames.shape == (90, 3)
    # only the %.6f rounding of the values remains: times on i/60 snap back to the grid
    np.testing.assert_allclose(loaded.utterances[0].frames, frames, atol=5.1e-7)


def test_120_fps_round_trip_is_exact_on_the_value_lattice(tmp_path: Path) -> None:
    frames = np.random.default_rng(2).integers(-999, 999, size=(241, 3)) / 1000
    utterance = Utterance("x", frames, [PhonemeSpan("AA", 0.0, 2.0)], fps=120.0)
    original = Corpus("c", 120.0, CHANNELS, [utterance])
    write_corpus(original, tmp_path)
    loaded = load_corpus(tmp_path)
    np.testing.assert_array_equal(loaded.utterances[0].frames, original.utterances[0].frames)
    assert loaded.digest() == original.digest()


def test_refuses_a_directory_with_corpus_files(tmp_path: Path) -> None:
    (tmp_path / "old.csv").write_text("time,a\n0,0\n")
    with pytest.raises(CorpusError, match="already holds corpus files"):
        write_corpus(exact_corpus(), tmp_path)


def test_refuses_unknown_phone_format_and_bad_stems(tmp_path: Path) -> None:
    with pytest.raises(CorpusError, match="phones_format"):
        write_corpus(exact_corpus(), tmp_path / "a", phones_format="json")
    corpus = exact_corpus()
    corpus.utterances[0].stem = "../escape"
    with pytest.raises(CorpusError, match="cannot name a file"):
        write_corpus(corpus, tmp_path / "b")


def test_write_frames_csv_reads_back(tmp_path: Path) -> None:
    frames = np.array([[0.25, -1.5], [0.5, 2.0], [0.125, 0.0]])
    write_frames_csv(tmp_path / "f.csv", frames, ("jawOpen", "headYaw"), 25.0)
    times, loaded, channels = read_frames_csv(tmp_path / "f.csv")
    np.testing.assert_array_equal(times, [0.0, 0.04, 0.08])
    np.testing.assert_array_equal(loaded, frames.astype(np.float32))
    assert channels == ("jawOpen", "headYaw")
    with pytest.raises(CorpusError, match="do not match"):
        write_frames_csv(tmp_path / "g.csv", frames, ("jawOpen",), 25.0)
