"""Why phoneme-driven `hmm` closes the lips late: where a state's pose is sampled in training,
and which trajectory frame takes which state.

Sketch: the synthesizer solves the trajectory at a rate f above R (``hmm_fps``) and gives
trajectory frame k (at k / f) the state of HMM frame ⌊k R / f⌋ (``synthesizer.hmm_frame``):
every state is held over [j / R, (j + 1) / R). Trained on the curves at the instants j / R
(``sample_offset`` 0, the engine's default), state j stands for the pose at j / R, so its
targets arrive on average (1 / R − 1 / f) / 2 late (4.2 ms at R = 60 Hz, f = 120 Hz).
``sample_offset`` ``engine.HOLD_CENTRE`` (½) trains on the curves at (j + ½) / R, the hold
interval's centre.

Two models are compared in one run (``SAMPLINGS``), both trained on the train split: one
with ``sample_offset`` 0 (``instant``) and one with ``HOLD_CENTRE`` (``centre``);
``--model`` (else the defaults trained on the train split) stands for the one its offset
names. Each line is decoded once per model, driven by phonemes alone on the offline rung
(Viterbi over the whole line, one solve; ``floor_max_abs_diff`` checks that the ``floor``
convention reproduces the engine's frames), and its trajectory solved at the engine's rate
with the state of frame k taken three ways (``CONVENTIONS``): ``floor`` (the engine's),
``nearest`` (⌊k R / f + ½⌋) and ``ceil`` (⌈k R / f⌉). Closure lags are timed as
``evaluation.closure_lags`` times them: on the demo corpus's held-out lines against their
recordings (with the RMS error), and on the real-face set behind the demo character
(``closure_sources.character_aperture``) and behind the real lips; ``centre``'s shift from
``instant`` is paired span by span. The served rungs' closure lag on the held-out lines
shows whether the decoder's lag adds to it. EM finds a different model from each seed, which
moves the closures too: ``--seeds`` (default ``SWEEP_SEEDS``) trains both samplings again
from each further seed and keeps their own lags (``seed_sweep``).

``python -m lipstream.bench.hmm_closure_lag --corpus DIR --json bench/hmm_closure_lag.json``
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ..corpus import Corpus, load_corpus
from ..engines import load_model
from ..engines.base import SynthesisRequest, frame_count
from ..engines.hmm.engine import HOLD_CENTRE, HmmEngine
from ..engines.hmm.model import INSTANT_SAMPLING, HmmModel
from ..engines.hmm.synthesizer import HmmSynthesizer
from ..engines.hmm.trajectory import solve
from ..errors import LipstreamError
from ..evaluation import closure_lags, lip_aperture, rms_error
from ..results_file import recorded, script_command, write_results
from ..timeline import PhonemeSpan
from ..training import train_engine
from .closure_sources import (
    CONTEXTS,
    bilabial_contexts,
    character_aperture,
    lags_by_context,
    summarize_contexts,
    summarize_lags,
)
from .real_faces import real_clips
from .real_set import real_set_parser

MODULE = "lipstream.bench.hmm_closure_lag"
CONVENTIONS = ("floor", "nearest", "ceil")
SAMPLINGS = ("instant", "centre")
SWEEP_SEEDS = (1, 2, 3)
OWN = "floor"
"""The engine's convention: the lags its own frames show."""
OFFLINE: dict[str, Any] = {"drive": "phonemes", "lag_ms": None, "window_ms": None}
_EPS = 1e-9


def frame_states(states: np.ndarray, n_frames: int, ratio: float, convention: str) -> np.ndarray:
    """The state of each of ``n_frames`` trajectory frames from the HMM frames' ``states``,
    ``ratio`` = R / f, by ``convention`` (``CONVENTIONS``); past the last HMM frame the last
    state holds."""
    position = np.arange(n_frames) * ratio
    if convention == "floor":
        index = np.floor(position + _EPS)
    elif convention == "nearest":
        index = np.floor(position + 0.5 + _EPS)
    elif convention == "ceil":
        index = np.ceil(position - _EPS)
    else:
        raise ValueError(f"unknown convention {convention!r}; known: {CONVENTIONS}")
    return np.asarray(np.asarray(states)[np.minimum(index.astype(np.int64), len(states) - 1)])


def aperture_of(frames: np.ndarray, channels: Sequence[str]) -> np.ndarray:
    """The lip aperture of ``frames``; a coded error when ``channels`` lack it."""
    aperture = lip_aperture(frames, channels)
    if aperture is None:
        raise LipstreamError(
            "no lip aperture (jawOpen and mouthClose) in the channels",
            where="channels",
            code="invalid_model",
        )
    return aperture


