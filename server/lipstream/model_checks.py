"""Load-time checks of a stored model: manifest fields and the arrays compiled kernels index.

Sketch: the compiled kernels (numba) index arrays without bounds checks, so one
stored index out of range reads outside memory and kills the process, and one
NaN poisons every frame. Nothing stored reaches them unchecked: a model's
loader reads each manifest field through a ``FieldReader`` and each array
through an ``ArrayReader`` once, when the model loads, and declares what it
needs (dtype kind, shape, index bounds, monotone offsets, finite values,
value ranges).

Ranges: a finite value can still be absurd (a filter rate of 1e300 loads and
then makes every frame NaN), so every stored float also lies in a range: the
one its loader documents for that array, else [-``MAX_MAGNITUDE``,
``MAX_MAGNITUDE``], far beyond any channel value, weight, cost or time a
model holds, and small enough that a kernel's sums and squares of them stay
finite.
Every failure is a ``ModelStoreError`` (code ``model_invalid``) whose
``where`` names the file and the field or array, for example
``.../model.json: hyperparameters.max_tile`` or
``.../arrays.npz: all_index_transitions``. The checks are whole-array numpy
passes, so a model costs one read of its arrays at load and nothing per
request.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .errors import ModelStoreError

MAX_NAME_LENGTH = 128
MAX_MAGNITUDE = 1e6
"""The largest magnitude of a stored float whose loader documents no narrower range."""
Shape = Sequence[int | None]
"""An expected shape: one entry per dimension, None where any length is allowed."""


def field_error(source: str, field: str, message: str) -> ModelStoreError:
    """``model_invalid`` at ``field`` of the file ``source``."""
    return ModelStoreError(message, where=f"{source}: {field}")


def _describe(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else f"{type(value).__name__} ({len(text)} characters)"


class FieldReader:
    """Typed reads of the fields of one JSON file (``source``); a field is named by its
    dotted path, ``hyperparameters.max_tile``."""

    def __init__(self, source: str) -> None:
        self.source = source

    def error(self, field: str, message: str) -> ModelStoreError:
        return field_error(self.source, field, message)

    def member(self, mapping: Mapping[str, Any], key: str, field: str) -> Any:
        """``mapping[key]``, or an error naming ``field`` when it is missing."""
        if key not in mapping:
            raise self.error(field, "is missing")
        return mapping[key]

    def mapping(self, value: Any, field: str) -> Mapping[str, Any]:
        if not isinstance(value, Mapping) or not all(isinstance(key, str) for key in value):
            raise self.error(field, f"must be an object, got {_describe(value)}")
        return value

    def string(
        self,
        value: Any,
        field: str,
        *,
        choices: Sequence[str] | None = None,
        max_length: int = MAX_NAME_LENGTH,
    ) -> str:
        """A string of 1 to ``max_length`` characters without control characters, one of
        ``choices`` when given."""
        if not isinstance(value, str):
            raise self.error(field, f"must be a string, got {_describe(value)}")
        if choices is not None:
            if value not in choices:
                raise self.error(field, f"must be one of {', '.join(choices)}, got {value!r}")
            return value
        if not 1 <= len(value) <= max_length:
            raise self.error(field, f"must be 1 to {max_length} characters, got {len(value)}")
        if any(ord(character) < 32 or ord(character) == 127 for character in value):
            raise self.error(field, "must not contain control characters")
        return value

    def strings(
        self, value: Any, field: str, *, unique: bool = False, min_count: int = 0
    ) -> list[str]:
        """A list of at least ``min_count`` strings (each as in ``string``)."""
        if not isinstance(value, list):
            raise self.error(field, f"must be a list of strings, got {_describe(value)}")
        if len(value) < min_count:
            raise self.error(field, f"must hold at least {min_count} strings, got {len(value)}")
        items = [self.string(item, f"{field}[{index}]") for index, item in enumerate(value)]
        if unique and len(set(items)) != len(items):
            repeated = sorted(item for item, count in Counter(items).items() if count > 1)
            raise self.error(field, f"must not repeat names, repeats {repeated[:5]}")
        return items

    def integer(self, value: Any, field: str, low: int, high: int) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise self.error(
                field, f"must be an integer in [{low}, {high}], got {_describe(value)}"
            )
        return value

    def number(
        self, value: Any, field: str, low: float, high: float, *, above: bool = False
    ) -> float:
        """A finite number in [low, high], or (low, high] when ``above``."""
        number_like = isinstance(value, (int, float)) and not isinstance(value, bool)
        inside = number_like and math.isfinite(value)
        inside = inside and (low < value if above else low <= value) and value <= high
        if not inside:
            opening = "(" if above else "["
            raise self.error(
                field, f"must be a number in {opening}{low:g}, {high:g}], got {_describe(value)}"
            )
        return float(value)

    def flag(self, value: Any, field: str) -> bool:
        if not isinstance(value, bool):
            raise self.error(field, f"must be true or false, got {_describe(value)}")
        return value


def check_shape(where: str, array: np.ndarray, shape: Shape) -> None:
    """``array`` has ``len(shape)`` dimensions, each of the given length (None: any)."""
    lengths = ", ".join("n" if length is None else str(length) for length in shape)
    expected = f"({lengths},)" if len(shape) == 1 else f"({lengths})"
    if array.ndim != len(shape) or any(
        length is not None and actual != length for actual, length in zip(array.shape, shape)
    ):
        raise ModelStoreError(f"has shape {array.shape}, expected {expected}", where=where)


def check_kind(where: str, array: np.ndarray, kinds: str) -> None:
    """The dtype is native-endian and of one of the numpy ``kinds`` ("i": signed
    integers, "f": floats); unsigned indices are refused, as a kernel's -1 sentinel and
    its signed arithmetic would wrap them."""
    dtype = array.dtype
    if dtype.kind not in kinds or not dtype.isnative or dtype.fields is not None:
        wanted = "signed integer" if kinds == "i" else "floating-point"
        raise ModelStoreError(
            f"has dtype {dtype.str}, expected a native {wanted} type", where=where
        )


def check_finite(where: str, array: np.ndarray) -> None:
    """No NaN or infinity."""
    finite = np.isfinite(array)
    if not finite.all():
        raise ModelStoreError(
            f"holds {array.size - int(finite.sum())} NaN or infinite values (first at "
            f"{_first_false(finite)})",
            where=where,
        )


def check_range(where: str, array: np.ndarray, low: float, high: float) -> None:
    """Every value lies in [low, high] (NaN lies nowhere)."""
    if array.size == 0:
        return
    inside = (array >= low) & (array <= high)
    if not inside.all():
        first = _first_false(inside)
        raise ModelStoreError(
            f"value {array[first]:.6g} at {first} is outside [{low:g}, {high:g}]", where=where
        )


def _first_false(mask: np.ndarray) -> tuple[int, ...]:
    """The index of ``mask``'s first False, in C order."""
    return tuple(int(i) for i in np.unravel_index(int(np.argmin(mask)), mask.shape))


