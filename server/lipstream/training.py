"""Training orchestration: corpus in, model directories out.

``train_engine`` fits one registered engine and records how long it took, and beside
it the corpus's duration model for word timings (``frontends.word_durations``);
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
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from multiprocessing.pool import Pool
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
    """Fit ``engine`` on ``corpus``; save it to ``out`` when given, with the corpus's duration
    model for word timings beside it."""
    from .frontends.word_durations import WordDurationModel

    started = time.perf_counter()
    model = get_engine_class(engine)().fit(corpus, progress=progress)
    model.manifest.metrics["train_seconds"] = round(time.perf_counter() - started, 3)
    model.manifest.metrics["train_utterances"] = len(corpus.utterances)
    if out is not None:
        model.save(out)
        WordDurationModel().fit(utterance.phones for utterance in corpus.utterances).save(out)
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


@contextmanager
def training_pool(jobs: int) -> Iterator[Pool]:
    """``jobs`` worker processes for ``train_in_parallel``, importing the engines as they
    start, so a pool opened before the corpus is written has them ready when it is."""
    import multiprocessing

    with multiprocessing.get_context("spawn").Pool(jobs, _start_worker) as pool:
        yield pool


def train_in_parallel(
    pool: Pool, jobs: int, corpus_dir: Path, engines: Sequence[str], out: Path, report: Report
) -> dict[str, Path]:
    """Train each engine on the train split of the corpus in ``corpus_dir`` into
    ``out/<engine>``, on the ``jobs`` processes of ``pool`` (``training_pool``), longest
    first, each then warming its model's kernels into numba's on-disk cache
    (``warm_kernels``) so the server's own warm-up loads them; returns the model
    directories. Identical to ``train_engines``'s models: the same code, corpus and seeds,
    another process. Each process reads the corpus itself, once. ``report`` gets a line as
    each engine starts, and its times as it ends."""
    order = sorted(engines, key=lambda name: -TRAINING_WEIGHT.get(name, 0))
    waiting = list(order)

    def begin_next() -> None:
        if waiting:  # the pool hands out the tasks in order, one per free process
            report(f"training {waiting.pop(0)} and compiling its kernels{BEGUN}")

    for _ in range(jobs):
        begin_next()
    tasks = [(engine, out / engine, corpus_dir) for engine in order]
    for engine, times in pool.imap_unordered(_train_and_warm, tasks):
        report(f"training {engine} and compiling its kernels{DONE}{times.total_s:.1f} s ({times})")
        begin_next()
    return {engine: out / engine for engine in engines}


# CPU seconds each engine of the demo character took to train and compile in its worker
# (bench/first_start.json): the longest go first.
TRAINING_WEIGHT = {
    "anime-graph": 28.6,
    "hmm": 24.4,
    "expressive-dp": 17.9,
    "dam": 16.8,
    "cohen-massaro": 4.4,
    "viseme-lerp": 1.9,
}
_train_splits: dict[Path, Corpus] = {}


@dataclass(frozen=True)
class WorkerTimes:
    """Where one engine's time went in its worker, in seconds."""

    reading_s: float
    training_s: float
    compiling_s: float
    cpu_s: float

    @property
    def total_s(self) -> float:
        return self.reading_s + self.training_s + self.compiling_s

    def __str__(self) -> str:
        reading = f"reading the corpus {self.reading_s:.1f} s, " if self.reading_s else ""
        return (
            f"{reading}training {self.training_s:.1f} s, compiling {self.compiling_s:.1f} s, "
            f"CPU {self.cpu_s:.1f} s"
        )


def _start_worker() -> None:
    """Import what training and warming need, and run BLAS on one thread: the cores are
    shared out as processes, and a second thread per process would only contend for them."""
    from threadpoolctl import threadpool_limits

    from .engines import load_model  # noqa: F401
    from .server.catalog import warm_kernels  # noqa: F401

    threadpool_limits(limits=1)


def _train_and_warm(task: tuple[str, Path, Path]) -> tuple[str, WorkerTimes]:
    """One engine trained and warmed in a worker; its CPU time is what the work would
    take alone on a busy machine."""
    from .engines import load_model
    from .server.catalog import warm_kernels

    engine, out, corpus_dir = task
    cpu_started, started = time.process_time(), time.perf_counter()
    read = started  # this process read the corpus for an earlier engine
    if corpus_dir not in _train_splits:
        _train_splits[corpus_dir] = load_corpus(corpus_dir).split()[0]
        read = time.perf_counter()
    train_engine(_train_splits[corpus_dir], engine, out)
    trained = time.perf_counter()
    warm_kernels(load_model(out))
    cpu_s = time.process_time() - cpu_started
    return engine, WorkerTimes(read - started, trained - read, time.perf_counter() - trained, cpu_s)


def training_jobs() -> int:
    """Worker processes for training: the cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def build_demo(
    out: Path, *, progress: bool = False, report: Report | None = None, jobs: int | None = None
) -> dict[str, Path]:
    """Generate the demo corpus into ``out/corpus`` and train every engine into ``out/models``,
    on ``jobs`` processes (default: one per core; 1 trains in this process). ``report``
    (default: stderr with ``progress``) gets a line per step."""
    report = report or (to_stderr if progress else None)
    bars = report is not None
    engines = engine_names()
    jobs = min(len(engines), jobs or training_jobs())
    models = out / DEMO_MODELS_DIR
    if jobs > 1:
        with training_pool(jobs) as pool:  # its processes import while the corpus is made
            corpus_dir = _demo_corpus(out, report, bars)
            with phase(f"training {len(engines)} engines on {jobs} processes", report):
                return train_in_parallel(pool, jobs, corpus_dir, engines, models, report or _silent)
    corpus_dir = _demo_corpus(out, report, bars)
    with phase(f"loading the corpus {corpus_dir}", report):
        corpus = load_corpus(corpus_dir, progress=bars)
    train, _heldout = corpus.split()
    return train_engines(train, engines, models, report=report)


def _demo_corpus(out: Path, report: Report | None, bars: bool) -> Path:
    """``out/corpus``, generated first when it is not there."""
    from .demo.generate import generate_demo_corpus

    corpus_dir = out / DEMO_CORPUS_DIR
    if not corpus_dir.is_dir():
        partial = out / (DEMO_CORPUS_DIR + ".partial")
        shutil.rmtree(partial, ignore_errors=True)
        with phase("generating the demo corpus (espeak-ng speaks every sentence)", report):
            write_corpus(generate_demo_corpus(progress=bars), partial)
        partial.rename(corpus_dir)
    return corpus_dir


def _silent(line: str) -> None:
    del line
