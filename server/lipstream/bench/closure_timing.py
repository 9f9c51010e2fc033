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
``dam`` and ``cohen-massaro`` trained here without their bilabial lead (the diagnosis is of
the engines as they were before it), and for both also their EM fit: Eq. 2 over the
training lines with every occurrence's own mode (``fit_frames``), which the mode search
does not enter, so the lag splits into fitting and mode selection. The recorded closures
after silence (or at a line's start) and after a phoneme are timed apart
(``after_silence``): whether the character leads a bilabial out of a pause as it does
inside a phrase. Last, the sweep that chose the engines' ``bilabial_lead_s``: both engines
are trained and run with each lead of ``LEADS_MS`` (``bilabial_lead.lead_bilabials``: every
bilabial's span started that much earlier than its acoustic one, the preceding span
shortened by at most half), their held-out closures timed against the recordings on the
acoustic spans, on the search rungs (offline) and on the ``causal`` rung, which keeps the
acoustic spans; and offline on the real-face set's force-aligned phones against the
character rendered on them (``closure_sources.RealPhones``; the real lips only for
information). ``best_lead_ms`` picks the lead that puts the closures nearest the
character's on both.

``python -m lipstream.bench.closure_timing --home DIR [--real DIR] --json FILE``
"""

from __future__ import annotations

from collections.abc import Sequence
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
from ..phonemes import SILENCE
from ..results_file import recorded, script_command, write_results
from ..timeline import PhonemeSpan
from .closure_sources import RealPhones
from .real_set import real_set_parser

MODULE = "lipstream.bench.closure_timing"
ENGINES = ("viseme-lerp", "dam", "cohen-massaro")
FITTED = ("dam", "cohen-massaro")
LEADS_MS = (0.0, 10.0, 20.0, 30.0, 40.0, 50.0)
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


def synthesized(model: Any, corpus: Corpus, **options: Any) -> list[np.ndarray]:
    """``model``'s frames for every line of ``corpus`` (on its spans), each with its line's
    emotion, with engine ``options``."""
    return [
        model.synthesize(u.phones, fps=corpus.fps, audio=None, emotion=u.emotion, **options).frames
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


def fitted_at_leads(name: str, hyperparameters: dict[str, Any], train: Corpus) -> dict[float, Any]:
    """Engine ``name`` with ``hyperparameters`` trained on ``train`` at each bilabial lead of
    ``LEADS_MS`` (by lead, ms)."""
    return {
        lead_ms: get_engine_class(name)(
            **{**hyperparameters, "bilabial_lead_s": lead_ms / 1000.0}
        ).fit(train)
        for lead_ms in LEADS_MS
    }


def time_leads(models: dict[float, Any], heldout: Corpus, real: RealPhones) -> list[dict[str, Any]]:
    """The models of ``fitted_at_leads`` run on ``heldout`` (offline, and on the ``causal``
    rung), their closures timed against the recordings; and offline on the real set's
    phones, behind the character (``real_phones_lag_ms``) and, for information, behind the
    real lips (``real``)."""
    rows = []
    for lead_ms, model in models.items():
        timed = time_frames(synthesized(model, heldout), heldout)
        causal = time_frames(synthesized(model, heldout, causal=True), heldout)
        found = real.timed(model)
        rows.append(
            {
                "lead_ms": lead_ms,
                **{k: v for k, v in timed.items() if k != "groups"},
                "causal": {"lag_ms": causal["lag_ms"], "rms": causal["rms"]},
                "real_phones_lag_ms": found["behind_character"]["mean_ms"],
                "real": found["behind_real"],
            }
        )
    return rows


def plateaus_by_pause(
    aperture: np.ndarray, spans: Sequence[PhonemeSpan], fps: float
) -> dict[str, list[tuple[float, float]]]:
    """``closure_plateaus`` of the /p b m/ after silence (or first in the line) and of those
    after a phoneme."""
    groups: dict[str, list[tuple[float, float]]] = {"silence": [], "phoneme": []}
    for index, span in enumerate(spans):
        if span.phoneme not in BILABIALS:
            continue
        paused = index == 0 or spans[index - 1].phoneme == SILENCE
        groups["silence" if paused else "phoneme"].extend(closure_plateaus(aperture, [span], fps))
    return groups


def best_lead_ms(rows: Sequence[dict[str, Any]]) -> float:
    """The lead of the sweep ``rows`` (``time_leads``) whose closures sit nearest the
    character's, among those whose held-out RMS is not above the RMS without a lead: the
    least of the larger of the held-out centre lag and the lag behind the character on the
    real set's phones (``real_phones_lag_ms``, where a row has it), both as magnitudes. The
    demo's lines alone would fit the lead to their own mix of contexts; real speech opens
    more bilabials out of silence, where a led closure lands early."""
    unled = next(row for row in rows if row["lead_ms"] == 0.0)
    kept = [row for row in rows if row["rms"] <= unled["rms"]]

    def distance(row: dict[str, Any]) -> float:
        return float(max(abs(row["lag_ms"]), abs(row.get("real_phones_lag_ms", 0.0))))

    return float(min(kept, key=distance)["lead_ms"])


def after_silence(corpus: Corpus) -> dict[str, dict[str, Any]]:
    """The recorded closures of ``corpus`` after silence (or first in a line) and after a
    phoneme: per group the count and mean closing, release and centre (ms) of the onset."""
    groups: dict[str, list[tuple[float, float]]] = {"silence": [], "phoneme": []}
    for utterance in corpus.utterances:
        aperture = lip_aperture(utterance.frames, corpus.channels)
        assert aperture is not None, "the demo character has a lip aperture"
        for group, plateaus in plateaus_by_pause(aperture, utterance.phones, corpus.fps).items():
            groups[group].extend(plateaus)
    summary = {}
    for group, plateaus in groups.items():
        edges = 1000.0 * np.asarray(plateaus).reshape(-1, 2)
        summary[group] = {
            "closures": len(edges),
            "closing_ms": float(edges[:, 0].mean()) if len(edges) else None,
            "release_ms": float(edges[:, 1].mean()) if len(edges) else None,
            "centre_ms": float(edges.mean()) if len(edges) else None,
        }
    return summary


def run(home: Path, engines: Sequence[str], real_set: Path, command: str) -> dict[str, Any]:
    corpus = load_corpus(home / "demo" / "corpus")
    train, heldout = corpus.split()
    real = RealPhones.load(real_set)
    timed: dict[str, dict[str, Any]] = {}
    with threadpool_limits(limits=1):
        for name in engines:
            model = load_model(home / "demo" / "models" / name)
            built_lead_ms = 1000.0 * float(model.manifest.hyperparameters.get("bilabial_lead_s", 0))
            hyperparameters = {**model.manifest.hyperparameters, "bilabial_lead_s": 0.0}
            models = fitted_at_leads(name, hyperparameters, train) if name in FITTED else {}
            # the diagnosis is of the engine as it was before its bilabial lead
            unled = models.get(0.0, model)
            timed[name] = {
                part: time_frames(synthesized(unled, lines), lines)
                for part, lines in (("train", train), ("heldout", heldout))
            }
            if name in FITTED:
                engine = get_engine_class(name)(**hyperparameters)
                assert isinstance(engine, DamEngine)
                timed[name]["fit"] = time_frames(fit_frames(engine, train), train)
                timed[name]["leads"] = time_leads(models, heldout, real)
                timed[name]["best_lead_ms"] = best_lead_ms(timed[name]["leads"])
                chosen = get_engine_class(name)().hyperparameters()["bilabial_lead_s"]
                timed[name]["chosen_lead_ms"] = round(1000.0 * chosen, 6)
                timed[name]["built_lead_ms"] = round(built_lead_ms, 6)
    return {
        **recorded(command),
        "corpus": {"name": corpus.name, "digest": corpus.digest(), "fps": corpus.fps},
        "real_set": {"name": real.name, "clips": len(real.clips), "fps": real.fps},
        "after_silence": after_silence(train),
        "engines": timed,
    }


def format_timing(results: dict[str, Any]) -> str:
    lines = [
        f"recorded after {group}: closing {row['closing_ms']:+.1f}, release"
        f" {row['release_ms']:+.1f}, centre {row['centre_ms']:+.1f} ms over {row['closures']}"
        for group, row in results["after_silence"].items()
        if row["closures"]
    ]
    for engine, parts in results["engines"].items():
        for row in parts.get("leads", []):
            lines.append(
                f"{engine} held-out, bilabials led {row['lead_ms']:g} ms: lag"
                f" {row['lag_ms']:+.1f} ms, RMS {row['rms']:.4f}; causal rung lag"
                f" {row['causal']['lag_ms']:+.1f} ms, RMS {row['causal']['rms']:.4f}; behind"
                f" the character on the real phones {row['real_phones_lag_ms']:+.1f} ms"
            )
        for part, timed in parts.items():
            if part not in ("train", "heldout", "fit"):
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
    parser = real_set_parser(f"python -m {MODULE}", __doc__, home=True)
    parser.add_argument("--json", type=Path, required=True, help="results file to write")
    args = parser.parse_args(argv)
    results = run(args.home, ENGINES, args.real, script_command(MODULE, argv))
    write_results(results, args.json)
    print(format_timing(results))


if __name__ == "__main__":
    main()
