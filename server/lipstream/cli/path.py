"""``lipstream path demo``: where the demo character's models are, or will be built."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from ..config import Settings, demo_model_path

if TYPE_CHECKING:
    from .commands import Commands


def _path(args: argparse.Namespace, settings: Settings) -> None:
    print(demo_model_path(args.engine, settings) if args.engine else settings.demo_models_dir)


def add_path_parser(commands: Commands) -> None:
    path = commands.add_parser(
        "path", help="print where the demo character's models are (or will be built)"
    )
    path.add_argument("what", choices=["demo"], help="demo: the demo character's model directory")
    path.add_argument(
        "--engine", help="print this engine's model directory (e.g. viseme-lerp) instead"
    )
    path.set_defaults(run=_path)
