"""Benchmarks of the anime-graph engine: the paper's tables, scaling, speed and quality.

Sketch (``run_anime_graph_bench``; every figure is JSON-able):

- ``table``: Cao et al.'s Tables 1-2 on held-out sentences of 22-38 phonemes:
  search time (ms), jumps and RMS of GreedyMatching (uncapped, the paper's
  algorithm) against PQ-Matching(h) for each h, on the unclustered and the
  clustered graph of the whole corpus, and greedy's speed-up over each PQ.
- ``scaling``: greedy search time per sentence with the training set
  duplicated 1x, 4x, 16x (every copy with fresh motion noise, no audio).
- ``speed``: greedy search for a 40-phoneme sentence and the whole synthesis
  (search, warp, blend, smooth) per held-out sentence, at 60 fps.
- ``quality``: RMS error against the recorded held-out curves and the /p b m/
  closure rate, for greedy (both graphs) beside ``viseme-lerp``.

Timings run with BLAS limited to one thread (one core) and report medians.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ..audio import Audio
from ..corpus import Corpus, Utterance
from ..engines.anime_graph.engine import AnimeGraphEngine
from ..engines.anime_graph.model import AnimeGraphModel
from ..engines.anime_graph.pq import SearchTimeout
from ..engines.anime_graph.synthesizer import AnimeGraphSynthesizer
from ..engines.viseme_lerp import VisemeLerpEngine
from ..errors import InvalidRequestError
from ..evaluation import rms_error
from ..timeline import PhonemeSpan
from .closure import closure_rate, learned_threshold

PAPER_LENGTHS = (22, 38, 37)
SPEED_FPS = 60.0


def _median_ms(call: Callable[[], float], repeats: int) -> float:
    """Median of ``repeats`` runs of ``call``, which returns its own time in ms."""
    return statistics.median(call() for _ in range(repeats))


def warm_search_times_ms(synthesizer: AnimeGraphSynthesizer, repeats: int) -> list[float]:
    """Times (ms) of ``repeats`` back-to-back GreedyMatching runs over the whole finished
    query of one view, as the benchmark's warm search time: the search alone, without
    the cache misses the rest of a synthesis leaves behind."""
    whole = synthesizer.finished and len(synthesizer.nodes) >= len(synthesizer.query)
    if not whole or synthesizer.run_starts:
        raise InvalidRequestError(
            "only a finished single-view request can be re-timed", code="request_unfinished"
        )
    searcher = synthesizer.searchers[0]
    query = synthesizer.query
    ranking = synthesizer.ranking(searcher.graph, 0, len(query))
    cap = synthesizer.options.max_tile
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        searcher.matcher.tiles(query, 0, len(query), cap, None, ranking)
        times.append(1000.0 * (time.perf_counter() - started))
    return times


def pick_sentences(
    heldout: Corpus, count: int = 3, low: int = 22, high: int = 38
) -> list[Utterance]:
    """Held-out utterances whose phoneme counts come closest to the paper's 22, 38 and 37,
    preferring counts inside [low, high]."""
    chosen: list[Utterance] = []
    for target in (PAPER_LENGTHS * count)[:count]:
        pool = [u for u in heldout.utterances if u not in chosen]
        if not pool:
            break
        chosen.append(
            min(
                pool,
                key=lambda u: (
                    not low <= len(u.phones) <= high,
                    abs(len(u.phones) - target),
                    u.stem,
                ),
            )
        )
    return chosen


def _run(
    model: AnimeGraphModel, utterance: Utterance, audio: bool, **options: Any
) -> dict[str, Any]:
    result = model.synthesize(
        utterance.phones, fps=model.fps, audio=utterance.audio if audio else None, **options
    )
    return {
        "search_ms": result.stats["search_ms"],
        "jumps": result.stats["jumps"],
        "rms": rms_error(result.frames, utterance.frames),
    }


def _greedy(
    model: AnimeGraphModel, utterance: Utterance, graph: str, audio: bool, repeats: int
) -> dict[str, Any]:
    """Uncapped greedy (the paper's algorithm) on ``graph``. ``search_ms``: the median of
    ``repeats`` back-to-back searches of the sentence; ``search_ms_in_synthesis``: the
    median search time inside ``repeats`` whole syntheses, where the rest of the work has
    evicted the search's data from the CPU caches."""
    greedy = _run(model, utterance, audio, graph=graph, max_tile=0)
    greedy["search_ms_in_synthesis"] = _median_ms(
        lambda: float(_run(model, utterance, audio, graph=graph, max_tile=0)["search_ms"]), repeats
    )
    synthesizer = model.start(fps=model.fps, graph=graph, max_tile=0)
    synthesizer.feed(utterance.phones, utterance.audio if audio else None)
    synthesizer.finish()
    greedy["search_ms"] = statistics.median(warm_search_times_ms(synthesizer, repeats))
    return greedy


def _table_row(
    model: AnimeGraphModel,
    utterance: Utterance,
    graph: str,
    audio: bool,
    windows: Sequence[int],
    advance: int,
    budget_s: float,
    greedy: dict[str, Any],
    unclustered: dict[str, Any],
) -> dict[str, Any]:
    """PQ(h) on ``graph`` beside ``greedy`` (``_greedy`` on that graph); each PQ's speed-up
    over greedy on the same graph and, as in the paper's Table 1, over greedy on the
    unclustered graph (``unclustered``)."""
    unclustered_ms = unclustered["search_ms"]
    unclustered_in_synthesis_ms = unclustered["search_ms_in_synthesis"]
    row: dict[str, Any] = {
        "phonemes": len(utterance.phones),
        "stem": utterance.stem,
        "graph": graph,
        "greedy": greedy,
        "pq": {},
    }
    for window in windows:
        try:
            found = _run(
                model,
                utterance,
                audio,
                graph=graph,
                search="pq",
                pq_window=window,
                pq_advance=min(advance, window),
                pq_budget_s=budget_s,
            )
            found["timed_out"] = False
        except SearchTimeout:
            found = {"timed_out": True, "search_ms": 1000.0 * budget_s, "jumps": None, "rms": None}
        found["speedup"] = found["search_ms"] / max(greedy["search_ms"], 1e-9)
        found["speedup_over_unclustered_greedy"] = found["search_ms"] / max(unclustered_ms, 1e-9)
        found["speedup_over_unclustered_greedy_in_synthesis"] = found["search_ms"] / max(
            unclustered_in_synthesis_ms, 1e-9
        )
        row["pq"][str(window)] = found
    return row


def paper_table(
    model: AnimeGraphModel,
    heldout: Corpus,
    windows: Sequence[int] = (3, 4, 5),
    advance: int = 1,
    budget_s: float = 60.0,
    repeats: int = 20,
    count: int = 3,
) -> dict[str, Any]:
    """Greedy against PQ-Matching(h) on the whole corpus's graphs (no emotion view), with
    the held-out audio when the model has audio features."""
    graphs = ["unclustered"] + (["clustered"] if model.has_clusters else [])
    rows = []
    for utterance in pick_sentences(heldout, count):
        greedy = {
            graph: _greedy(model, utterance, graph, model.has_audio, repeats) for graph in graphs
        }
        rows += [
            _table_row(
                model,
                utterance,
                graph,
                model.has_audio,
                windows,
                advance,
                budget_s,
                greedy[graph],
                greedy["unclustered"],
            )
            for graph in graphs
        ]
    finished = [
        (row["greedy"]["jumps"], pq["jumps"])
        for row in rows
        for pq in row["pq"].values()
        if not pq["timed_out"]
    ]
    pq4 = [row["pq"]["4"] for row in rows if "4" in row["pq"]]
    return {
        "rows": rows,
        "pq_advance": advance,
        "pq_budget_s": budget_s,
        "audio": model.has_audio,
        "greedy_never_more_jumps": all(greedy <= pq for greedy, pq in finished),
        "min_speedup_over_pq4": min(
            (pq["speedup_over_unclustered_greedy"] for pq in pq4), default=None
        ),
        "min_speedup_over_pq4_in_synthesis": min(
            (pq["speedup_over_unclustered_greedy_in_synthesis"] for pq in pq4), default=None
        ),
        "min_speedup_over_pq4_same_graph": {
            graph: min(
                (
                    row["pq"]["4"]["speedup"]
                    for row in rows
                    if row["graph"] == graph and "4" in row["pq"]
                ),
                default=None,
            )
            for graph in graphs
        },
    }


def _search_ms(
    model: AnimeGraphModel, spans: Sequence[PhonemeSpan], audio: Audio | None, repeats: int
) -> float:
    """Median greedy search time (ms) of one request over ``repeats`` runs."""

    def once() -> float:
        return float(model.synthesize(spans, fps=SPEED_FPS, audio=audio).stats["search_ms"])

    return _median_ms(once, repeats)


def _noisy_copies(train: Corpus, factor: int, seed: int) -> Corpus:
    """``factor`` copies of every training utterance, each copy's frames with independent
    Gaussian noise of 1% of the channel's spread; audio dropped."""
    rng = np.random.default_rng(seed)
    spread = np.concatenate([u.frames for u in train.utterances]).std(axis=0) * 0.01
    copies = [
        replace(
            u,
            stem=f"{u.stem}~{copy}",
            audio=None,
            frames=(u.frames + rng.normal(0.0, 1.0, u.frames.shape) * spread).astype(np.float32),
        )
        for copy in range(factor)
        for u in train.utterances
    ]
    return replace(train, name=f"{train.name}x{factor}", utterances=copies, heldout=())


def _warm_search_ms(model: AnimeGraphModel, spans: Sequence[PhonemeSpan], repeats: int) -> float:
    """Median of ``repeats`` back-to-back greedy searches of one request (served options)."""
    synthesizer = model.start(fps=SPEED_FPS)
    synthesizer.feed(spans)
    synthesizer.finish()
    return statistics.median(warm_search_times_ms(synthesizer, repeats))


def scaling(
    train: Corpus,
    heldout: Corpus,
    factors: Sequence[int] = (1, 4, 16),
    repeats: int = 5,
    seed: int = 0,
) -> list[dict[str, Any]]:
    """Greedy search time per held-out sentence as the database grows: inside a synthesis,
    and back to back (warm), which leaves out the cache misses of a bigger index."""
    rows = []
    phonemes = sum(len(u.phones) for u in heldout.utterances)
    for factor in factors:
        grown = _noisy_copies(train, factor, seed)
        started = time.perf_counter()
        model = AnimeGraphEngine(clusters=0).fit(grown)
        fit_s = time.perf_counter() - started
        per_sentence = [_search_ms(model, u.phones, None, repeats) for u in heldout.utterances]
        warm = [_warm_search_ms(model, u.phones, 4 * repeats) for u in heldout.utterances]
        rows.append(
            {
                "factor": factor,
                "animes": model.animes.size,
                "fit_s": fit_s,
                "search_ms_per_sentence": float(np.mean(per_sentence)),
                "search_us_per_phoneme": 1000.0 * sum(per_sentence) / phonemes,
                "warm_search_ms_per_sentence": float(np.mean(warm)),
            }
        )
    return rows


def _first_phonemes(
    utterances: Sequence[Utterance], count: int
) -> tuple[list[PhonemeSpan], Audio | None]:
    """``count`` spans from the held-out sentences laid end to end, with their audio."""
    spans: list[PhonemeSpan] = []
    pieces: list[np.ndarray] = []
    rate: int | None = None
    for utterance in utterances:
        offset = spans[-1].end if spans else 0.0
        taken = utterance.phones[: count - len(spans)]
        spans.extend(PhonemeSpan(s.phoneme, s.start + offset, s.end + offset) for s in taken)
        if utterance.audio is not None:
            rate = utterance.audio.sample_rate
            pieces.append(utterance.audio.samples[: round(taken[-1].end * rate)])
        if len(spans) == count:
            break
    audio = Audio(np.concatenate(pieces), rate) if rate and pieces else None
    return spans, audio


def speed(model: AnimeGraphModel, heldout: Corpus, repeats: int = 30) -> dict[str, Any]:
    """Greedy search for a 40-phoneme sentence; whole synthesis per held-out sentence."""
    spans, audio = _first_phonemes(heldout.utterances, 40)

    def synthesis_ms(sound: bool) -> float:
        times = []
        for utterance in heldout.utterances:
            started = time.perf_counter()
            model.synthesize(
                utterance.phones,
                fps=SPEED_FPS,
                emotion=utterance.emotion,
                audio=utterance.audio if sound else None,
            )
            times.append(1000.0 * (time.perf_counter() - started))
        return statistics.median(times)

    figures: dict[str, Any] = {
        "phonemes": len(spans),
        "greedy_search_ms": _search_ms(model, spans, None, repeats),
        "synthesis_ms_per_sentence": synthesis_ms(False),
        "mean_phonemes_per_sentence": float(np.mean([len(u.phones) for u in heldout.utterances])),
    }
    if model.has_audio and audio is not None:
        figures["greedy_search_ms_with_audio"] = _search_ms(model, spans, audio, repeats)
        figures["synthesis_ms_per_sentence_with_audio"] = synthesis_ms(True)
    return figures


def quality(model: AnimeGraphModel, train: Corpus, heldout: Corpus) -> dict[str, Any]:
    """RMS and /p b m/ closure of greedy (each graph) and of ``viseme-lerp``."""
    threshold = learned_threshold(train)
    baseline = VisemeLerpEngine().fit(train)
    runs: dict[str, list[np.ndarray]] = {
        "viseme-lerp": [
            baseline.synthesize(u.phones, fps=heldout.fps).frames for u in heldout.utterances
        ]
    }
    for graph in ["unclustered"] + (["clustered"] if model.has_clusters else []):
        runs[f"anime-graph {graph}"] = [
            model.synthesize(
                u.phones, fps=heldout.fps, audio=u.audio, emotion=u.emotion, graph=graph
            ).frames
            for u in heldout.utterances
        ]
    figures: dict[str, Any] = {}
    for name, predictions in runs.items():
        figures[name] = {
            "rms": float(
                np.mean([rms_error(p, u.frames) for p, u in zip(predictions, heldout.utterances)])
            ),
            "closure_rate": closure_rate(predictions, heldout, threshold),
        }
    figures["recorded_closure_rate"] = closure_rate(
        [u.frames for u in heldout.utterances], heldout, threshold
    )
    return figures


def run_anime_graph_bench(
    corpus: Corpus,
    *,
    windows: Sequence[int] = (3, 4, 5),
    pq_advance: int = 1,
    pq_budget_s: float = 60.0,
    factors: Sequence[int] = (1, 4, 16),
    repeats: int = 20,
    seed: int = 0,
) -> dict[str, Any]:
    """Every anime-graph benchmark on ``corpus``'s train/held-out split."""
    train, heldout = corpus.split()
    with threadpool_limits(limits=1):
        started = time.perf_counter()
        model = AnimeGraphEngine(seed=seed).fit(train)
        fit_s = time.perf_counter() - started
        return {
            "corpus": {
                "name": corpus.name,
                "train_utterances": len(train.utterances),
                "heldout_utterances": len(heldout.utterances),
            },
            "model": {
                "fit_s": fit_s,
                "metrics": model.manifest.metrics,
                "lookahead": {
                    "seconds": model.lookahead.seconds,
                    "phonemes": model.lookahead.phonemes,
                },
            },
            "table": paper_table(model, heldout, windows, pq_advance, pq_budget_s, repeats),
            "scaling": scaling(train, heldout, factors, max(1, repeats // 4), seed),
            "speed": speed(model, heldout, repeats),
            "quality": quality(model, train, heldout),
        }


def _number(value: float | None, pattern: str) -> str:
    return "n/a" if value is None else format(value, pattern)


def format_anime_graph_bench(results: dict[str, Any]) -> str:
    """The benchmark as plain-text tables."""
    header = (
        f"{'phon':>5} {'graph':<12} {'search':<10} {'ms':>10} {'jumps':>6} {'RMS':>7} "
        f"{'speedup':>9} {'vs unclustered greedy':>22}"
    )
    lines = [header]
    for row in results["table"]["rows"]:
        greedy = row["greedy"]
        lines.append(
            f"{row['phonemes']:>5} {row['graph']:<12} {'greedy':<10} "
            f"{greedy['search_ms']:>10.3f} {greedy['jumps']:>6} {greedy['rms']:>7.4f} "
            f"(in synthesis {greedy['search_ms_in_synthesis']:.3f} ms)"
        )
        for window, pq in row["pq"].items():
            mark = ">" if pq["timed_out"] else ""
            lines.append(
                f"{'':>5} {'':<12} {'PQ(' + window + ')':<10} "
                f"{mark + format(pq['search_ms'], '.1f'):>10} "
                f"{_number(pq['jumps'], 'd'):>6} {_number(pq['rms'], '.4f'):>7} "
                f"{mark + format(pq['speedup'], '.0f') + 'x':>9} "
                f"{mark + format(pq['speedup_over_unclustered_greedy'], '.0f') + 'x':>22}"
            )
    table = results["table"]
    lines.append(
        f"min PQ(4) speed-up over unclustered greedy (paper's Table 1): "
        f"{_number(table['min_speedup_over_pq4'], '.0f')}x (greedy timed inside a "
        f"synthesis: {_number(table['min_speedup_over_pq4_in_synthesis'], '.0f')}x); "
        "same graph: "
        + ", ".join(
            f"{graph} {_number(value, '.0f')}x"
            for graph, value in table["min_speedup_over_pq4_same_graph"].items()
        )
    )
    lines.append("")
    lines.append(
        f"{'copies':>6} {'animes':>8} {'fit s':>7} {'ms/sentence':>12} "
        f"{'us/phoneme':>11} {'warm ms/sentence':>17}"
    )
    for row in results["scaling"]:
        lines.append(
            f"{row['factor']:>6} {row['animes']:>8} {row['fit_s']:>7.1f} "
            f"{row['search_ms_per_sentence']:>12.3f} "
            f"{row['search_us_per_phoneme']:>11.2f} "
            f"{row['warm_search_ms_per_sentence']:>17.3f}"
        )
    lines.append("")
    lines.extend(
        f"{key}: {_number(value, '.3f') if isinstance(value, float) else value}"
        for key, value in results["speed"].items()
    )
    lines.append("")
    for name, figures in results["quality"].items():
        if isinstance(figures, dict):
            lines.append(
                f"{name:<26} RMS {figures['rms']:.4f}  closure "
                f"{_number(figures['closure_rate'], '.1%')}"
            )
    lines.append(f"recorded closure {_number(results['quality']['recorded_closure_rate'], '.1%')}")
    return "\n".join(lines)
