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
"""

from __future__ import annotations

import statistics
import time
from typing import Any

from threadpoolctl import threadpool_limits

from ..corpus import Corpus
from ..engines.base import Model
from ..engines.dam import CohenMassaroEngine, DamEngine
from ..loadtest.clips import synthetic_clip

SENTENCE_PHONEMES = 40
SPEED_FPS = 60.0
SPEED_REPEATS = 200
PAPER_MS_PER_PHONEME = 0.8


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
    return "\n".join(lines)
