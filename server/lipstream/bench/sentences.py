"""How much speech a personal character needs: held-out quality against sentences recorded.

Sketch: a speaker who is not one of the demo character's three (``VISITOR``, drawn by
``Speaker.from_seed`` like them) reads the shipped sentences in a neutral voice, as someone
recording themselves would, and the demo generator speaks and performs them. The fixed
held-out set is the first ``--heldout`` of the demo corpus's held-out sentences, which the
shipped demo models never trained on; the recording session draws from the first
``--pool`` of the other sentences. For each size N and each of ``--draws`` seeded draws,
N sentences are drawn from the pool (one draw shared by every engine), each engine is
trained on them (CPU seconds on one BLAS thread, after a warm-up run that compiles the
kernels) and scored on the held-out set as ``lipstream bench`` and ``bench --real`` score:

- **RMS** over all channels and frames, the mean over the held-out utterances, and its
  ratio to ``viseme-lerp`` trained on the same draw;
- **closure rate**: the share of /p b m/ spans whose lips close, the threshold learned from
  the held-out recordings (so the same for every N);
- **aperture r**: Pearson r of the lip aperture (``jawOpen - mouthClose``) over the speech
  frames, the mean over utterances;
- **closure lag**: the mean lag (ms) of the synthesized closures behind the recorded ones.

The demo character's shipped models (trained on the full demo corpus) are scored on the
same held-out set beside them. Per engine and N, each figure is summarized as the median
and range over the draws. A real-face corpus (``--real``, such as the shipped GRID set)
draws a curve only for a speaker with enough clips; the file records how many clips each of
its speakers has.

    python -m lipstream.bench.sentences [--sizes 3 5 10 20 40] [--draws 5] [--json FILE]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ..config import load_settings
from ..corpus import Corpus, Utterance, load_corpus
from ..demo.face import DEMO_CHANNELS
from ..demo.generate import (
    DemoUtterancePlan,
    build_demo_utterance,
    heldout_indices,
    synthesizer_for,
)
from ..demo.sentences import load_sentences
from ..demo.speakers import Speaker
from ..demo.speech_batch import speak_batch
from ..engines import engine_names, load_model
from ..engines.base import Model
from ..errors import LipstreamError
from ..evaluation import lip_aperture, rms_error
from ..models import model_dirs
from ..results_file import recorded, script_command, write_results
from ..training import train_engine
from .closure import closure_lag_ms, closure_rate, learned_threshold
from .real_faces import pearson_r, speech_mask

MODULE = "lipstream.bench.sentences"
BASELINE = "viseme-lerp"
VISITOR = Speaker.from_seed("visitor", 4242, voice="en-us+m2")
EMOTION = "neutral"
SIZES = (3, 5, 10, 20, 40)
FIGURES = ("rms_error", "rms_ratio", "closure_rate", "aperture_r", "closure_lag_ms", "train_cpu_s")


@dataclass(frozen=True)
class Session:
    """The visitor's recordings: the pool a session draws from, and the held-out set."""

    pool: list[Utterance]
    heldout: Corpus


@dataclass
class Score:
    """One model's figures on the held-out set."""

    rms_error: float
    closure_rate: float | None
    aperture_r: float | None
    closure_lag_ms: float | None


@dataclass
class Run:
    """One engine trained on one draw of ``n`` sentences, and its figures."""

    engine: str
    n: int
    draw: int
    train_cpu_s: float | None
    rms_error: float | None = None
    rms_ratio: float | None = None
    closure_rate: float | None = None
    aperture_r: float | None = None
    closure_lag_ms: float | None = None
    error: str | None = None


def sentence_split(n_sentences: int, pool: int, heldout: int) -> tuple[list[int], list[int]]:
    """(pool, held-out) sentence indices: the first ``heldout`` of the demo corpus's
    held-out sentences, and the first ``pool`` of the others."""
    held = heldout_indices(n_sentences)
    kept = set(held)
    others = [index for index in range(n_sentences) if index not in kept]
    if pool > len(others) or heldout > len(held) or min(pool, heldout) < 1:
        raise LipstreamError(
            f"pool must be in [1, {len(others)}] and held-out in [1, {len(held)}], "
            f"got {pool} and {heldout}",
            where="sentences",
            code="invalid_request",
        )
    return others[:pool], held[:heldout]


