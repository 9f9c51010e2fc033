"""The duration model against the durations that generated a synthetic alignment."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lipstream.engines.durations import DurationModel
from lipstream.errors import ModelStoreError
from lipstream.model_checks import ArrayReader
from lipstream.phonemes import PHONEME_INDEX
from lipstream.timeline import PhonemeSpan

GENERATING_MEDIAN_S = {"AA": 0.12, "P": 0.05, "S": 0.09}
LOG_STD = 0.25


def _alignment(seed: int, utterances: int) -> list[list[PhonemeSpan]]:
    rng = np.random.default_rng(seed)
    alignment = []
    for _ in range(utterances):
        spans, cursor = [], 0.0
        for phoneme in rng.choice(list(GENERATING_MEDIAN_S), size=30):
            length = GENERATING_MEDIAN_S[phoneme] * math.exp(rng.normal(0.0, LOG_STD))
            spans.append(PhonemeSpan(str(phoneme), cursor, cursor + length))
            cursor += length
        alignment.append(spans)
    return alignment


def test_medians_and_spreads_recover_the_generating_ones() -> None:
    model = DurationModel.fit(_alignment(seed=3, utterances=200))
    for phoneme, median in GENERATING_MEDIAN_S.items():
        assert model.expected_s(phoneme) == pytest.approx(median, rel=0.03)
        assert model.log_std[PHONEME_INDEX[phoneme]] == pytest.approx(LOG_STD, rel=0.08)
        assert model.count[PHONEME_INDEX[phoneme]] > 1500


def test_unseen_phonemes_borrow_the_pooled_median() -> None:
    spans = [PhonemeSpan("AA", 0.0, 0.1), PhonemeSpan("AA", 0.1, 0.3), PhonemeSpan("P", 0.3, 0.7)]
    spans.append(PhonemeSpan("AA", 0.7, 1.1))
    model = DurationModel.fit([spans])
    assert model.expected_s("AA") == pytest.approx((0.1 * 0.2 * 0.4) ** (1 / 3))
    pooled = (0.1 * 0.2 * 0.4 * 0.4) ** (1 / 4)
    assert model.expected_s("P") == pytest.approx(pooled)
    assert model.expected_s("M") == pytest.approx(pooled)


def test_the_statistics_survive_the_array_round_trip() -> None:
    model = DurationModel.fit(_alignment(seed=5, utterances=5))
    again = DurationModel.from_arrays(ArrayReader(model.arrays(), "arrays.npz"))
    np.testing.assert_array_equal(again.log_mean, model.log_mean)
    np.testing.assert_array_equal(again.count, model.count)


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("duration_count", np.full(3, 1)),
        ("duration_log_mean", np.full(len(PHONEME_INDEX), np.nan)),
        ("duration_log_std", np.full(len(PHONEME_INDEX), -1.0)),
    ],
)
def test_bad_stored_statistics_are_refused_naming_the_array(name: str, value: np.ndarray) -> None:
    arrays = {**DurationModel.fit(_alignment(seed=5, utterances=5)).arrays(), name: value}
    with pytest.raises(ModelStoreError) as caught:
        DurationModel.from_arrays(ArrayReader(arrays, "arrays.npz"))
    assert caught.value.code == "model_invalid"
    where = caught.value.where
    assert where is not None and where.startswith("arrays.npz: duration_")
