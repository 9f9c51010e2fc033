"""Key-pose pairs as CSV: a hand-written table reads as its JSON twin, a written table reads
back exactly, and a malformed table is a coded error naming the file and the place."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lipstream.errors import ModelStoreError
from lipstream.output.retarget import KeyPosePairs, read_pairs, write_pairs
from tests.lipstream.output.test_retarget import CHANNELS, VALID_PAIRS, generated_rig, pairs_file

# VALID_PAIRS of test_retarget, as a spreadsheet would hold it
VALID_CSV = """name,source.jawOpen,source.mouthClose,source.eyeBlinkLeft,controls.open,controls.close
@rest,,0.1,,,0
AA,0.8,,,1,
MM,,0.9,,,1.0
@weight,,,0,,
"""


def _same(left: KeyPosePairs, right: KeyPosePairs) -> None:
    assert (left.channels, left.controls, left.key_names) == (
        right.channels,
        right.controls,
        right.key_names,
    )
    for name in ("source_rest", "control_rest", "source_keys", "control_keys", "channel_weights"):
        np.testing.assert_array_equal(getattr(left, name), getattr(right, name))


def test_a_csv_table_reads_as_the_same_pairs_as_its_json_twin(tmp_path: Path) -> None:
    path = tmp_path / "pairs.csv"
    path.write_text(VALID_CSV)
    _same(read_pairs(path, CHANNELS), read_pairs(pairs_file(tmp_path, VALID_PAIRS), CHANNELS))


def test_written_csv_pairs_read_back_exactly(tmp_path: Path) -> None:
    pairs, _ = generated_rig()
    pairs = KeyPosePairs(
        pairs.channels,
        pairs.controls,
        pairs.key_names,
        np.linspace(0.0, 0.1, len(pairs.channels)),
        np.full(len(pairs.controls), 0.05),
        pairs.source_keys,
        pairs.control_keys,
        np.array([1.0, 2.0, 0.5, 1.0, 0.0, 1.0]),
    )
    path = tmp_path / "written.csv"
    write_pairs(path, pairs)
    assert path.read_text().splitlines()[0].startswith("name,source.jawOpen,")
    _same(read_pairs(path, CHANNELS), pairs)


@pytest.mark.parametrize(
    ("table", "field"),
    [
        (VALID_CSV.replace("name,", "key,", 1), "header"),
        (VALID_CSV.replace("controls.close", "close"), "header"),
        (VALID_CSV.replace("AA,0.8,,,1,", "AA,0.8,,,1"), "row 3"),
        (VALID_CSV.replace("AA,0.8,", "AA,wide,"), "keys[0].source.jawOpen"),
        (VALID_CSV.replace("AA,0.8,", "AA,nan,"), "keys[0].source.jawOpen"),
        (VALID_CSV.replace("@weight,,,0,,", "@weight,,,0,1,"), "row 5"),
        (VALID_CSV.replace("MM,,0.9,,,1.0", "MM,,0.9,,,1.5"), "control_keys"),
    ],
)
def test_a_malformed_csv_table_is_model_invalid_naming_file_and_place(
    tmp_path: Path, table: str, field: str
) -> None:
    path = tmp_path / "pairs.csv"
    path.write_text(table)
    with pytest.raises(ModelStoreError) as caught:
        read_pairs(path, CHANNELS)
    assert caught.value.code == "model_invalid"
    assert caught.value.where == f"{path}: {field}"
