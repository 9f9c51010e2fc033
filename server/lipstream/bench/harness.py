"""``lipstream bench``: every engine against ``viseme-lerp`` on held-out utterances.

For each registered engine: train on the train split (timed), synthesize each
held-out utterance from its recorded phone spans, and compare with the
recording: RMS error over all channels, and the share of /p b m/ spans whose
lips close (``lipstream.evaluation``), and the RMS of each emotion's lines.
The lip timing is the mean lag of the synthesized /p b m/ closures behind the
recorded ones (``closure.closure_lag_ms``). Speed is the synthesis time per
phoneme and the real-time factor (synthesis time / utterance duration) at 60
fps. Each figure is also given as a ratio to the baseline. Then every rung of
every engine's ladder is measured the same way (``rungs``). Requests carry the
utterance's emotion (and its audio, for engines that use audio), as a
chat-avatar backend's requests would.
Everything runs on one BLAS thread.

Engines may add their own benchmark (``ENGINE_BENCHES``, lazy import strings
of a ``run(corpus) -> dict`` and a ``format(dict) -> str``), such as the
anime-graph search comparison of Cao et al.'s Tables 1 and 2.
"""

from __future__ import annotations

import importlib
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ..corpus import Corpus
from ..engines import engine_names
from ..engines.base import Model
from ..evaluation import rms_error
from ..results_file import recorded
from ..training import train_engine
from .closure import closure_lag_ms, closure_rate, learned_threshold
from .rungs import RungRow, rung_rows

BASELINE = "viseme-lerp"
SPEED_FPS = 60.0
ENGINE_BENCHES: dict[str, tuple[str, str]] = {
    "anime-graph": (
        "lipstream.bench.anime_graph:run_anime_graph_bench",
        "lipstream.bench.anime_graph:format_anime_graph_bench",
    ),
    "dam": ("lipstream.bench.dam:run_dam_bench", "lipstream.bench.dam:format_dam_bench"),
    "hmm": ("lipstream.bench.hmm:run_hmm_bench", "lipstream.bench.hmm:format_hmm_bench"),
    "expressive-dp": (
        "lipstream.bench.expressive_dp:run_expressive_dp_bench",
        "lipstream.bench.expressive_dp:format_expressive_dp_bench",
    ),
}


@dataclass
class EngineRow:
    """One engine's figures; ``*_ratio`` fields are relative to the baseline."""

    engine: str
    train_seconds: float
    ms_per_phoneme: float
    real_time_factor: float
    rms_error: float
    closure_rate: float | None
    rms_by_emotion: dict[str, float] = field(default_factory=dict)
    closure_lag_ms: float | None = None
    train_ratio: float = 1.0
    speed_ratio: float = 1.0
    rms_ratio: float = 1.0
    closure_ratio: float | None = 1.0


def _time_synthesis(model: Model, heldout: Corpus) -> tuple[float, float]:
    """(ms per phoneme, real-time factor) at ``SPEED_FPS``."""
    elapsed = 0.0
    for utterance in heldout.utterances:
        audio = utterance.audio if model.uses_audio else None
        started = time.perf_counter()
        model.synthesize(utterance.phones, fps=SPEED_FPS, audio=audio, emotion=utterance.emotion)
        elapsed += time.perf_counter() - started
    phonemes = sum(len(u.phones) for u in heldout.utterances)
    duration = sum(u.phones[-1].end for u in heldout.utterances)
    return 1000.0 * elapsed / phonemes, elapsed / duration


def bench_engine(model: Model, heldout: Corpus, threshold: float | None) -> EngineRow:
    predictions = []
    for utterance in heldout.utterances:
        audio = utterance.audio if model.uses_audio else None
        result = model.synthesize(
            utterance.phones, fps=heldout.fps, audio=audio, emotion=utterance.emotion
        )
        predictions.append(result.frames)
    errors = [rms_error(p, u.frames) for p, u in zip(predictions, heldout.utterances)]
    ms_per_phoneme, rtf = _time_synthesis(model, heldout)
    return EngineRow(
        engine=model.manifest.engine,
        train_seconds=float(model.manifest.metrics["train_seconds"]),
        ms_per_phoneme=ms_per_phoneme,
        real_time_factor=rtf,
        rms_error=float(np.mean(errors)),
        closure_rate=closure_rate(predictions, heldout, threshold),
        rms_by_emotion=_by_emotion(errors, heldout),
        closure_lag_ms=closure_lag_ms(predictions, heldout),
    )