def draw_sentences(pool: int, n: int, seed: int, draw: int) -> list[int]:
    """The positions in the pool of draw ``draw`` of ``n`` sentences, sorted; the same for
    the same (pool, n, seed, draw)."""
    if not 1 <= n <= pool:
        raise LipstreamError(
            f"cannot draw {n} sentences from a pool of {pool}",
            where="sizes",
            code="invalid_request",
        )
    rng = np.random.default_rng([seed, pool, n, draw])
    return sorted(int(index) for index in rng.choice(pool, size=n, replace=False))


def _plans(indices: Sequence[int], sentences: Sequence[str]) -> list[DemoUtterancePlan]:
    return [
        DemoUtterancePlan(index, f"visitor_{index + 1:04d}", sentences[index], EMOTION, VISITOR)
        for index in indices
    ]


def record_session(pool: int, heldout: int, fps: float) -> Session:
    """The visitor reading the pool and the held-out sentences (see the module sketch)."""
    sentences = load_sentences()
    pool_indices, heldout_indices_ = sentence_split(len(sentences), pool, heldout)
    plans = _plans([*pool_indices, *heldout_indices_], sentences)
    speech = speak_batch([(synthesizer_for(p.speaker, p.emotion), p.sentence) for p in plans])
    utterances = [build_demo_utterance(p, spoken, fps) for p, spoken in zip(plans, speech)]
    held = Corpus("visitor-heldout", fps, DEMO_CHANNELS, utterances[len(pool_indices) :])
    return Session(utterances[: len(pool_indices)], held)


def score(model: Model, heldout: Corpus, threshold: float | None) -> Score:
    """``model``'s figures on ``heldout``, synthesized from the recorded phones."""
    predictions = [
        model.synthesize(u.phones, fps=heldout.fps, audio=None, emotion=u.emotion).frames
        for u in heldout.utterances
    ]
    errors = [rms_error(p, u.frames) for p, u in zip(predictions, heldout.utterances)]
    correlations = []
    for predicted, utterance in zip(predictions, heldout.utterances):
        n = min(len(predicted), utterance.n_frames)
        mine = lip_aperture(predicted[:n], model.channels)
        real = lip_aperture(utterance.frames[:n], heldout.channels)
        if mine is not None and real is not None:
            speech = speech_mask(utterance.phones, heldout.fps, n)
            correlations.append(pearson_r(mine[speech], real[speech]))
    known = [r for r in correlations if r is not None]
    return Score(
        rms_error=float(np.mean(errors)),
        closure_rate=closure_rate(predictions, heldout, threshold),
        aperture_r=float(np.mean(known)) if known else None,
        closure_lag_ms=closure_lag_ms(predictions, heldout),
    )


def _train_and_score(
    corpus: Corpus, engine: str, heldout: Corpus, threshold: float | None
) -> tuple[float | None, Score | str]:
    started = time.process_time()
    try:
        model = train_engine(corpus, engine)
    except LipstreamError as error:
        return None, f"{type(error).__name__}: {error}"
    return time.process_time() - started, score(model, heldout, threshold)


def _warm_up(session: Session, engines: Sequence[str]) -> None:
    """Train each engine once on two sentences, so no timing includes compiling kernels."""
    corpus = Corpus("visitor", session.heldout.fps, DEMO_CHANNELS, session.pool[:2])
    for engine in engines:
        try:
            train_engine(corpus, engine)
        except LipstreamError:
            pass


