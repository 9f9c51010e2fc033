"""lipstream: real-time lip-sync server.

Public, stable API for in-process use::

    import lipstream
    model = lipstream.load_model("models/viseme-lerp")
    frames, channels, fps = model.synthesize([("HH", 0.0, 0.1), ("AY", 0.1, 0.3)], fps=60)
    synthesizer = model.start(fps=60)   # streaming: feed(), frames(), finish()
    lipstream.demo_model_path("viseme-lerp")  # where the demo character's model is
"""

from __future__ import annotations

# First: numba reads NUMBA_CACHE_DIR when it is imported (kernel_cache.py says why).
from . import kernel_cache  # noqa: F401
from ._version import __version__
from .config import demo_model_path
from .engines import load_model
from .engines.base import (
    Lookahead,
    Model,
    Rung,
    SynthesisRequest,
    SynthesisResult,
    Synthesizer,
)
from .timeline import PhonemeSpan

__all__ = [
    "Lookahead",
    "Model",
    "PhonemeSpan",
    "Rung",
    "SynthesisRequest",
    "SynthesisResult",
    "Synthesizer",
    "__version__",
    "demo_model_path",
    "load_model",
]
