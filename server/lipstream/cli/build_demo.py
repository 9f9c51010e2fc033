"""``lipstream build-demo``: generate the demo corpus and train every engine on it."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from ..config import Settings

if TYPE_CHECKING:
    from .commands import Commands


def _build_demo(args: argparse.Namespace, settings: Settings) -> None:
    from ..status import Heartbeat, to_stderr
    from ..training import build_demo

    out = Path(args.out) if args.out else settings.demo_dir
    heartbeat = Heartbeat(to_stderr).start()
    try:
        written = build_demo(out, report=heartbeat.report)
    finally:
        heartbeat.stop()
    print(f"demo corpus in {out / 'corpus'}; models: {', '.join(map(str, written.values()))}")


def add_build_demo_parser(commands: Commands) -> None:
    demo = commands.add_parser("build-demo", help="generate the demo corpus and train every engine")
    demo.add_argument("--out", help="output directory (default: $LIPSTREAM_HOME/demo)")
    demo.set_defaults(run=_build_demo)
