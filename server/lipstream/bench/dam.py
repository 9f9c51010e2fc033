"""The ``dam`` and ``cohen-massaro`` engines' own figures for ``lipstream bench``.

Both are fitted on the train split (one BLAS thread); reported per engine: the
fit time, the modes and motion-basis components, the EM objective after each
iteration, the training RMS, and every fidelity rung with its lookahead and
the truncation error of its tail cut (the largest error on the training lines,
relative to each channel's range, see ``engines.dam.tails``), beside the error
of cutting the tail to one and to no phoneme ahead.
"""

from __future__ import annotations

import time
from typing import Any

from threadpoolctl import threadpool_limits

from ..corpus import Corpus
from ..engines.dam import CohenMassaroEngine, DamEngine


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
    return "\n".join(lines)
