"""The ``expressive-dp`` engine's own figures for ``lipstream bench``.

Fitted on the train split (one BLAS thread). Reported: the fit time, nodes,
basis and α; the paper's Table V lengths (14, 24, 53, 63 phonemes, cut from
the held-out lines joined end to end, spoken neutral) searched on the whole
database by the fast search (median and least CPU time of ``REPEATS``, one
thread: the machine may be shared) and by exact DP (Alg. 1). Exact DP is Θ(N²·T): it is
timed over ``EXACT_LAYERS`` layers of one sentence, scaled to T − 1
transitions, and on those layers its optimum is compared with the fast
search's. Then each fixed lag
against the full search on the held-out lines (how many lines and nodes
differ, the mean and largest relative cost gap, the lag's lookahead at the
corpus's median phoneme and its time per phoneme); the held-out RMS per
emotion with the correct emotion modifiers and with all neutral ones, beside
``viseme-lerp``; and the time of a phoneme-map pick.

``python -m lipstream.bench.expressive_dp`` fits the model on the demo corpus (built
if missing) and prints the Table V rows alone (fast search only; about a minute).
"""

from __future__ import annotations

import statistics
import time
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ..corpus import Corpus
from ..engines.base import fill_gaps
from ..engines.expressive_dp import ExpressiveDpEngine, ExpressiveDpModel
from ..engines.expressive_dp.search import LayerSpec, search
from ..engines.viseme_lerp import VisemeLerpEngine
from ..evaluation import rms_error
from ..phonemes import PHONEME_INDEX
from ..timeline import EMOTION_INDEX, PhonemeSpan

TABLE_V = {14: 221.391, 24: 333.171, 53: 815.719, 63: 942.609}
"""The paper's CPU seconds per length (5,556 nodes)."""
REPEATS = 15
EXACT_FROM = 1
EXACT_LAYERS = 3
LAGS = (0, 1, 2, 4, 8)
PICKS = 200


def _sentence(heldout: Corpus, length: int) -> list[PhonemeSpan]:
    """The first ``length`` spans of the held-out lines joined end to end."""
    spans: list[PhonemeSpan] = []
    offset = 0.0
    for utterance in heldout.utterances:
        for span in fill_gaps(utterance.phones):
            spans.append(PhonemeSpan(span.phoneme, span.start + offset, span.end + offset))
            if len(spans) == length:
                return spans
        offset = spans[-1].end
    return spans


def _layers(spans: list[PhonemeSpan]) -> list[LayerSpec]:
    return [LayerSpec(PHONEME_INDEX[s.phoneme], EMOTION_INDEX["neutral"]) for s in spans]


def _fast_rows(model: ExpressiveDpModel, heldout: Corpus) -> list[dict[str, Any]]:
    """Fast-search CPU time (median and least of ``REPEATS``) per Table V length."""
    excluded = np.zeros(model.nodes.size, dtype=bool)
    rows = []
    for length, paper_s in TABLE_V.items():
        layers = _layers(_sentence(heldout, length))
        search(model.space, layers, excluded)  # compiled kernels warm
        times = []
        for _ in range(REPEATS):
            started = time.process_time()
            fast = search(model.space, layers, excluded)
            times.append(time.process_time() - started)
        rows.append(
            {
                "phonemes": len(layers),
                "paper_cpu_s": paper_s,
                "fast_cpu_ms": 1000.0 * statistics.median(times),
                "fast_cpu_ms_least": 1000.0 * min(times),
                "fast_priced_nodes": fast.candidates,
            }
        )
    return rows


def _table_v(model: ExpressiveDpModel, heldout: Corpus) -> dict[str, Any]:
    """Fast-search CPU time per Table V length, and exact DP's CPU time per transition."""
    excluded = np.zeros(model.nodes.size, dtype=bool)
    rows = _fast_rows(model, heldout)
    # Alg. 1 prices every pair: its time is (T - 1) transitions of N² pairs each
    head = _layers(_sentence(heldout, EXACT_FROM + EXACT_LAYERS))[EXACT_FROM:]
    started = time.process_time()
    exact = search(model.space, head, excluded, fast=False)
    per_transition = (time.process_time() - started) / (len(head) - 1)
    fast_head = search(model.space, head, excluded)
    for row in rows:
        row["exact_dp_cpu_s"] = per_transition * (row["phonemes"] - 1)
    return {
        "rows": rows,
        "exact_dp_cpu_s_per_transition": per_transition,
        "same_optimum_on_exact_layers": bool(
            abs(exact.cost - fast_head.cost) <= 1e-9 * max(1.0, abs(exact.cost))
        ),
    }


def _run(model: ExpressiveDpModel, spans: list[PhonemeSpan], **options: Any) -> tuple[Any, float]:
    synthesizer = model.start(fps=60.0, **options)
    started = time.perf_counter()
    synthesizer.feed(spans)
    synthesizer.finish()
    return synthesizer.stats, time.perf_counter() - started


def _lags(model: ExpressiveDpModel, heldout: Corpus) -> list[dict[str, Any]]:
    full = [_run(model, u.phones, emotion=u.emotion, lag="full")[0] for u in heldout.utterances]
    median_s = model.durations.pooled_median_s()
    rows = []
    for lag in LAGS:
        gaps, lines, nodes, total, elapsed, phonemes = [], 0, 0, 0, 0.0, 0
        for utterance, best in zip(heldout.utterances, full):
            stats, seconds = _run(model, utterance.phones, emotion=utterance.emotion, lag=lag)
            gaps.append((stats["path_cost"] - best["path_cost"]) / best["path_cost"])
            differing = sum(a != b for a, b in zip(stats["nodes"].split(), best["nodes"].split()))
            lines += differing > 0
            nodes += differing
            total += len(best["nodes"].split())
            elapsed += seconds
            phonemes += len(utterance.phones)
        rows.append(
            {
                "lag": lag,
                "lines_differing": lines / len(full),
                "nodes_differing": nodes / total,
                "mean_cost_gap": float(np.mean(gaps)),
                "max_cost_gap": float(np.max(gaps)),
                "lookahead_ms": 1000.0 * (lag + 2) * median_s,
                "ms_per_phoneme": 1000.0 * elapsed / phonemes,
            }
        )
    return rows