def _by_emotion(errors: list[float], heldout: Corpus) -> dict[str, float]:
    """The mean RMS of the held-out lines of each emotion."""
    grouped: dict[str, list[float]] = {}
    for error, utterance in zip(errors, heldout.utterances, strict=True):
        grouped.setdefault(utterance.emotion, []).append(error)
    return {emotion: float(np.mean(values)) for emotion, values in sorted(grouped.items())}


def _ratio(value: float | None, baseline: float | None) -> float | None:
    if value is None or not baseline:
        return None
    return value / baseline


def _with_ratios(rows: list[EngineRow]) -> list[EngineRow]:
    base = next(row for row in rows if row.engine == BASELINE)
    for row in rows:
        row.train_ratio = _ratio(row.train_seconds, base.train_seconds) or 0.0
        row.speed_ratio = _ratio(row.ms_per_phoneme, base.ms_per_phoneme) or 0.0
        row.rms_ratio = _ratio(row.rms_error, base.rms_error) or 0.0
        row.closure_ratio = _ratio(row.closure_rate, base.closure_rate)
    return rows


def _recorded_reference(heldout: Corpus, threshold: float | None) -> dict[str, Any]:
    rate = closure_rate([u.frames for u in heldout.utterances], heldout, threshold)
    return {"closure_rate": rate, "closure_threshold": threshold}


def _resolve(target: str) -> Any:
    module, _, attribute = target.partition(":")
    return getattr(importlib.import_module(module), attribute)


def run_engine_benches(corpus: Corpus, names: list[str]) -> dict[str, Any]:
    """The engines' own benchmarks, for those of ``names`` that have one."""
    return {
        name: _resolve(ENGINE_BENCHES[name][0])(corpus) for name in names if name in ENGINE_BENCHES
    }


def format_engine_benches(results: dict[str, Any]) -> str:
    return "\n\n".join(
        f"== {name} ==\n" + _resolve(ENGINE_BENCHES[name][1])(figures)
        for name, figures in results.get("engine_benches", {}).items()
    )


def run_bench(
    corpus: Corpus,
    engines: list[str] | None = None,
    *,
    engine_benches: bool = True,
    command: str = "lipstream bench",
) -> dict[str, Any]:
    """Benchmark ``engines`` (default: all registered) on ``corpus``'s held-out split;
    ``command`` is the command line recorded in the results."""
    train, heldout = corpus.split()
    threshold = learned_threshold(train)
    names = engines or engine_names()
    if BASELINE not in names:
        names = [BASELINE, *names]
    rungs: list[RungRow] = []
    with threadpool_limits(limits=1):
        models = [train_engine(train, name) for name in names]
        rows = _with_ratios([bench_engine(model, heldout, threshold) for model in models])
        for model in models:
            rungs.extend(rung_rows(model, heldout, threshold))
    extra = run_engine_benches(corpus, names) if engine_benches else {}
    return {
        **recorded(command),
        "corpus": {
            "name": corpus.name,
            "digest": corpus.digest(),
            "fps": corpus.fps,
            "train_utterances": len(train.utterances),
            "heldout_utterances": len(heldout.utterances),
        },
        "recorded": _recorded_reference(heldout, threshold),
        "engines": [asdict(row) for row in rows],
        "rungs": [asdict(row) for row in rungs],
        "engine_benches": extra,
    }


def _fmt(value: float | None, pattern: str) -> str:
    return "n/a" if value is None else format(value, pattern)


def format_table(results: dict[str, Any]) -> str:
    header = (
        f"{'engine':<16}{'train s':>9}{'ms/phon':>9}{'RTF':>9}{'RMS':>9}"
        f"{'closure':>9}{'RMS÷base':>10}{'speed÷base':>12}{'close÷base':>12}{'lip lag ms':>12}"
    )
    lines = [header, "-" * len(header)]
    for row in results["engines"]:
        lines.append(
            f"{row['engine']:<16}{row['train_seconds']:>9.2f}{row['ms_per_phoneme']:>9.3f}"
            f"{row['real_time_factor']:>9.5f}{row['rms_error']:>9.4f}"
            f"{_fmt(row['closure_rate'], '.1%'):>9}{row['rms_ratio']:>10.3f}"
            f"{row['speed_ratio']:>12.3f}{_fmt(row['closure_ratio'], '.3f'):>12}"
            f"{_fmt(row.get('closure_lag_ms'), '.1f'):>12}"
        )
    reference = results["recorded"]
    lines.append(f"{'recorded':<16}{'':>45}{_fmt(reference['closure_rate'], '.1%'):>9}")
    return "\n".join(lines)