def curve_runs(
    session: Session, sizes: Sequence[int], draws: int, engines: Sequence[str], seed: int
) -> list[Run]:
    """Every engine trained on every draw of every size, scored on the held-out set."""
    threshold = learned_threshold(session.heldout)
    runs: list[Run] = []
    for n in sizes:
        for draw in range(draws):
            chosen = [session.pool[i] for i in draw_sentences(len(session.pool), n, seed, draw)]
            corpus = Corpus("visitor", session.heldout.fps, DEMO_CHANNELS, chosen)
            batch = []
            for engine in engines:
                cpu_s, figures = _train_and_score(corpus, engine, session.heldout, threshold)
                run = Run(engine, n, draw, None if cpu_s is None else round(cpu_s, 3))
                if isinstance(figures, str):
                    run.error = figures
                else:
                    for key, value in asdict(figures).items():
                        setattr(run, key, value)
                batch.append(run)
            runs.extend(_with_baseline_ratio(batch))
            print(f"N={n} draw {draw}: trained and scored", file=sys.stderr, flush=True)
    return runs


def _with_baseline_ratio(batch: list[Run]) -> list[Run]:
    base = next((run for run in batch if run.engine == BASELINE), None)
    for run in batch:
        if base is not None and base.rms_error and run.rms_error is not None:
            run.rms_ratio = run.rms_error / base.rms_error
    return batch


def spread(values: Sequence[float | None]) -> dict[str, float] | None:
    """Median, lowest and highest of the known ``values``; None when none is known."""
    known = [float(value) for value in values if value is not None]
    if not known:
        return None
    return {"median": statistics.median(known), "min": min(known), "max": max(known)}


def summarize(runs: Sequence[Run]) -> list[dict[str, Any]]:
    """Per engine and size: the draws trained, those that failed, and each figure's spread."""
    keys = sorted({(run.engine, run.n) for run in runs}, key=lambda key: (key[1], key[0]))
    rows = []
    for engine, n in keys:
        mine = [run for run in runs if run.engine == engine and run.n == n]
        row: dict[str, Any] = {
            "engine": engine,
            "n": n,
            "draws": len(mine),
            "failed": sum(run.error is not None for run in mine),
        }
        row.update({figure: spread([getattr(run, figure) for run in mine]) for figure in FIGURES})
        rows.append(row)
    return rows


def demo_scores(models_dir: Path | None, heldout: Corpus) -> list[dict[str, Any]]:
    """The shipped demo models under ``models_dir`` scored on ``heldout`` (none without
    one), each with its RMS ratio to the demo ``viseme-lerp``."""
    if models_dir is None or not models_dir.is_dir():
        return []
    threshold = learned_threshold(heldout)
    rows = []
    for directory in model_dirs(models_dir):
        model = load_model(directory)
        rows.append(
            {
                "engine": model.manifest.engine,
                "character": model.manifest.name,
                "train_utterances": model.manifest.metrics.get("train_utterances"),
                "corpus_digest": model.manifest.corpus_digest,
                **asdict(score(model, heldout, threshold)),
            }
        )
    base = next((row for row in rows if row["engine"] == BASELINE), None)
    for row in rows:
        row["rms_ratio"] = row["rms_error"] / base["rms_error"] if base else None
    return rows


def real_speakers(corpus_dir: Path | None, smallest: int) -> dict[str, Any] | None:
    """How many clips each speaker of a real-face corpus has, and whether any has enough
    for a curve (the smallest size needs that many training clips plus one held out)."""
    if corpus_dir is None:
        return None
    corpus = load_corpus(corpus_dir)
    counts = Counter(u.speaker or u.stem for u in corpus.utterances)
    return {
        "corpus": corpus.name,
        "digest": corpus.digest(),
        "clips": len(corpus.utterances),
        "speakers": len(counts),
        "most_clips_of_one_speaker": max(counts.values(), default=0),
        "curve_possible": max(counts.values(), default=0) > smallest,
    }


