"""Modes: spline resampling, affinity propagation, context counts, stand-ins."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.corpus import Corpus
from lipstream.corpus.model import Utterance
from lipstream.engines.dam.modes import (
    PHONEME_INDEX,
    assign_modes,
    cluster,
    collect_occurrences,
    resample,
    stand_ins,
)
from lipstream.errors import CorpusError
from lipstream.phonemes import PHONEMES
from lipstream.timeline import EMOTION_INDEX, PhonemeSpan


def _corpus() -> Corpus:
    fps = 100.0
    times = np.arange(31) / fps
    ramp = np.stack([times, 2.0 * times + 1.0], axis=1)
    first = Utterance(
        "a", ramp, [PhonemeSpan("P", 0.0, 0.1), PhonemeSpan("AA", 0.1, 0.3)], fps, emotion="happy"
    )
    second = Utterance(
        "b", ramp[:21], [PhonemeSpan("AA", 0.0, 0.15), PhonemeSpan("M", 0.15, 0.2)], fps
    )
    return Corpus("tiny", fps, ("x", "y"), [first, second])


def test_occurrences_carry_neighbours_with_silence_at_the_ends() -> None:
    occurrences, frames = collect_occurrences(_corpus())
    assert frames.shape == (52, 2)
    names = [PHONEMES[p] for p in occurrences.phoneme]
    assert names == ["P", "AA", "AA", "M"]
    assert [PHONEMES[p] for p in occurrences.previous] == ["sil", "P", "sil", "AA"]
    assert [PHONEMES[p] for p in occurrences.following] == ["AA", "sil", "M", "sil"]
    assert occurrences.emotion.tolist() == [EMOTION_INDEX["happy"]] * 2 + [0, 0]
    assert occurrences.first_row.tolist() == [0, 0, 31, 31]


def test_resampling_a_linear_curve_is_exact() -> None:
    occurrences, frames = collect_occurrences(_corpus())
    curves = resample(occurrences, frames, 5).reshape(4, 5, 2)
    local = np.linspace(0, 1, 5)
    for index in range(4):
        times = occurrences.start[index] + occurrences.duration[index] * local
        np.testing.assert_allclose(curves[index, :, 0], times, atol=1e-12)
        np.testing.assert_allclose(curves[index, :, 1], 2 * times + 1, atol=1e-12)


def test_affinity_propagation_finds_separated_groups_numbered_by_first_appearance() -> None:
    rng = np.random.default_rng(0)
    centres = np.array([[5.0, 5.0], [-5.0, 0.0], [0.0, -6.0]])
    order = [2, 0, 1, 2, 0, 1] * 5
    curves = centres[order] + rng.normal(scale=0.05, size=(30, 2))
    labels = cluster(curves, 3)
    assert labels[:3].tolist() == [0, 1, 2]
    for group in range(3):
        members = [i for i, g in enumerate(order) if g == order[group]]
        assert set(labels[members].tolist()) == {group}
    assert cluster(curves[:2], 3).tolist() == [0, 0]


def test_mode_context_counts() -> None:
    occurrences, frames = collect_occurrences(_corpus())
    modes, mode_of = assign_modes(occurrences, resample(occurrences, frames, 4), 3)
    assert modes.count == 3  # P, AA, M: each below min_occurrences keeps one mode
    assert sorted(PHONEMES[p] for p in modes.phoneme) == ["AA", "M", "P"]
    aa = int(mode_of[1])
    assert mode_of[2] == aa
    assert modes.previous[aa, PHONEME_INDEX["P"]] == 1
    assert modes.previous[aa, PHONEME_INDEX["sil"]] == 1
    assert modes.following[aa, PHONEME_INDEX["M"]] == 1
    assert modes.emotion[aa].tolist() == [1, 1, 0, 0]
    assert np.diff(modes.offsets)[PHONEME_INDEX["AA"]] == 1
    assert modes.stand_in[PHONEME_INDEX["B"]] in (PHONEME_INDEX["P"], PHONEME_INDEX["M"])


def test_stand_ins_fall_back_to_the_viseme_class_then_silence() -> None:
    counts = np.zeros(len(PHONEMES), dtype=np.int64)
    counts[PHONEME_INDEX["P"]] = 2
    counts[PHONEME_INDEX["sil"]] = 1
    offsets = np.concatenate([[0], np.cumsum(counts)])
    result = stand_ins(offsets)
    assert result[PHONEME_INDEX["B"]] == PHONEME_INDEX["P"]
    assert result[PHONEME_INDEX["AA"]] == PHONEME_INDEX["sil"]
    assert result[PHONEME_INDEX["P"]] == PHONEME_INDEX["P"]
    counts[PHONEME_INDEX["sil"]] = 0
    counts[PHONEME_INDEX["AA"]] = 3
    result = stand_ins(np.concatenate([[0], np.cumsum(counts)]))
    assert result[PHONEME_INDEX["IY"]] == PHONEME_INDEX["AA"]  # no IY, no silence: most modes
    with pytest.raises(CorpusError):
        stand_ins(np.zeros(len(PHONEMES) + 1, dtype=np.int64))
