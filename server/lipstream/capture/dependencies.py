"""The capture extra's packages, imported on first use with a coded error when absent."""

from __future__ import annotations

import importlib
from typing import Any

from ..errors import LipstreamError
from .errors import MISSING_DEPENDENCY


def require(module: str) -> Any:
    """``module`` imported; ``missing_dependency`` naming the extra when it is not installed."""
    try:
        return importlib.import_module(module)
    except ImportError as error:
        raise LipstreamError(
            f'lipstream capture needs the capture extra: pip install "lipstream[capture]" '
            f"({error})",
            where=module.split(".")[0],
            code=MISSING_DEPENDENCY,
        ) from None


def require_capture_extra() -> None:
    """``missing_dependency`` before any work when PyAV or mediapipe is not installed."""
    require("av")
    require("mediapipe")
