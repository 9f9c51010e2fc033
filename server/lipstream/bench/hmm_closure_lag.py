"""Why phoneme-driven `hmm` closes the lips late: which trajectory frame takes which state.

Sketch: the facial HMM is trained on the curves sampled at the instants j / R (R =
``hmm_fps``, ``engine.observations``), so state j of a decoded sequence stands for the pose
at j / R and for the backward difference over ((j − 1) / R, j / R]. The synthesizer solves
the trajectory at a rate f above R and gives trajectory frame k (at k / f) the state of HMM
frame ⌊k R / f⌋ (``synthesizer.hmm_frame``): every state is held over [j / R, (j + 1) / R),
after the instant it stands for, so the targets arrive on average (1 / R − 1 / f) / 2 late
(8.3 ms at R = 40 Hz, f = 120 Hz) and the velocity targets another as much.

Each line is decoded once, driven by phonemes alone on the offline rung (Viterbi over the
whole line, one solve; ``floor_max_abs_diff`` checks that the ``floor`` convention
reproduces the engine's frames), and its trajectory solved at the engine's rate with the
state of frame k taken three ways (``CONVENTIONS``): ``floor`` (the engine's), ``nearest``
(the HMM frame whose instant is nearest, ⌊k R / f + ½⌋) and ``ceil`` (⌈k R / f⌉, the first
HMM frame whose backward difference covers the frame's). Closure lags are timed as
``evaluation.closure_lags`` times them: on the demo corpus's held-out lines against their
recordings (with the RMS error), and on the real-face set behind the demo character
(``closure_sources.character_aperture``) and behind the real lips. The served rungs'
closure lag on the held-out lines shows whether the decoder's lag adds to it.

``python -m lipstream.bench.hmm_closure_lag --corpus DIR --json bench/hmm_closure_lag.json``
"""

from __future__ import annotations

import argparse
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
from ..engines.hmm.model import HmmModel
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
from .demo_calibration import REAL_SET
from .real_faces import real_clips

MODULE = "lipstream.bench.hmm_closure_lag"
CONVENTIONS = ("floor", "nearest", "ceil")
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


def demo_lags(model: HmmModel, heldout: Corpus) -> dict[str, Any]:
    """Per convention, the closure lags and RMS error on the held-out lines; the served
    rungs' (phoneme-driven) beside them."""
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
    }


def real_lags(model: HmmModel, real_set: Path) -> dict[str, Any]:
    """Per convention, the lags on the real-face set behind the character and the real lips."""
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
    return {
        "clips": len(clips),
        "fps": fps,
        "conventions": {
            name: {
                "behind_character": summarize_contexts(
                    lags_by_context(clips, character, curves[name], fps)
                ),
                "behind_real": summarize_contexts(lags_by_context(clips, real, curves[name], fps)),
            }
            for name in CONVENTIONS
        },
    }


def run(corpus_dir: Path, real_set: Path, model_dir: Path | None, command: str) -> dict[str, Any]:
    corpus = load_corpus(corpus_dir)
    train, heldout = corpus.split()
    with threadpool_limits(limits=1):
        model = load_model(model_dir) if model_dir else train_engine(train, "hmm")
        if not isinstance(model, HmmModel):
            raise LipstreamError("not an hmm model", where=str(model_dir), code="invalid_model")
        return {
            **recorded(command),
            "corpus": {"name": corpus.name, "digest": corpus.digest(), "fps": corpus.fps},
            "model": "trained on the train split" if model_dir is None else str(model_dir),
            "hmm_fps": model.hmm_fps,
            "demo": demo_lags(model, heldout),
            "real": real_lags(model, real_set),
        }


def format_lags(results: dict[str, Any]) -> str:
    def ms(summary: dict[str, Any]) -> str:
        se = "" if summary["se_ms"] is None else f" ± {summary['se_ms']:.1f}"
        return "n/a" if summary["mean_ms"] is None else f"{summary['mean_ms']:+.1f}{se}"

    demo, real = results["demo"], results["real"]
    lines = [f"floor reproduces the engine to {demo['floor_max_abs_diff']:.1e}"]
    for name in CONVENTIONS:
        row, grid = demo["conventions"][name], real["conventions"][name]
        lines.append(
            f"{name:<8} demo {ms(row['lag'])} (shift {ms(row['shift_from_floor'])}) "
            f"RMS {row['rms']:.5f}; real: behind character {ms(grid['behind_character']['all'])}"
            f", behind real {ms(grid['behind_real']['all'])}"
        )
    for rung, row in demo["rungs"].items():
        lines.append(f"rung {rung:<12} demo {ms(row['lag'])} RMS {row['rms']:.5f}")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog=f"python -m {MODULE}", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--corpus", type=Path, required=True, help="the demo corpus")
    parser.add_argument("--real", type=Path, default=REAL_SET, help="real-face corpus")
    parser.add_argument("--model", type=Path, help="an hmm model (default: train one)")
    parser.add_argument("--json", type=Path, required=True, help="results file to write")
    args = parser.parse_args(argv)
    results = run(args.corpus, args.real, args.model, script_command(MODULE, argv))
    write_results(results, args.json)
    print(format_lags(results))


if __name__ == "__main__":
    main()
