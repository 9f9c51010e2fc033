"""The load-time checks every engine reads its stored model through."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from lipstream.errors import ModelStoreError
from lipstream.model_checks import (
    ArrayReader,
    FieldReader,
    check_ascending,
    check_finite,
    check_indices,
    check_kind,
    check_offsets,
    check_range,
    check_shape,
)

WHERE = "m/arrays.npz: x"


def _refused(call: Callable[..., object], *args: object, **kwargs: object) -> ModelStoreError:
    with pytest.raises(ModelStoreError) as caught:
        call(*args, **kwargs)
    assert caught.value.code == "model_invalid"
    return caught.value


def test_offsets_must_run_from_zero_to_the_item_count_without_going_back() -> None:
    check_offsets(WHERE, np.array([0, 2, 2, 5]), 5)
    assert "from 0 to 5" in _refused(check_offsets, WHERE, np.array([1, 2, 5]), 5).message
    assert "from 0 to 6" in _refused(check_offsets, WHERE, np.array([0, 2, 5]), 6).message
    assert "from 0 to 0" in _refused(check_offsets, WHERE, np.zeros(0, np.int64), 0).message
    error = _refused(check_offsets, WHERE, np.array([0, 4, 3, 5]), 5)
    assert error.message == "must be non-decreasing: 4 at 1 is followed by 3"
    assert error.where == WHERE


def test_nonempty_offsets_refuse_an_empty_row() -> None:
    check_offsets(WHERE, np.array([0, 1, 3]), 3, nonempty=True)
    error = _refused(check_offsets, WHERE, np.array([0, 2, 2, 3]), 3, nonempty=True)
    assert error.message == "must be strictly increasing: 2 at 1 is followed by 2"


def test_ascending_is_judged_without_integer_wrap_around() -> None:
    # int32 differences would wrap: -2**31 - (2**31 - 1) is +1 in 32 bits.
    values = np.array([2**31 - 1, -(2**31)], dtype=np.int32)
    _refused(check_ascending, WHERE, values, strict=False)


def test_indices_outside_the_range_name_the_first_position() -> None:
    check_indices(WHERE, np.array([[-1, 0], [3, 2]]), -1, 4)
    check_indices(WHERE, np.zeros((0, 3), np.int32), 0, 0)
    error = _refused(check_indices, WHERE, np.array([[-1, 0], [4, -2]]), -1, 4)
    assert error.message == "value 4 at (1, 0) is outside [-1, 4)"


def test_non_finite_values_are_counted() -> None:
    check_finite(WHERE, np.ones((2, 2)))
    values = np.array([[0.0, np.inf], [np.nan, 1.0]], dtype=np.float32)
    assert _refused(check_finite, WHERE, values).message == (
        "holds 2 NaN or infinite values (first at (0, 1))"
    )


def test_shapes_and_kinds() -> None:
    check_shape(WHERE, np.zeros((3, 4)), (None, 4))
    assert _refused(check_shape, WHERE, np.zeros((3, 4)), (None, 5)).message == (
        "has shape (3, 4), expected (n, 5)"
    )
    assert _refused(check_shape, WHERE, np.zeros((3, 1)), (3,)).message == (
        "has shape (3, 1), expected (3,)"
    )
    check_kind(WHERE, np.zeros(2, np.int16), "i")
    for refused in (np.zeros(2, np.uint32), np.zeros(2, ">i4"), np.zeros(2, np.float64)):
        _refused(check_kind, WHERE, refused, "i")
    _refused(check_kind, WHERE, np.zeros(2, ">f8"), "f")


def test_an_array_reader_names_the_file_and_the_array() -> None:
    reader = ArrayReader({"offsets": np.array([0, 3]), "x": np.zeros(3)}, "m/arrays.npz")
    assert reader.offsets("offsets", 1, 3, nonempty=True).tolist() == [0, 3]
    assert _refused(reader.floats, "y", (3,)).where == "m/arrays.npz: y"
    assert _refused(reader.integers, "x", (3,)).where == "m/arrays.npz: x"
    assert _refused(reader.offsets, "offsets", 2, 3, nonempty=True).where == (
        "m/arrays.npz: offsets"
    )


@pytest.mark.parametrize(
    ("read", "value", "message"),
    [
        ("integer", "3", "must be an integer in [1, 9], got '3'"),
        ("integer", True, "must be an integer in [1, 9], got True"),
        ("integer", 10, "must be an integer in [1, 9], got 10"),
        ("number", "3", "must be a number in (0, 9], got '3'"),
        ("number", float("nan"), "must be a number in (0, 9], got nan"),
        ("number", 0, "must be a number in (0, 9], got 0"),
        ("flag", 1, "must be true or false, got 1"),
        ("string", "", "must be 1 to 128 characters, got 0"),
        ("string", "a\x00b", "must not contain control characters"),
        ("string", 7, "must be a string, got 7"),
        ("mapping", [1], "must be an object, got [1]"),
    ],
)
def test_field_reads_name_the_field(read: str, value: object, message: str) -> None:
    fields = FieldReader("m/model.json")
    calls = {
        "integer": lambda: fields.integer(value, "a.b", 1, 9),
        "number": lambda: fields.number(value, "a.b", 0.0, 9.0, above=True),
        "flag": lambda: fields.flag(value, "a.b"),
        "string": lambda: fields.string(value, "a.b"),
        "mapping": lambda: fields.mapping(value, "a.b"),
    }
    error = _refused(calls[read])
    assert (error.where, error.message) == ("m/model.json: a.b", message)


def test_a_long_value_is_not_echoed_whole() -> None:
    error = _refused(FieldReader("m/model.json").flag, "x" * 10_000, "f")
    assert error.message == "must be true or false, got str (10002 characters)"


def test_values_outside_a_range_name_the_first_position() -> None:
    check_range(WHERE, np.array([0.1, 100.0]), 0.1, 100.0)
    error = _refused(check_range, WHERE, np.array([[1.0, 2.0], [1e300, -5.0]]), 0.0, 10.0)
    assert error.message == "value 1e+300 at (1, 0) is outside [0, 10]"
    assert error.where == WHERE


def test_floats_stay_within_the_default_magnitude_unless_given_a_range() -> None:
    reader = ArrayReader({"x": np.array([-1e6, 1e6]), "y": np.array([2e6])}, "m/arrays.npz")
    reader.floats("x", (2,))
    error = _refused(reader.floats, "y", (1,))
    assert (error.where, error.message) == (
        "m/arrays.npz: y",
        "value 2e+06 at (0,) is outside [-1e+06, 1e+06]",
    )
    reader.floats("y", (1,), 0.0, 1e7)
    assert "outside [0, 1]" in _refused(reader.floats, "x", (2,), 0.0, 1.0).message