def decoded(
    model: HmmModel, phones: Sequence[PhonemeSpan], fps: float, emotion: str | None
) -> tuple[np.ndarray, np.ndarray]:
    """The engine's frames of ``phones`` on the offline rung, and the HMM frames' states."""
    synthesizer = model.start(SynthesisRequest(fps=fps, emotion=emotion, options=OFFLINE))
    if not isinstance(synthesizer, HmmSynthesizer):
        raise LipstreamError("not an hmm synthesizer", where=model.name, code="invalid_model")
    synthesizer.feed(phones, None)
    frames = synthesizer.finish()
    return frames, synthesizer.states.data[: synthesizer.states.count].copy()


def resynthesized(
    model: HmmModel, states: np.ndarray, duration: float, fps: float, convention: str
) -> np.ndarray:
    """The frames at ``fps`` of the trajectory through ``states`` (HMM frames) solved in one
    piece at the engine's rate, each trajectory frame's state by ``convention``."""
    rate = model.solve_fps(fps)
    n_solved = frame_count(duration, rate)
    curve = solve(
        model.dynamics_at(rate),
        frame_states(states, n_solved, model.hmm_fps / rate, convention),
    )
    rows = [math.floor(i * rate / fps + _EPS) for i in range(frame_count(duration, fps))]
    return model.basis.reconstruct(curve[rows])


def demo_lags(model: HmmModel, heldout: Corpus) -> tuple[dict[str, Any], dict[str, list[float]]]:
    """Per convention, the closure lags and RMS error on the held-out lines; the served
    rungs' (phoneme-driven) beside them. With them, span by span, the lags (s) of the engine's
    own frames offline (``offline``) and on each rung, for pairing with another model's."""
    fps, channels = heldout.fps, heldout.channels
    lags: dict[str, dict[str, list[float]]] = {
        name: {"all": [], **{c: [] for c in CONTEXTS}} for name in CONVENTIONS
    }
    paired: dict[str, list[float]] = {name: [] for name in CONVENTIONS}
    errors: dict[str, list[float]] = {name: [] for name in CONVENTIONS}
    worst = 0.0
    for utterance in heldout.utterances:
        engine, states = decoded(model, utterance.phones, fps, utterance.emotion)
        real = aperture_of(utterance.frames, channels)
        base: list[float] = []
        for name in CONVENTIONS:
            frames = resynthesized(model, states, utterance.phones[-1].end, fps, name)
            if name == "floor":
                worst = max(worst, float(np.max(np.abs(frames - engine))))
            predicted = aperture_of(frames, channels)
            own = []
            for span, context in bilabial_contexts(utterance.phones):
                timed = closure_lags(real, predicted, [span], fps)
                own.extend(timed)
                lags[name][context].extend(timed)
            base = own if name == "floor" else base
            lags[name]["all"].extend(own)
            paired[name].extend(np.subtract(own, base).tolist())
            errors[name].append(rms_error(frames, utterance.frames))
    rungs = {}
    spans = {"offline": lags[OWN]["all"]}
    for rung in model.fidelity_ladder():
        rung_lags, rung_errors = [], []
        for utterance in heldout.utterances:
            options = {**dict(rung.options), "drive": "phonemes"}
            frames = model.synthesize(
                utterance.phones, fps=fps, emotion=utterance.emotion, **options
            ).frames
            real = aperture_of(utterance.frames, channels)
            predicted = aperture_of(frames, channels)
            rung_lags.extend(closure_lags(real, predicted, utterance.phones, fps))
            rung_errors.append(rms_error(frames, utterance.frames))
        rungs[rung.name] = {
            "lag": asdict(summarize_lags(rung_lags)),
            "rms": float(np.mean(rung_errors)),
        }
        spans[rung.name] = rung_lags
    return {
        "lines": len(heldout.utterances),
        "floor_max_abs_diff": worst,
        "conventions": {
            name: {
                "lag": asdict(summarize_lags(lags[name]["all"])),
                "by_context": summarize_contexts(lags[name]),
                "shift_from_floor": asdict(summarize_lags(paired[name])),
                "rms": float(np.mean(errors[name])),
            }
            for name in CONVENTIONS
        },
        "rungs": rungs,
    }, spans


