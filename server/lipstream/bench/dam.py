"""The ``dam`` and ``cohen-massaro`` engines' own figures for ``lipstream bench``.

Both are fitted on the train split (one BLAS thread); reported per engine: the
fit time, the modes and motion-basis components, the EM objective after each
iteration, the training RMS, and every fidelity rung with its lookahead and
the truncation error of its tail cut (the largest error on the training lines,
relative to each channel's range, see ``engines.dam.tails``), beside the error
of cutting the tail to one and to no phoneme ahead, and the synthesis time per
phoneme of a 40-phoneme sentence at 60 fps (Lin et al. report 0.8 ms): the
median over repeated whole syntheses (``synthesize``: validation, mode search,
Eq. 2, the basis) of the CPU time of this process, which a busy machine
inflates far less than wall time, beside the wall time of the same runs.

The causal rungs are measured as a server at lead 0 drives them: each span of
``sentence()`` fed alone at 60 fps and its frames taken at once (``feed`` then
``frames``, one call per ``phonemes`` message), timed by the calling thread's
CPU clock (``time.thread_time``, which neither other threads nor other
processes inflate); reported are the median and 90th percentile over every
call of ``CALL_SESSIONS`` sessions after one warm-up session. On its own, for
the demo character's models (``lipstream build-demo`` makes them):

    python -m lipstream.bench.dam
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from typing import Any

from threadpoolctl import threadpool_limits

from ..config import demo_model_path
from ..corpus import Corpus
from ..engines.base import Model, Rung
from ..engines.dam import CohenMassaroEngine, CohenMassaroModel, DamEngine, DamModel
from ..loadtest.clips import synthetic_clip
from ..loadtest.stats import percentile

SENTENCE_PHONEMES = 40
SPEED_FPS = 60.0
SPEED_REPEATS = 200
PAPER_MS_PER_PHONEME = 0.8
CALL_SESSIONS = 50


def sentence(phonemes: int = SENTENCE_PHONEMES, seed: int = 0) -> list[tuple[str, float, float]]:
    """The first ``phonemes`` spans of a seeded speech-like clip (``loadtest.clips``)."""
    return synthetic_clip(0.2 * phonemes, seed=seed)[:phonemes]


def synthesis_speed(model: Model, repeats: int = SPEED_REPEATS) -> dict[str, Any]:
    """Per phoneme, the median CPU and wall time of synthesizing ``sentence()`` at 60 fps."""
    spans = sentence()
    model.synthesize(spans, fps=SPEED_FPS)  # compiled kernels load on the first call
    cpu, wall = [], []
    for _ in range(repeats):
        cpu_began, wall_began = time.process_time(), time.perf_counter()
        model.synthesize(spans, fps=SPEED_FPS)
        cpu.append(time.process_time() - cpu_began)
        wall.append(time.perf_counter() - wall_began)
    return {
        "phonemes": len(spans),
        "fps": SPEED_FPS,
        "repeats": repeats,
        "cpu_ms_per_phoneme": 1000.0 * statistics.median(cpu) / len(spans),
        "wall_ms_per_phoneme": 1000.0 * statistics.median(wall) / len(spans),
        "paper_ms_per_phoneme": PAPER_MS_PER_PHONEME,
    }


def causal_call_speed(model: Model, rung: Rung, sessions: int = CALL_SESSIONS) -> dict[str, Any]:
    """The CPU time (ms) of one streaming call on a causal ``rung``: ``sessions`` sessions of
    ``sentence()`` at 60 fps, each span fed alone and its frames taken at once."""
    spans = sentence()
    calls: list[float] = []
    for session in range(sessions + 1):  # the first loads the compiled kernels
        synthesizer = model.start(fps=SPEED_FPS, **rung.options)
        for span in spans:
            began = time.thread_time()
            synthesizer.feed([span])
            synthesizer.frames()
            if session:
                calls.append(1000.0 * (time.thread_time() - began))
        synthesizer.finish()
    return {
        "rung": rung.name,
        "lead_ms": rung.options["lead_ms"],
        "calls": len(calls),
        "cpu_ms_median": statistics.median(calls),
        "cpu_ms_p90": percentile(sorted(calls), 90.0),
    }


def causal_call_speeds(model: Model, sessions: int = CALL_SESSIONS) -> list[dict[str, Any]]:
    """``causal_call_speed`` of every causal rung of ``model``'s ladder."""
    ladder = model.fidelity_ladder()
    return [
        causal_call_speed(model, rung, sessions) for rung in ladder if "lead_ms" in rung.options
    ]


