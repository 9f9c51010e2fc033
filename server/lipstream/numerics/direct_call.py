"""Calling a compiled kernel without numba's per-call argument typing.

Sketch: numba's dispatcher types every argument of every call to pick the compiled
overload. Arrays and scalars take a fast path in C; a NamedTuple is typed in Python, field
by field, which costs about a microsecond a call, as much as a small streaming kernel's
whole work. Kernels here take named groups of arrays (NamedTuples built in one place, with
fixed dtypes and layouts), so the argument types at one call site do not change from call
to call. A ``DirectCall`` lets the dispatcher type its first call (compiling, or loading
the cached machine code) and from then on calls that overload's entry point, which unboxes
the arguments by the signature it was compiled for. That skips the typing, not the
unboxing: a call costs what the same call with flat arguments cost.

The price is trust: arguments of other types than the first call's would be unboxed by the
wrong signature. So each call site holds its own ``DirectCall`` (a synthesizer's, built
with its model's arrays), and with ``check_types(True)`` (the test suite's setting) every
call's types are compared with the bound signature first, so a group built with another
dtype or layout fails the tests with ``TypeError`` instead.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

_checking = False


def check_types(enabled: bool) -> None:
    """Whether every ``DirectCall`` checks its arguments' types on every call (tests)."""
    global _checking
    _checking = enabled


class DirectCall:
    """``kernel`` (an ``@njit`` function) called through the overload its first call picked."""

    __slots__ = ("kernel", "_entry", "_signature")

    def __init__(self, kernel: Any) -> None:
        self.kernel: Any = kernel  # a numba Dispatcher; its stubs lack overloads' entry points
        self._entry: Callable[..., Any] | None = None
        self._signature: tuple[Any, ...] = ()

    def __call__(self, *args: Any) -> Any:
        entry = self._entry
        if entry is None:
            return self._bind(args)
        if _checking:
            self._check(args)
        return entry(*args)

    def _bind(self, args: tuple[Any, ...]) -> Any:
        result = self.kernel(*args)
        signature = tuple(self.kernel.typeof_pyval(arg) for arg in args)
        self._signature = signature
        overload = self.kernel.overloads.get(signature)
        # None when the dispatcher converted an argument to fit an existing overload
        self._entry = overload.entry_point if overload is not None else self.kernel
        return result

    def _check(self, args: tuple[Any, ...]) -> None:
        types = tuple(self.kernel.typeof_pyval(arg) for arg in args)
        if types != self._signature:
            raise TypeError(
                f"{self.kernel.__name__} was bound to {self._signature} and called with {types}"
            )
