"""Voice puppetry (Brand 1999): an entropically trained facial HMM driven by voice, phonemes
or both (``engine``, ``model``, ``synthesizer``)."""

from .engine import HmmEngine
from .model import HmmModel

__all__ = ["HmmEngine", "HmmModel"]
