"""Training orchestration: corpus in, model directories out.

``train_engine`` fits one registered engine and records how long it took;
``train_engines`` does several into one directory of model directories;
``build_demo`` generates the demo corpus, splits it, and trains every
registered engine on the train split. With ``progress``, each step prints a
status line on stderr as it starts and ends (``status.phase``) and the long
ones show their own progress bar.
"""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Sequence
from pathlib import Path

from .config import DEMO_MODELS_DIR
from .corpus import Corpus, load_corpus, write_corpus
from .engines import engine_names, get_engine_class
from .engines.base import Model
from .status import BEGUN, DONE, Report, phase, to_stderr

DEMO_CORPUS_DIR = "corpus"


def train_engine(
    corpus: Corpus, engine: str, out: Path | None = None, *, progress: bool = False
) -> Model:
    """Fit ``engine`` on ``corpus``; save it to ``out`` when given."""
    started = time.perf_counter()
    model = get_engine_class(engine)().fit(corpus, progress=progress)
    model.manifest.metrics["train_seconds"] = round(time.perf_counter() - started, 3)
    model.manifest.metrics["train_utterances"] = len(corpus.utterances)
    if out is not None:
        model.save(out)
    return model


def resolve_engines(selection: str) -> list[str]:
    """``all`` or one registered name."""
    if selection == "all":
        return engine_names()
    get_engine_class(selection)
    return [selection]


def train_engines(
    corpus: Corpus,
    engines: Sequence[str],
    out: Path,
    *,
    progress: bool = False,
    report: Report | None = None,
) -> dict[str, Path]:
    """Train each engine into ``out/<engine>``, one after another; returns the model
    directories. ``report`` (default: stderr with ``progress``) gets a line per engine."""
    written: dict[str, Path] = {}
    report = report or (to_stderr if progress else None)
    for number, engine in enumerate(engines, 1):
        what = f"training {engine} ({number} of {len(engines)}) on the corpus"
        with phase(what, report):
            train_engine(corpus, engine, out / engine, progress=report is not None)
        written[engine] = out / engine
    return written


def train_in_parallel(
    corpus: Corpus, engines: Sequence[str], out: Path, report: Report, jobs: int
) -> dict[str, Path]:
    """Train each engine into ``out/<engine>`` in ``jobs`` worker processes, longest first,
    each then warming its model's kernels into numba's on-disk cache (``warm_kernels``) so
    the server's own warm-up loads them; returns the model directories. Identical to
    ``train_engines``'s models: the same code and seeds, another process. ``report`` gets
    a line as each engine starts, and its training and compiling times as it ends."""
    import multiprocessing

    order = sorted(engines, key=lambda name: -TRAINING_WEIGHT.get(name, 0))
    waiting = list(order)

    def begin_next() -> None:
        if waiting:  # the pool hands out the tasks in order, one per free process
            report(f"training {waiting.pop(0)} and compiling its kernels{BEGUN}")

    for _ in range(jobs):
        begin_next()
    context = multiprocessing.get_context("spawn")
    with context.Pool(jobs, _start_worker, (corpus,)) as pool:
        tasks = [(engine, out / engine) for engine in order]
        for engine, train_s, compile_s, cpu_s in pool.imap_unordered(_train_and_warm, tasks):
            report(
                f"training {engine} and compiling its kernels{DONE}{train_s + compile_s:.1f} s "
                f"(training {train_s:.1f} s, compiling {compile_s:.1f} s, CPU {cpu_s:.1f} s)"
            )
            begin_next()
    return {engine: out / engine for engine in engines}


# CPU seconds each engine of the demo character took to train and compile in its worker
# (bench/first_start.json): the longest go first.
TRAINING_WEIGHT = {
    "anime-graph": 38.8,
    "hmm": 24.6,
    "dam": 22.6,
    "expressive-dp": 21.5,
    "cohen-massaro": 7.0,
    "viseme-lerp": 2.3,
}
_corpus: list[Corpus] = []


def _start_worker(corpus: Corpus) -> None:
    """Keep the corpus, and run BLAS on one thread: the cores are shared out as processes,
    and a second thread per process would only contend for them."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1)
    _corpus[:] = [corpus]


def _train_and_warm(task: tuple[str, Path]) -> tuple[str, float, float, float]:
    """(engine, training s, compiling s, CPU s of both) of one engine trained and warmed in a
    worker; on a busy machine the CPU time is what the two would take alone."""
    from .engines import load_model
    from .server.catalog import warm_kernels

    engine, out = task
    started, cpu_started = time.perf_counter(), time.process_time()
    train_engine(_corpus[0], engine, out)
    trained = time.perf_counter()
    warm_kernels(load_model(out))
    cpu_s = time.process_time() - cpu_started
    return engine, trained - started, time.perf_counter() - trained, cpu_s


def training_jobs() -> int:
    """Worker processes for training: the cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def build_demo(
    out: Path, *, progress: bool = False, report: Report | None = None, jobs: int | None = None
) -> dict[str, Path]:
    """Generate the demo corpus into ``out/corpus`` and train every engine into ``out/models``,
    on ``jobs`` processes (default: one per core; 1 trains in this process). ``report``
    (default: stderr with ``progress``) gets a line per step."""
    from .demo.generate import generate_demo_corpus

    report = report or (to_stderr if progress else None)
    bars = report is not None
    corpus_dir = out / DEMO_CORPUS_DIR
    if not corpus_dir.is_dir():
        partial = out / (DEMO_CORPUS_DIR + ".partial")
        shutil.rmtree(partial, ignore_errors=True)
        with phase("generating the demo corpus (espeak-ng speaks every sentence)", report):
            write_corpus(generate_demo_corpus(progress=bars), partial)
        partial.rename(corpus_dir)
    with phase(f"loading the corpus {corpus_dir}", report):
        corpus = load_corpus(corpus_dir, progress=bars)
    train, _heldout = corpus.split()
    engines = engine_names()
    jobs = min(len(engines), jobs or training_jobs())
    models = out / DEMO_MODELS_DIR
    if jobs > 1:
        with phase(f"training {len(engines)} engines on {jobs} processes", report):
            return train_in_parallel(train, engines, models, report or _silent, jobs)
    return train_engines(train, engines, models, report=report)


def _silent(line: str) -> None:
    del line
