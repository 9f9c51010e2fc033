"""The export formats, their file extensions, and choosing one for an output path.

Kept free of heavy imports: the command line builds its options from it.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import InvalidRequestError

FORMATS: tuple[str, ...] = (
    "csv",
    "json",
    "livelink",
    "rhubarb-tsv",
    "rhubarb-xml",
    "rhubarb-json",
    "moho",
)
EXTENSIONS: dict[str, str] = {
    ".csv": "csv",
    ".json": "json",
    ".tsv": "rhubarb-tsv",
    ".xml": "rhubarb-xml",
    ".dat": "moho",
}
# Formats made from mouth shapes: they need output visemes "preston-blair".
SHAPE_FORMATS = frozenset({"rhubarb-tsv", "rhubarb-xml", "rhubarb-json", "moho"})
MOHO_FPS = 24.0  # Rhubarb's default --datFrameRate


def format_for(path: Path, requested: str | None = None) -> str:
    """``requested`` if given (one of ``FORMATS``), else the format of ``path``'s extension."""
    if requested is not None:
        if requested not in FORMATS:
            raise InvalidRequestError(
                f"unknown output format {requested!r}; expected one of {', '.join(FORMATS)}",
                where="format",
            )
        return requested
    found = EXTENSIONS.get(path.suffix.lower())
    if found is None:
        raise InvalidRequestError(
            f"unsupported output type {path.suffix!r} (use {', '.join(EXTENSIONS)}, "
            f"or name a format: {', '.join(FORMATS)})",
            where=str(path),
        )
    return found
