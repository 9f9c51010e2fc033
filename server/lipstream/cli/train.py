"""``lipstream train``: train one engine, or all, on a corpus directory."""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

from ..config import Settings

if TYPE_CHECKING:
    from .commands import Commands


def _train(args: argparse.Namespace, settings: Settings) -> None:
    from ..corpus import CorpusWarning, load_corpus
    from ..status import Heartbeat, phase, to_stderr
    from ..training import resolve_engines, train_engine, train_engines

    engines = resolve_engines(args.engine)
    with warnings.catch_warnings(record=True) as ignored:
        warnings.simplefilter("always", CorpusWarning)
        corpus = load_corpus(args.corpus, progress=True, tier=args.tier)
    for warning in ignored:
        print(f"warning: {warning.message}", file=sys.stderr)
    out = Path(args.out)
    heartbeat = Heartbeat(to_stderr).start()  # a stage with no bar of its own still shows
    try:
        if args.engine == "all":
            written = train_engines(corpus, engines, out, report=heartbeat.report)
            print("trained " + ", ".join(f"{name} -> {path}" for name, path in written.items()))
            return
        with phase(f"training {args.engine} on the corpus", heartbeat.report):
            model = train_engine(corpus, engines[0], out, progress=True)
    finally:
        heartbeat.stop()
    print(f"trained {args.engine} -> {out} in {model.manifest.metrics['train_seconds']} s")


def add_train_parser(commands: Commands) -> None:
    train = commands.add_parser("train", help="train engines on a corpus directory")
    train.add_argument(
        "--corpus", required=True, help="corpus directory (docs/reference/corpus-formats.md)"
    )
    train.add_argument("--engine", required=True, help="an engine name, or all")
    train.add_argument(
        "--out",
        required=True,
        help="model directory to write; with --engine all, one subdirectory per engine",
    )
    train.add_argument(
        "--tier", help="TextGrid phone tier (default: corpus.json's tier, else phones/MAU/...)"
    )
    train.set_defaults(run=_train)
