"""Where the demo models put a /p b m/ closure against the acoustic onset, and the recordings.

Sketch: every /p b m/ of the demo corpus is timed as ``evaluation.closure_lags`` times it
(the plateau around the aperture's minimum within the span widened by ``LAG_WINDOW_S``),
on the recording and on each engine's frames synthesized from the same phones: the
plateau's first frame (closing), last frame (release) and centre, each less the span's
acoustic start. The centre's lag is half the closing lag plus half the release lag. The
closures are also grouped by the recording's centre (``OFFSET_EDGES_MS``): a model whose lag
comes from a timing convention lags every group alike, one that cannot move a closure off
the span lags the anticipated closures (those the recording centres before the onset)
most. The training lines (what the model was fitted to) and the held-out lines are timed,
and for ``dam`` and ``cohen-massaro`` also their EM fit as it was trained: Eq. 2 over the
training lines with every occurrence's own mode (``fit_frames``), which the mode search
does not enter, so the lag splits into fitting and mode selection. Last, both engines are
trained and run with every bilabial's span started ``LEADS_MS`` earlier than its acoustic
one (``lead_bilabials``: the preceding span ends there, shortened by at most half), and
their held-out closures timed against the recordings on the acoustic spans.

``python -m lipstream.bench.closure_timing --home DIR --json bench/closure_timing.json``
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ..corpus import Corpus, load_corpus
from ..engines import get_engine_class, load_model
from ..engines.dam import em
from ..engines.dam.engine import DamEngine
from ..evaluation import (
    BILABIALS,
    LAG_WINDOW_S,
    closure_plateau,
    lip_aperture,
    rms_error,
)
from ..results_file import recorded, script_command, write_results
from ..timeline import PhonemeSpan

MODULE = "lipstream.bench.closure_timing"
ENGINES = ("viseme-lerp", "dam", "cohen-massaro")
FITTED = ("dam", "cohen-massaro")
LEADS_MS = (0.0, 20.0, 40.0)
OFFSET_EDGES_MS = (-20.0, 0.0, 20.0, 40.0)
"""Group bounds of the recorded closure centre less the acoustic onset: before -20 ms,
-20..0, 0..20, 20..40, from 40 ms."""


def closure_plateaus(
    aperture: np.ndarray, spans: Sequence[PhonemeSpan], fps: float
) -> list[tuple[float, float]]:
    """Per /p b m/ span with frames in its window, the (first, last) frame time (s) of the
    closure's plateau less the span's start: the run whose centre ``closure_centre`` is."""
    plateaus = []
    for span in spans:
        if span.phoneme not in BILABIALS:
            continue
        first = max(0, int(np.ceil((span.start - LAG_WINDOW_S) * fps)))
        stop = min(int(np.ceil((span.end + LAG_WINDOW_S) * fps)), len(aperture))
        if stop <= first:
            continue
        low, high = closure_plateau(aperture[first:stop])
        plateaus.append(((first + low) / fps - span.start, (first + high) / fps - span.start))
    return plateaus


def closure_offsets(aperture: np.ndarray, spans: Sequence[PhonemeSpan], fps: float) -> list[float]:
    """Per /p b m/ span with frames in its window, the closure's plateau centre (s) less
    the span's start."""
    return [(first + last) / 2.0 for first, last in closure_plateaus(aperture, spans, fps)]


def _group_label(index: int) -> str:
    edges = OFFSET_EDGES_MS
    if index == 0:
        return f"< {edges[0]:g}"
    if index == len(edges):
        return f">= {edges[-1]:g}"
    return f"{edges[index - 1]:g} .. {edges[index]:g}"


def grouped(recorded_s: Sequence[float], predicted_s: Sequence[float]) -> list[dict[str, Any]]:
    """Closures grouped by the recorded offset: per group the count and the mean recorded
    offset, predicted offset and lag (predicted less recorded), in ms."""
    truth = 1000.0 * np.asarray(recorded_s, dtype=np.float64)
    guess = 1000.0 * np.asarray(predicted_s, dtype=np.float64)
    group = np.searchsorted(np.asarray(OFFSET_EDGES_MS), truth, side="right")
    rows = []
    for index in range(len(OFFSET_EDGES_MS) + 1):
        chosen = group == index
        count = int(chosen.sum())
        rows.append(
            {
                "group": _group_label(index),
                "count": count,
                "recorded_ms": float(truth[chosen].mean()) if count else None,
                "predicted_ms": float(guess[chosen].mean()) if count else None,
                "lag_ms": float((guess - truth)[chosen].mean()) if count else None,
            }
        )
    return rows


def time_frames(predicted: Sequence[np.ndarray], corpus: Corpus) -> dict[str, Any]:
    """Frames ``predicted`` for every line of ``corpus`` against its recordings: the mean
    lag of the closures' centres, closings and releases (ms), the RMS and the groups."""
    truth: list[tuple[float, float]] = []
    guess: list[tuple[float, float]] = []
    errors = []
    for frames, utterance in zip(predicted, corpus.utterances, strict=True):
        errors.append(rms_error(frames, utterance.frames))
        for plateaus, source in ((truth, utterance.frames), (guess, frames)):
            aperture = lip_aperture(source, corpus.channels)
            assert aperture is not None, "the demo character has a lip aperture"
            plateaus.extend(closure_plateaus(aperture, utterance.phones, corpus.fps))
    recorded_edges = 1000.0 * np.asarray(truth).reshape(-1, 2)
    predicted_edges = 1000.0 * np.asarray(guess).reshape(-1, 2)
    lags = predicted_edges - recorded_edges
    return {
        "closures": len(lags),
        "lag_ms": float(lags.mean()),
        "closing_lag_ms": float(lags[:, 0].mean()),
        "release_lag_ms": float(lags[:, 1].mean()),
        "recorded_closing_ms": float(recorded_edges[:, 0].mean()),
        "recorded_release_ms": float(recorded_edges[:, 1].mean()),
        "rms": float(np.mean(errors)),
        "groups": grouped(
            recorded_edges.mean(axis=1) / 1000.0, predicted_edges.mean(axis=1) / 1000.0
        ),
    }


