"""Float32 little-endian payloads without numpy.

Sketch: frame data travels as row-major float32 little-endian bytes.
``struct`` packs with IEEE rounding and refuses values beyond the float32
range; ``array('f')`` unpacks at C speed (byte-swapped on big-endian hosts).
Finiteness is checked on the raw bytes: a float32 is NaN or infinite exactly
when its eight exponent bits are all ones, i.e. when byte 3 has bits 0x7F set
and byte 2 has bit 0x80 set. Two byte translations and one big-integer AND
test every value at C speed.
"""

from __future__ import annotations

import struct
import sys
from array import array
from collections.abc import Sequence

FLOAT32_BYTES = 4
_EXPONENT_HIGH = bytes(1 if byte & 0x7F == 0x7F else 0 for byte in range(256))
_EXPONENT_LOW = bytes(1 if byte & 0x80 else 0 for byte in range(256))
_MAX_FLOAT32_DIGITS = 9


def pack_float32(values: Sequence[float]) -> bytes:
    """Pack numbers as float32 little-endian.

    OverflowError beyond the float32 range; struct.error for integers too
    large for a double.
    """
    return struct.pack(f"<{len(values)}f", *values)


def unpack_float32(data: bytes) -> list[float]:
    """Float32 little-endian bytes (length a multiple of 4) to Python floats."""
    values = array("f")
    values.frombytes(data)
    if sys.byteorder == "big":
        values.byteswap()
    return values.tolist()


def all_finite_float32(data: bytes) -> bool:
    """True when no float32 in the little-endian ``data`` is NaN or infinite."""
    high = data[3::FLOAT32_BYTES].translate(_EXPONENT_HIGH)
    low = data[2::FLOAT32_BYTES].translate(_EXPONENT_LOW)
    return not int.from_bytes(high, "little") & int.from_bytes(low, "little")


def split_rows(values: list[float], width: int) -> list[list[float]]:
    """Flat row-major values to rows of ``width``."""
    return [values[start : start + width] for start in range(0, len(values), width)]


def shortest_float32(value: float) -> float:
    """The float whose decimal repr is shortest among those that round to the same float32.

    ``value`` must be finite and representable as float32. JSON then carries
    ``0.1`` rather than ``0.10000000149011612`` and still decodes to the
    identical float32. Rounding to more digits never moves further away, so
    the fewest round-tripping digits (1 to 9) are found by bisection.
    """
    target = struct.pack("<f", value)
    low, high = 1, _MAX_FLOAT32_DIGITS
    while low < high:
        middle = (low + high) // 2
        if struct.pack("<f", _rounded(value, middle)) == target:
            high = middle
        else:
            low = middle + 1
    return _rounded(value, low)


def _rounded(value: float, digits: int) -> float:
    return float(f"{value:.{digits}g}")