def check_indices(where: str, array: np.ndarray, low: int, high: int) -> None:
    """Every value lies in [low, high)."""
    if array.size == 0:
        return
    outside = (array < low) | (array >= high)
    if outside.any():
        first = np.unravel_index(int(np.argmax(outside)), array.shape)
        raise ModelStoreError(
            f"value {array[first]} at {tuple(int(i) for i in first)} is outside [{low}, {high})",
            where=where,
        )


def check_ascending(where: str, array: np.ndarray, *, strict: bool) -> None:
    """A 1-D integer array in ascending order (``strict``: no repeats)."""
    steps = np.diff(np.asarray(array, dtype=np.int64))
    wrong = steps <= 0 if strict else steps < 0
    if wrong.any():
        at = int(np.argmax(wrong))
        order = "strictly increasing" if strict else "non-decreasing"
        raise ModelStoreError(
            f"must be {order}: {array[at]} at {at} is followed by {array[at + 1]}", where=where
        )


def check_offsets(where: str, offsets: np.ndarray, n_items: int, *, nonempty: bool = False) -> None:
    """CSR offsets over ``n_items`` items: from 0 to ``n_items``, non-decreasing (strictly
    when every row must be ``nonempty``)."""
    if offsets.size == 0 or offsets[0] != 0 or offsets[-1] != n_items:
        ends = (offsets[0], offsets[-1]) if offsets.size else "nothing"
        raise ModelStoreError(f"must run from 0 to {n_items}, runs {ends}", where=where)
    check_ascending(where, offsets, strict=nonempty)


class ArrayReader:
    """The arrays of one model (from the file ``source``), each read with its kind and
    shape checked; errors name the file and the array."""

    def __init__(self, arrays: Mapping[str, np.ndarray], source: str) -> None:
        self.arrays = arrays
        self.source = source

    def where(self, name: str) -> str:
        return f"{self.source}: {name}"

    def error(self, name: str, message: str) -> ModelStoreError:
        return ModelStoreError(message, where=self.where(name))

    def _get(self, name: str, kinds: str, shape: Shape) -> np.ndarray:
        if name not in self.arrays:
            raise self.error(name, "is missing")
        array = self.arrays[name]
        check_kind(self.where(name), array, kinds)
        check_shape(self.where(name), array, shape)
        return array

    def integers(
        self, name: str, shape: Shape, low: int | None = None, high: int | None = None
    ) -> np.ndarray:
        """An integer array of ``shape``, every value in [low, high) when both are given."""
        array = self._get(name, "i", shape)
        if low is not None and high is not None:
            check_indices(self.where(name), array, low, high)
        return array

    def floats(
        self,
        name: str,
        shape: Shape,
        low: float = -MAX_MAGNITUDE,
        high: float = MAX_MAGNITUDE,
    ) -> np.ndarray:
        """A floating-point array of ``shape`` without NaN or infinity, every value in
        [low, high] (by default within ``MAX_MAGNITUDE``)."""
        array = self._get(name, "f", shape)
        check_finite(self.where(name), array)
        check_range(self.where(name), array, low, high)
        return array

    def offsets(self, name: str, rows: int | None, n_items: int, *, nonempty: bool) -> np.ndarray:
        """CSR offsets (rows + 1,) over ``n_items`` items (see ``check_offsets``)."""
        array = self._get(name, "i", (None if rows is None else rows + 1,))
        check_offsets(self.where(name), array, n_items, nonempty=nonempty)
        return array