def synthesized(model: Any, corpus: Corpus) -> list[np.ndarray]:
    """``model``'s frames for every line of ``corpus`` (on its spans), each with its line's
    emotion."""
    return [
        model.synthesize(u.phones, fps=corpus.fps, audio=None, emotion=u.emotion).frames
        for u in corpus.utterances
    ]


def fit_frames(engine: DamEngine, train: Corpus) -> list[np.ndarray]:
    """The EM fit of ``engine`` on ``train``, as ``DamEngine.fit`` runs it, evaluated on
    ``train`` with every occurrence's own mode (Eq. 2 over the design matrix): per line."""
    occurrences, _, basis, frames, _, mode_of, settings, fitted = engine.fit_em(train)
    matrix = em.design(occurrences, mode_of, fitted.sigma, len(frames), settings)
    fitted_frames = basis.reconstruct(matrix @ fitted.coefficients.reshape(-1, frames.shape[1]))
    bounds = np.cumsum([0] + [len(u.frames) for u in train.utterances])
    return [fitted_frames[low:high] for low, high in zip(bounds[:-1], bounds[1:])]


def lead_bilabials(spans: Sequence[PhonemeSpan], lead_s: float) -> list[PhonemeSpan]:
    """``spans`` with every /p b m/ after another span started ``lead_s`` earlier and that
    span ended there, each moved by at most half the preceding span's duration."""
    moved = list(spans)
    for index in range(1, len(moved)):
        span, before = moved[index], moved[index - 1]
        if span.phoneme not in BILABIALS:
            continue
        shift = min(lead_s, 0.5 * (before.end - before.start))
        moved[index - 1] = replace(before, end=before.end - shift)
        moved[index] = replace(span, start=span.start - shift)
    return moved


def led(corpus: Corpus, lead_s: float) -> Corpus:
    """``corpus`` with its bilabials led by ``lead_s`` (``lead_bilabials``)."""
    return replace(
        corpus,
        utterances=[replace(u, phones=lead_bilabials(u.phones, lead_s)) for u in corpus.utterances],
    )


def time_leads(name: str, train: Corpus, heldout: Corpus) -> list[dict[str, Any]]:
    """Engine ``name`` trained on ``train`` and run on ``heldout`` with the bilabials led by
    each of ``LEADS_MS``, its closures timed against the recordings."""
    rows = []
    for lead_ms in LEADS_MS:
        model = get_engine_class(name)().fit(led(train, lead_ms / 1000.0))
        timed = time_frames(synthesized(model, led(heldout, lead_ms / 1000.0)), heldout)
        rows.append({"lead_ms": lead_ms, **{k: v for k, v in timed.items() if k != "groups"}})
    return rows


def run(home: Path, engines: Sequence[str], command: str) -> dict[str, Any]:
    corpus = load_corpus(home / "demo" / "corpus")
    train, heldout = corpus.split()
    timed: dict[str, dict[str, Any]] = {}
    with threadpool_limits(limits=1):
        for name in engines:
            model = load_model(home / "demo" / "models" / name)
            timed[name] = {
                part: time_frames(synthesized(model, lines), lines)
                for part, lines in (("train", train), ("heldout", heldout))
            }
            if name in FITTED:
                engine = get_engine_class(name)(**model.manifest.hyperparameters)
                assert isinstance(engine, DamEngine)
                timed[name]["fit"] = time_frames(fit_frames(engine, train), train)
                timed[name]["leads"] = time_leads(name, train, heldout)
    return {
        **recorded(command),
        "corpus": {"name": corpus.name, "digest": corpus.digest(), "fps": corpus.fps},
        "engines": timed,
    }


def format_timing(results: dict[str, Any]) -> str:
    lines = []
    for engine, parts in results["engines"].items():
        for row in parts.get("leads", []):
            lines.append(
                f"{engine} held-out, bilabials led {row['lead_ms']:g} ms: lag"
                f" {row['lag_ms']:+.1f} ms, RMS {row['rms']:.4f}"
            )
        for part, timed in parts.items():
            if part == "leads":
                continue
            lines.append(
                f"{engine} {part}: lag {timed['lag_ms']:+.1f} ms (closing"
                f" {timed['closing_lag_ms']:+.1f}, release {timed['release_lag_ms']:+.1f}) over"
                f" {timed['closures']} closures, RMS {timed['rms']:.4f}"
            )
            for row in timed["groups"]:
                if row["count"]:
                    lines.append(
                        f"  recorded {row['group']:>10} ms: n {row['count']:4d} recorded"
                        f" {row['recorded_ms']:+6.1f} predicted {row['predicted_ms']:+6.1f}"
                        f" lag {row['lag_ms']:+6.1f}"
                    )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog=f"python -m {MODULE}", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--home", type=Path, required=True, help="LIPSTREAM_HOME with a demo")
    parser.add_argument("--json", type=Path, required=True, help="results file to write")
    args = parser.parse_args(argv)
    results = run(args.home, ENGINES, script_command(MODULE, argv))
    write_results(results, args.json)
    print(format_timing(results))


if __name__ == "__main__":
    main()
