"""Training orchestration: corpus in, model directories out.

``train_engine`` fits one registered engine and records how long it took;
``train_engines`` does several into one directory of model directories;
``build_demo`` generates the demo corpus, splits it, and trains every
registered engine on the train split. With ``progress``, each step prints a
status line on stderr as it starts and ends (``status.phase``) and the long
ones show their own progress bar.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Sequence
from pathlib import Path

from .config import DEMO_MODELS_DIR
from .corpus import Corpus, load_corpus, write_corpus
from .engines import engine_names, get_engine_class
from .engines.base import Model
from .status import phase, to_stderr

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
    corpus: Corpus, engines: Sequence[str], out: Path, *, progress: bool = False
) -> dict[str, Path]:
    """Train each engine into ``out/<engine>``; returns the model directories."""
    written: dict[str, Path] = {}
    report = to_stderr if progress else None
    for number, engine in enumerate(engines, 1):
        what = f"training {engine} ({number} of {len(engines)}) on the corpus"
        with phase(what, report):
            train_engine(corpus, engine, out / engine, progress=progress)
        written[engine] = out / engine
    return written


def build_demo(out: Path, *, progress: bool = False) -> dict[str, Path]:
    """Generate the demo corpus into ``out/corpus`` and train every engine into ``out/models``."""
    from .demo.generate import generate_demo_corpus

    report = to_stderr if progress else None
    corpus_dir = out / DEMO_CORPUS_DIR
    if not corpus_dir.is_dir():
        partial = out / (DEMO_CORPUS_DIR + ".partial")
        shutil.rmtree(partial, ignore_errors=True)
        with phase("generating the demo corpus (espeak-ng speaks every sentence)", report):
            write_corpus(generate_demo_corpus(progress=progress), partial)
        partial.rename(corpus_dir)
    with phase(f"loading the corpus {corpus_dir}", report):
        corpus = load_corpus(corpus_dir, progress=progress)
    train, _heldout = corpus.split()
    return train_engines(train, engine_names(), out / DEMO_MODELS_DIR, progress=progress)
