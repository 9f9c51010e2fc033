"""lipstream: real-time lip-sync server.

Public, stable API for in-process use::

    import lipstream
    model = lipstream.load_model("models/viseme-lerp")
    frames, channels, fps = model.synthesize([("HH", 0.0, 0.1), ("AY", 0.1, 0.3)], fps=60)
    synthesizer = model.start(fps=60)   # streaming: feed(), frames(), finish()
    lipstream.demo_model_path("viseme-lerp")  # where the demo character's model is

The names load on first use (PEP 562), so ``import lipstream`` (and the ``lipstream``
command, which imports it first) stays cheap: ``lipstream serve`` listens and prints
before numpy, scipy and numba load.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING

# First: numba reads NUMBA_CACHE_DIR when it is imported (kernel_cache.py says why).
from . import kernel_cache  # noqa: F401
from ._version import __version__

if TYPE_CHECKING:
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

_HOMES = {
    "demo_model_path": ".config",
    "load_model": ".engines",
    "Lookahead": ".engines.base",
    "Model": ".engines.base",
    "Rung": ".engines.base",
    "SynthesisRequest": ".engines.base",
    "SynthesisResult": ".engines.base",
    "Synthesizer": ".engines.base",
    "PhonemeSpan": ".timeline",
}

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


def __getattr__(name: str) -> object:
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'lipstream' has no attribute {name!r}")
    value = getattr(import_module(home, __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