def run_sentences_bench(
    sizes: Sequence[int],
    draws: int,
    engines: Sequence[str],
    *,
    seed: int = 0,
    pool: int = 60,
    heldout: int = 12,
    fps: float = 120.0,
    models_dir: Path | None = None,
    real_corpus: Path | None = None,
) -> dict[str, Any]:
    """The curve of ``engines`` (``viseme-lerp`` always among them) over ``sizes``."""
    names = [BASELINE, *(name for name in engines if name != BASELINE)]
    session = record_session(pool, heldout, fps)
    with threadpool_limits(limits=1):
        _warm_up(session, names)
        runs = curve_runs(session, sizes, draws, names, seed)
        demo = demo_scores(models_dir, session.heldout)
    threshold = learned_threshold(session.heldout)
    recorded_rate = closure_rate(
        [u.frames for u in session.heldout.utterances], session.heldout, threshold
    )
    return {
        "speaker": asdict(VISITOR),
        "emotion": EMOTION,
        "fps": fps,
        "seed": seed,
        "sizes": list(sizes),
        "draws": draws,
        "engines": names,
        "pool_stems": [u.stem for u in session.pool],
        "drawn": {
            str(n): [
                [session.pool[i].stem for i in draw_sentences(pool, n, seed, draw)]
                for draw in range(draws)
            ]
            for n in sizes
        },
        "heldout": {
            "stems": list(session.heldout.stems),
            "digest": session.heldout.digest(),
            "closure_threshold": threshold,
            "recorded_closure_rate": recorded_rate,
        },
        "curve": summarize(runs),
        "demo": demo,
        "real_faces": real_speakers(real_corpus, min(sizes)),
        "runs": [asdict(run) for run in runs],
    }


def _fmt(cell: dict[str, float] | None, pattern: str) -> str:
    if cell is None:
        return "n/a"
    return (
        f"{format(cell['median'], pattern)} "
        f"[{format(cell['min'], pattern)}, {format(cell['max'], pattern)}]"
    )


def format_curve(results: dict[str, Any]) -> str:
    """A plain-text table of the curve, then the demo models' row per engine."""
    header = f"{'engine':<15}{'N':>4}  {'RMS':<26}{'RMS/base':<24}{'aperture r':<24}{'train cpu s'}"
    lines = [header, "-" * len(header)]
    for row in results["curve"]:
        lines.append(
            f"{row['engine']:<15}{row['n']:>4}  {_fmt(row['rms_error'], '.4f'):<26}"
            f"{_fmt(row['rms_ratio'], '.3f'):<24}{_fmt(row['aperture_r'], '.3f'):<24}"
            f"{_fmt(row['train_cpu_s'], '.2f')}"
        )
    for row in results["demo"]:
        lines.append(
            f"{'demo ' + row['engine']:<19}  {row['rms_error']:<26.4f}"
            f"{row['rms_ratio'] or 0:<24.3f}{row['aperture_r'] or 0:.3f}"
        )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog=f"python -m {MODULE}", description=__doc__.splitlines()[0]
    )
    parser.add_argument(
        "--sizes", type=int, nargs="+", default=list(SIZES), help="sentences per draw"
    )
    parser.add_argument("--draws", type=int, default=5, help="seeded draws per size (default 5)")
    parser.add_argument("--engines", nargs="+", default=engine_names(), help="default: all")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--pool", type=int, default=60, help="sentences a session draws from")
    parser.add_argument("--heldout", type=int, default=12, help="held-out sentences")
    parser.add_argument("--fps", type=float, default=120.0)
    parser.add_argument("--models", type=Path, help="demo models (default: the demo's)")
    parser.add_argument("--real", type=Path, help="a real-face corpus to count speakers of")
    parser.add_argument(
        "--json", help="results file (default $LIPSTREAM_HOME/bench/sentences_curve.json)"
    )
    args = parser.parse_args(argv)
    settings = load_settings()
    started = recorded(script_command(MODULE, argv))
    results = started | run_sentences_bench(
        args.sizes,
        args.draws,
        args.engines,
        seed=args.seed,
        pool=args.pool,
        heldout=args.heldout,
        fps=args.fps,
        models_dir=args.models or settings.demo_models_dir,
        real_corpus=args.real,
    )
    path = settings.results_file(args.json, "sentences_curve.json")
    write_results(results, path)
    print(format_curve(results))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
