"""Compiled kernels are cached under ``$LIPSTREAM_HOME``, never inside the installed package.

Sketch: numba's ``cache=True`` writes ``.nbi``/``.nbc`` files into a ``__pycache__``
beside each source file unless ``NUMBA_CACHE_DIR`` names a folder. Files left there
outlive ``pip uninstall`` and turn ``site-packages/lipstream`` into a folder without
``__init__.py`` that hides a later editable install. Numba reads the variable once, when
it is first imported, and binds each kernel's cache folder when the kernel is decorated;
``lipstream/__init__.py`` imports this module before anything imports numba. It sets
``NUMBA_CACHE_DIR`` (when unset) to ``config.kernel_cache_dir()``, in ``os.environ`` so
that every process started from this one (uvicorn workers, load-test workers) inherits
it, and in numba's loaded configuration when numba was imported before lipstream.
"""

from __future__ import annotations

import os
import sys

from .config import NUMBA_CACHE_VARIABLE, kernel_cache_dir


def use_kernel_cache_dir() -> str:
    """Point numba's cache at ``kernel_cache_dir()`` unless ``NUMBA_CACHE_DIR`` is set;
    the folder in use."""
    folder = str(kernel_cache_dir())
    os.environ.setdefault(NUMBA_CACHE_VARIABLE, folder)
    numba_config = sys.modules.get("numba.core.config")
    if numba_config is not None and not getattr(numba_config, "CACHE_DIR", ""):
        numba_config.CACHE_DIR = folder  # type: ignore[attr-defined]
    return folder


use_kernel_cache_dir()
