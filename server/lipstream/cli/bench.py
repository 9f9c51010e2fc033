"""``lipstream bench``: every engine on held-out utterances of a corpus, or with
``--word-timings`` the TTS timing formats against espeak-ng's own phonemes."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from ..config import Settings
from ..errors import LipstreamError

if TYPE_CHECKING:
    from .commands import Commands


def _bench(args: argparse.Namespace, settings: Settings) -> None:
    if (args.models or args.engines) and not args.real:
        raise LipstreamError(
            "--models and --engines go with --real", where="--models", code="invalid_request"
        )
    if args.real and (args.word_timings or args.no_engine_benches):
        raise LipstreamError(
            "--real measures the demo models on real lips; it takes no --word-timings or "
            "--no-engine-benches",
            where="--real",
            code="invalid_request",
        )
    if args.word_timings:
        _bench_word_timings(args, settings)
        return
    if args.real:
        _bench_real(args, settings)
        return
    from ..bench.harness import format_engine_benches, format_table, run_bench
    from ..bench.rungs import format_rungs
    from ..corpus import load_corpus
    from ..results_file import write_results
    from ..training import DEMO_CORPUS_DIR, build_demo

    corpus_dir = Path(args.corpus) if args.corpus else settings.demo_dir / DEMO_CORPUS_DIR
    if args.corpus is None and not corpus_dir.exists():
        build_demo(settings.demo_dir, progress=True)
    path = settings.results_file(args.results, "results.json")
    results = run_bench(
        load_corpus(corpus_dir, progress=True),
        engine_benches=not args.no_engine_benches,
        command=shlex.join(args.command_line),
    )
    write_results(results, path)
    print(f"wrote {path}", file=sys.stderr)
    if args.json:
        print(json.dumps(results, indent=2))
    else:
        print(format_table(results))
        print()
        print(format_rungs(results["rungs"]))
        print(format_engine_benches(results))


REAL_FACES_CORPUS = Path(__file__).resolve().parents[3] / "tests" / "data" / "grid" / "corpus"
"""The GRID real-face set a checkout ships (``tests/data/grid``)."""


def _bench_real(args: argparse.Namespace, settings: Settings) -> None:
    """``lipstream bench --real``: ``lipstream.bench.real_faces``."""
    from ..bench.real_faces import demo_models, format_real_table, run_real_bench
    from ..corpus import load_corpus
    from ..results_file import write_results
    from ..training import build_demo

    corpus_dir = Path(args.corpus) if args.corpus else REAL_FACES_CORPUS
    if not corpus_dir.is_dir():
        raise LipstreamError(
            "no real-face corpus here: give one made by `lipstream capture` with --corpus",
            where=str(corpus_dir),
            code="invalid_request",
        )
    models_dir = Path(args.models) if args.models else settings.demo_models_dir
    if args.models is None and not models_dir.exists():
        build_demo(settings.demo_dir, progress=True)
    path = settings.results_file(args.results, "real_faces.json")
    engines = args.engines.split(",") if args.engines else None
    results = run_real_bench(
        load_corpus(corpus_dir), demo_models(models_dir, engines), args.command_line
    )
    write_results(results, path)
    print(f"wrote {path}", file=sys.stderr)
    print(json.dumps(results, indent=2) if args.json else format_real_table(results))


def _bench_word_timings(args: argparse.Namespace, settings: Settings) -> None:
    """``lipstream bench --word-timings``: ``lipstream.bench.word_timings``."""
    from ..bench.word_timings import print_summary, run
    from ..results_file import write_results

    if args.corpus is not None or args.no_engine_benches:
        raise LipstreamError(
            "--word-timings measures on espeak-ng's own speech of the demo sentences; it takes "
            "no --corpus or --no-engine-benches",
            where="--word-timings",
            code="invalid_request",
        )
    path = settings.results_file(args.results, "word_timings.json")
    results = run(["lipstream", *sys.argv[1:]])
    write_results(results, path)
    print(f"wrote {path}", file=sys.stderr)
    if args.json:
        print(json.dumps(results, indent=2))
    else:
        print_summary(results)


def add_bench_parser(commands: Commands) -> None:
    bench = commands.add_parser("bench", help="benchmark every engine on held-out utterances")
    bench.add_argument("--corpus", help="corpus directory (default: the demo corpus)")
    bench.add_argument("--json", action="store_true", help="print JSON instead of a table")
    bench.add_argument(
        "--results",
        help="JSON file to write the results to (default $LIPSTREAM_HOME/bench/results.json)",
    )
    bench.add_argument(
        "--word-timings",
        action="store_true",
        help="instead: phoneme onset error of each TTS timing format against espeak-ng's own, "
        "and the real-time factor of words to spans (default file word_timings.json)",
    )
    bench.add_argument(
        "--real",
        action="store_true",
        help="instead: the demo character's models against real lips (--corpus: a capture "
        "corpus, default the checkout's GRID set; results by default in "
        "$LIPSTREAM_HOME/bench/real_faces.json)",
    )
    bench.add_argument(
        "--models",
        help="with --real: directory of the models to measure (default: the demo models)",
    )
    bench.add_argument(
        "--engines",
        help="with --real: comma-separated engines to measure (default: every model found)",
    )
    bench.add_argument(
        "--no-engine-benches",
        action="store_true",
        help="skip the engines' own benchmarks (e.g. anime-graph vs PQ-Matching)",
    )
    bench.set_defaults(run=_bench)
