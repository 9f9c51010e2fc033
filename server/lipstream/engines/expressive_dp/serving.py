"""What a request's synthesizer reads of an expressive-dp model (``ExpressiveDpServing``).

Sketch: the model builds its synthesizers and the synthesizer reads the model's
tables, so the tables' type lives here, where both import it: ``model`` imports
``synthesizer``, and neither imports the other back. ``ExpressiveDpModel`` has every
member (mypy checks it where the model passes itself to a synthesizer).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ...numerics.basis import MotionBasis
from ...numerics.direct_call import DirectCall
from ..base import LookaheadSource
from ..durations import DurationModel
from .causal_curve import NodeCurves
from .contamination import Contamination
from .nodes import NodeDatabase
from .postprocess import Renderer
from .search import SearchSpace


class ExpressiveDpServing(LookaheadSource, Protocol):
    """An expressive-dp model's tables as its synthesizers read them."""

    @property
    def channels(self) -> tuple[str, ...]: ...
    @property
    def basis(self) -> MotionBasis: ...
    @property
    def nodes(self) -> NodeDatabase: ...
    @property
    def space(self) -> SearchSpace: ...
    @property
    def contamination(self) -> Contamination: ...
    @property
    def renderer(self) -> Renderer: ...
    @property
    def rest_pose(self) -> np.ndarray: ...
    @property
    def curves(self) -> NodeCurves: ...
    @property
    def follow(self) -> DirectCall: ...
    @property
    def durations(self) -> DurationModel: ...
    @property
    def causal_omegas(self) -> np.ndarray: ...