def real_lags(model: HmmModel, real_set: Path) -> tuple[dict[str, Any], list[float]]:
    """Per convention, the lags on the real-face set behind the character and the real lips;
    with them, span by span, the lags (s) of the engine's own frames behind the character."""
    corpus = load_corpus(real_set)
    clips, fps = real_clips(corpus), corpus.fps
    character = [
        character_aperture(clip.phones, len(clip.aperture), fps, seed)
        for seed, clip in enumerate(clips)
    ]
    curves: dict[str, list[np.ndarray]] = {name: [] for name in CONVENTIONS}
    for clip in clips:
        _, states = decoded(model, clip.phones, fps, None)
        for name in CONVENTIONS:
            frames = resynthesized(model, states, clip.phones[-1].end, fps, name)
            aperture = aperture_of(frames, model.channels)
            n = len(clip.aperture)
            padded = np.full(n, aperture[-1])
            padded[: min(n, len(aperture))] = aperture[:n]
            curves[name].append(padded)
    real = [clip.aperture for clip in clips]
    behind = {name: lags_by_context(clips, character, curves[name], fps) for name in CONVENTIONS}
    return {
        "clips": len(clips),
        "fps": fps,
        "conventions": {
            name: {
                "behind_character": summarize_contexts(behind[name]),
                "behind_real": summarize_contexts(lags_by_context(clips, real, curves[name], fps)),
            }
            for name in CONVENTIONS
        },
    }, behind[OWN]["all"]


def paired_shift(lags: Sequence[float], base: Sequence[float]) -> dict[str, Any]:
    """The summary of ``lags`` less ``base``, span by span (the same spans, in order)."""
    if len(lags) != len(base):
        raise LipstreamError(
            f"{len(lags)} closures against {len(base)}: not the same spans",
            where="hmm_closure_lag",
            code="invalid_model",
        )
    return asdict(summarize_lags(np.subtract(lags, base).tolist()))


def measured(
    model: HmmModel, heldout: Corpus, real_set: Path
) -> tuple[dict[str, Any], tuple[dict[str, list[float]], list[float]]]:
    """One model's lags (``demo_lags``, ``real_lags``), and its per-span lags for pairing."""
    demo, demo_spans = demo_lags(model, heldout)
    real, real_spans = real_lags(model, real_set)
    return {"sample_offset": model.sample_offset, "demo": demo, "real": real}, (
        demo_spans,
        real_spans,
    )


def own_lags(found: dict[str, Any]) -> dict[str, Any]:
    """The lags of a model's own frames (``floor``) of a ``measured`` result."""
    demo, real = found["demo"], found["real"]
    return {
        "offline": demo["conventions"][OWN]["lag"],
        "rms": demo["conventions"][OWN]["rms"],
        "rungs": {rung: row["lag"] for rung, row in demo["rungs"].items()},
        "real_behind_character": real["conventions"][OWN]["behind_character"]["all"],
    }


def seed_sweep(
    train: Corpus,
    heldout: Corpus,
    real_set: Path,
    seeds: Sequence[int],
    settings: dict[str, Any],
) -> list[dict[str, Any]]:
    """Per seed, both samplings trained from it with the other hyperparameters of
    ``settings``: their own lags and the paired shift."""
    rows = []
    for seed in seeds:
        found = {}
        for name, offset in (("instant", INSTANT_SAMPLING), ("centre", HOLD_CENTRE)):
            model = HmmEngine(**(settings | {"seed": seed, "sample_offset": offset})).fit(train)
            found[name] = measured(model, heldout, real_set)
        (_, (before_demo, before_real)), (_, (after_demo, after_real)) = (
            found["instant"],
            found["centre"],
        )
        rows.append(
            {
                "seed": seed,
                **{name: own_lags(result) for name, (result, _) in found.items()},
                "shift": {
                    **{k: paired_shift(after_demo[k], before_demo[k]) for k in after_demo},
                    "real_behind_character": paired_shift(after_real, before_real),
                },
            }
        )
    return rows


