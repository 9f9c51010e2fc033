"""What a request's synthesizer reads of a DAM model (``DamServing``).

Sketch: the model builds its synthesizers and the synthesizer reads the model's
tables, so the tables' type lives here, where both import it: ``model`` imports
``causal``, and neither imports the other back. ``DamModel`` has every member (mypy
checks it where the model passes itself to a synthesizer).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ...numerics.basis import MotionBasis
from ...numerics.direct_call import DirectCall
from ..base import LookaheadSource
from .kernels import DamTables


class DamServing(LookaheadSource, Protocol):
    """A DAM model's tables as its causal synthesizers read them."""

    @property
    def channels(self) -> tuple[str, ...]: ...
    @property
    def basis(self) -> MotionBasis: ...
    @property
    def tables(self) -> DamTables: ...
    @property
    def span_rates(self) -> np.ndarray: ...
    @property
    def causal_call(self) -> DirectCall: ...
