"""``lipstream inspect``: summarize a model directory, or a directory of them."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

from ..config import Settings

if TYPE_CHECKING:
    from .commands import Commands


def _inspect(args: argparse.Namespace, settings: Settings) -> None:
    from ..models import model_dirs
    from ..store import read_manifest

    for directory in model_dirs(Path(args.dir)):
        manifest = read_manifest(directory)
        print(
            f"{directory}: engine {manifest.engine}, character {manifest.name}, "
            f"{len(manifest.channels)} channels at {manifest.fps:g} fps"
        )
        print(f"  hyperparameters: {json.dumps(manifest.hyperparameters, sort_keys=True)}")
        print(f"  corpus digest: {manifest.corpus_digest}")
        print(f"  metrics: {json.dumps(manifest.metrics, sort_keys=True)}")
        print(f"  channels: {', '.join(manifest.channels)}")


def add_inspect_parser(commands: Commands) -> None:
    inspect = commands.add_parser("inspect", help="summarize a model directory")
    inspect.add_argument("dir", help="a model directory or a directory of them")
    inspect.set_defaults(run=_inspect)