def seed_mean_shift(shifts: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Per measure, the mean over seeds of the paired shift's mean (ms), its standard error
    across the seeds and the number of seeds."""
    out = {}
    for name in shifts[0]:
        means = [shift[name]["mean_ms"] for shift in shifts if shift[name]["mean_ms"] is not None]
        se = float(np.std(means, ddof=1) / np.sqrt(len(means))) if len(means) > 1 else None
        out[name] = {
            "mean_ms": float(np.mean(means)) if means else None,
            "se_ms": se,
            "count": len(means),
        }
    return out


def run(
    corpus_dir: Path,
    real_set: Path,
    model_dir: Path | None,
    command: str,
    seeds: Sequence[int] = SWEEP_SEEDS,
) -> dict[str, Any]:
    corpus = load_corpus(corpus_dir)
    train, heldout = corpus.split()
    with threadpool_limits(limits=1):
        model = load_model(model_dir) if model_dir else train_engine(train, "hmm")
        if not isinstance(model, HmmModel):
            raise LipstreamError("not an hmm model", where=str(model_dir), code="invalid_model")
        settings = dict(model.manifest.hyperparameters)
        instant, centre = (
            model
            if model.sample_offset == offset
            else HmmEngine(**(settings | {"sample_offset": offset})).fit(train)
            for offset in (INSTANT_SAMPLING, HOLD_CENTRE)
        )
        before, (before_demo, before_real) = measured(instant, heldout, real_set)
        after, (after_demo, after_real) = measured(centre, heldout, real_set)
        sweep = seed_sweep(train, heldout, real_set, seeds, settings)
    shift = {name: paired_shift(after_demo[name], before_demo[name]) for name in after_demo}
    shift["real_behind_character"] = paired_shift(after_real, before_real)
    after["shift_from_instant"] = shift
    return {
        **recorded(command),
        "corpus": {"name": corpus.name, "digest": corpus.digest(), "fps": corpus.fps},
        "model": "trained on the train split" if model_dir is None else str(model_dir),
        "hmm_fps": model.hmm_fps,
        "samplings": {"instant": before, "centre": after},
        "seeds": sweep,
        "seed": settings.get("seed"),
        "seed_mean_shift": seed_mean_shift([shift] + [row["shift"] for row in sweep]),
    }


def format_lags(results: dict[str, Any]) -> str:
    def ms(summary: dict[str, Any]) -> str:
        se = "" if summary["se_ms"] is None else f" ± {summary['se_ms']:.1f}"
        return "n/a" if summary["mean_ms"] is None else f"{summary['mean_ms']:+.1f}{se}"

    lines = []
    for sampling in SAMPLINGS:
        found = results["samplings"][sampling]
        demo, real = found["demo"], found["real"]
        lines.append(
            f"{sampling} (sample_offset {found['sample_offset']:g}): floor reproduces the "
            f"engine to {demo['floor_max_abs_diff']:.1e}"
        )
        for name in CONVENTIONS:
            row, grid = demo["conventions"][name], real["conventions"][name]
            lines.append(
                f"  {name:<8} demo {ms(row['lag'])} (shift {ms(row['shift_from_floor'])}) "
                f"RMS {row['rms']:.5f}; real: behind character "
                f"{ms(grid['behind_character']['all'])}, behind real "
                f"{ms(grid['behind_real']['all'])}"
            )
        for rung, row in demo["rungs"].items():
            lines.append(f"  rung {rung:<12} demo {ms(row['lag'])} RMS {row['rms']:.5f}")
    for label, shift in (
        ("centre less instant, paired", results["samplings"]["centre"]["shift_from_instant"]),
        ("mean over seeds", results["seed_mean_shift"]),
    ):
        lines.append(f"{label}: " + ", ".join(f"{k} {ms(v)}" for k, v in shift.items()))
    for row in results["seeds"]:
        lines.append(
            f"seed {row['seed']}: offline {ms(row['instant']['offline'])} -> "
            f"{ms(row['centre']['offline'])} (paired {ms(row['shift']['offline'])}); real behind "
            f"character {ms(row['instant']['real_behind_character'])} -> "
            f"{ms(row['centre']['real_behind_character'])} "
            f"(paired {ms(row['shift']['real_behind_character'])})"
        )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    parser = real_set_parser(f"python -m {MODULE}", __doc__)
    parser.add_argument("--corpus", type=Path, required=True, help="the demo corpus")
    parser.add_argument("--model", type=Path, help="an hmm model (default: train one)")
    parser.add_argument("--json", type=Path, required=True, help="results file to write")
    parser.add_argument(
        "--seeds",
        type=int,
        nargs="*",
        default=list(SWEEP_SEEDS),
        help="further EM seeds to train both samplings from",
    )
    args = parser.parse_args(argv)
    command = script_command(MODULE, argv)
    results = run(args.corpus, args.real, args.model, command, args.seeds)
    write_results(results, args.json)
    print(format_lags(results))


if __name__ == "__main__":
    main()
