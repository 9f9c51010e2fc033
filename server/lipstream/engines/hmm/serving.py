"""What a request's synthesizer reads of an HMM model (``HmmServing``).

Sketch: the model builds its synthesizers and the synthesizer reads the model's
tables, so the tables' type lives here, where both import it: ``model`` imports
``synthesizer``, and neither imports the other back. ``HmmModel`` has every member
(mypy checks it where the model passes itself to a synthesizer).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ...features import MfccConfig, StreamingNormalizer
from ...numerics.basis import MotionBasis
from ...numerics.direct_call import DirectCall
from .gaussian import Gaussians
from .trajectory import Dynamics


class HmmServing(Protocol):
    """An HMM model's tables as its synthesizers read them."""

    @property
    def name(self) -> str: ...
    @property
    def channels(self) -> tuple[str, ...]: ...
    @property
    def hmm_fps(self) -> float: ...
    @property
    def mfcc(self) -> MfccConfig: ...
    @property
    def basis(self) -> MotionBasis: ...
    @property
    def log_start(self) -> np.ndarray: ...
    @property
    def log_transition(self) -> np.ndarray: ...
    @property
    def predecessors(self) -> tuple[np.ndarray, np.ndarray]: ...
    @property
    def categories(self) -> np.ndarray: ...
    @property
    def vocal(self) -> Gaussians | None: ...
    @property
    def audio_weight(self) -> float: ...
    @property
    def decode_step(self) -> DirectCall: ...
    @property
    def solve_step(self) -> DirectCall: ...

    def emotion_row(self, emotion: str) -> int: ...
    def normalizer(self) -> StreamingNormalizer | None: ...
    def dynamics_at(self, rate: float, coupled: bool = True) -> Dynamics: ...