def _rms_by_emotion(heldout: Corpus, synthesize: Any) -> dict[str, float]:
    grouped: dict[str, list[float]] = {}
    for utterance in heldout.utterances:
        error = rms_error(synthesize(utterance), utterance.frames)
        grouped.setdefault(utterance.emotion, []).append(error)
    return {emotion: float(np.mean(values)) for emotion, values in sorted(grouped.items())}


def _pick_ms(model: ExpressiveDpModel) -> float:
    rng = np.random.default_rng(0)
    phonemes = [int(p) for p in np.unique(model.nodes.phoneme)]
    for phoneme in phonemes:
        model.maps.triangulation(phoneme)
    times = []
    for _ in range(PICKS):
        phoneme = phonemes[int(rng.integers(len(phonemes)))]
        rows = model.maps.phoneme_rows(phoneme)
        x, y = model.maps.points[rows[int(rng.integers(len(rows)))]] + rng.normal(0, 0.01, 2)
        started = time.perf_counter()
        picked = model.maps.pick(phoneme, float(x), float(y))
        model.basis.reconstruct(picked.frame[None])
        times.append(time.perf_counter() - started)
    return 1000.0 * statistics.median(times)


def run_expressive_dp_bench(corpus: Corpus) -> dict[str, Any]:
    train, heldout = corpus.split()
    with threadpool_limits(limits=1):
        started = time.perf_counter()
        model = ExpressiveDpEngine().fit(train)
        fit_s = time.perf_counter() - started
        lerp = VisemeLerpEngine().fit(train)
        metrics = model.manifest.metrics
        return {
            "fit_s": fit_s,
            "nodes": model.nodes.size,
            "basis_components": metrics["basis_components"],
            "alphas": metrics["alphas"],
            "cv_error": metrics.get("cv_error"),
            "cv_error_defaults": metrics.get("cv_error_defaults"),
            "table_v": _table_v(model, heldout),
            "lags": _lags(model, heldout),
            "rms_by_emotion": {
                "correct_modifiers": _rms_by_emotion(
                    heldout,
                    lambda u: model.synthesize(u.phones, heldout.fps, emotion=u.emotion).frames,
                ),
                "neutral_modifiers": _rms_by_emotion(
                    heldout,
                    lambda u: model.synthesize(u.phones, heldout.fps, emotion="neutral").frames,
                ),
                "viseme-lerp": _rms_by_emotion(
                    heldout, lambda u: lerp.synthesize(u.phones, heldout.fps).frames
                ),
            },
            "pick_ms": _pick_ms(model),
        }


def format_expressive_dp_bench(results: dict[str, Any]) -> str:
    table = results["table_v"]
    lines = [
        f"expressive-dp: fit {results['fit_s']:.1f} s, {results['nodes']} nodes, "
        f"{results['basis_components']} components, map pick {results['pick_ms']:.2f} ms",
        "  Table V (neutral): phonemes | paper CPU s | exact DP CPU s | fast CPU ms (least)",
    ]
    for row in table["rows"]:
        lines.append(
            f"  {row['phonemes']:>3} | {row['paper_cpu_s']:8.1f} | {row['exact_dp_cpu_s']:8.1f} | "
            f"{row['fast_cpu_ms']:7.1f} ({row['fast_cpu_ms_least']:.1f})"
        )
    lines.append(f"  same optimum as exact DP: {table['same_optimum_on_exact_layers']}")
    lines.append(
        "  fixed lag vs full: lag | lines differ | nodes differ | mean gap | max gap | wait ms"
    )
    for row in results["lags"]:
        lines.append(
            f"  {row['lag']:>3} | {row['lines_differing']:.0%} | {row['nodes_differing']:.1%} | "
            f"{row['mean_cost_gap']:.2%} | {row['max_cost_gap']:.2%} | {row['lookahead_ms']:.0f}"
        )
    for name, table_ in results["rms_by_emotion"].items():
        cells = ", ".join(f"{emotion} {value:.4f}" for emotion, value in table_.items())
        lines.append(f"  held-out RMS, {name}: {cells}")
    return "\n".join(lines)


def main() -> None:
    """Fit on the demo corpus and print the fast search's Table V rows."""
    from ..config import load_settings
    from ..corpus import load_corpus
    from ..training import DEMO_CORPUS_DIR, build_demo

    demo_dir = load_settings().demo_dir
    if not (demo_dir / DEMO_CORPUS_DIR).exists():
        build_demo(demo_dir, progress=True)
    train, heldout = load_corpus(demo_dir / DEMO_CORPUS_DIR).split()
    with threadpool_limits(limits=1):
        model = ExpressiveDpEngine().fit(train)
        rows = _fast_rows(model, heldout)
    print(f"expressive-dp fast search, {model.nodes.size} nodes, CPU ms of {REPEATS} runs:")
    print("  phonemes | median | least | nodes priced")
    for row in rows:
        print(
            f"  {row['phonemes']:>8} | {row['fast_cpu_ms']:6.1f} | {row['fast_cpu_ms_least']:5.1f}"
            f" | {row['fast_priced_nodes']}"
        )


if __name__ == "__main__":
    main()
