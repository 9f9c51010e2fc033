"""Engine 2: Dominated Animeme Models (Lin et al.) and the Cohen-Massaro baseline.

``modes`` (occurrences resampled and clustered), ``dominance`` (Eq. 1),
``em`` (E-step Eq. 5-7, M-step Eq. 8-9, the convergence monitor), ``tails``
(the truncated Eq. 2 and the lookahead bounding it), ``selection`` (the mode
search of Eq. 10), ``model`` (synthesis and the store), ``engine`` (``fit``).
"""

from .engine import CohenMassaroEngine, DamEngine
from .model import CohenMassaroModel, DamModel

__all__ = ["CohenMassaroEngine", "CohenMassaroModel", "DamEngine", "DamModel"]