def run_dam_bench(corpus: Corpus) -> dict[str, Any]:
    train, _ = corpus.split()
    results: dict[str, Any] = {}
    with threadpool_limits(limits=1):
        for engine in (DamEngine(), CohenMassaroEngine()):
            started = time.perf_counter()
            model = engine.fit(train)
            elapsed = time.perf_counter() - started
            metrics = model.manifest.metrics
            errors = metrics["truncation_error"]
            results[engine.name] = {
                "fit_s": elapsed,
                "modes": metrics["modes"],
                "basis_components": metrics["basis_components"],
                "em_objective": metrics["em_objective"],
                "fit_rms": metrics["fit_rms"],
                "tail": model.tail,
                "rungs": [
                    {
                        "name": rung.name,
                        "lookahead_phonemes": rung.lookahead.phonemes,
                        # causal rungs give up anticipation altogether: their cost is the
                        # rung quality table's (``rungs``), not a tail cut's
                        "truncation_error": errors.get(f"tail_ahead={rung.options['tail_ahead']}")
                        if "tail_ahead" in rung.options
                        else None,
                    }
                    for rung in model.fidelity_ladder()
                ],
                "cut_tail_errors": {
                    name: value for name, value in errors.items() if name != "tail"
                },
                "synthesis": synthesis_speed(model),
                "causal_calls": causal_call_speeds(model),
            }
    return results


def format_dam_bench(results: dict[str, Any]) -> str:
    lines = []
    for name, figures in results.items():
        lines.append(
            f"{name}: fit {figures['fit_s']:.2f} s, {figures['modes']} modes, "
            f"{figures['basis_components']} components, tail {figures['tail']} phonemes, "
            f"training RMS {figures['fit_rms']:.4f}"
        )
        for rung in figures["rungs"]:
            error = rung["truncation_error"]
            cut = "causal" if error is None else f"{error:.2%} of a channel's range"
            lines.append(
                f"  rung {rung['name']:<11} lookahead {rung['lookahead_phonemes']} phonemes, "
                f"truncation error {cut}"
            )
        cuts = ", ".join(f"{k}: {v:.1%}" for k, v in figures["cut_tail_errors"].items())
        lines.append(f"  tail cuts: {cuts}")
        speed = figures["synthesis"]
        lines.append(
            f"  synthesis of a {speed['phonemes']}-phoneme sentence at {speed['fps']:g} fps: "
            f"{speed['cpu_ms_per_phoneme']:.4f} ms CPU per phoneme "
            f"({speed['wall_ms_per_phoneme']:.4f} ms wall; the paper: "
            f"{speed['paper_ms_per_phoneme']:g} ms)"
        )
        lines.extend(_format_calls(figures["causal_calls"]))
    return "\n".join(lines)


def _format_calls(calls: list[dict[str, Any]]) -> list[str]:
    return [
        f"  rung {call['rung']} fed a phoneme at a time at {SPEED_FPS:g} fps: "
        f"{call['cpu_ms_median']:.4f} ms CPU per call (median of {call['calls']}; "
        f"p90 {call['cpu_ms_p90']:.4f} ms)"
        for call in calls
    ]


def main(argv: list[str] | None = None) -> int:
    """The causal rungs' call figures and the whole-sentence speed of the demo character's
    ``dam`` and ``cohen-massaro`` models, as JSON, then as text."""
    parser = argparse.ArgumentParser(prog="python -m lipstream.bench.dam", description=__doc__)
    parser.add_argument("--sessions", type=int, default=CALL_SESSIONS, help="sessions per rung")
    args = parser.parse_args(argv)
    report: dict[str, Any] = {}
    with threadpool_limits(limits=1):
        for name, model_class in (("dam", DamModel), ("cohen-massaro", CohenMassaroModel)):
            model = model_class.load(demo_model_path(name))
            report[name] = {
                "causal_calls": causal_call_speeds(model, args.sessions),
                "synthesis": synthesis_speed(model),
            }
    print(json.dumps(report, indent=2))
    for name, figures in report.items():
        print(name)
        print("\n".join(_format_calls(figures["causal_calls"])))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
