"""Engine 4, ``expressive-dp``: expressive constrained DP over motion nodes (Deng & Neumann
2008), an exact fast search serving it in real time, and the phoneme-Isomap library."""

from .engine import ExpressiveDpEngine
from .model import ExpressiveDpModel

__all__ = ["ExpressiveDpEngine", "ExpressiveDpModel"]
