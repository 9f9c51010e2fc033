"""The ``hmm`` engine's own figures for ``lipstream bench`` (Brand 1999's evaluation).

On the train split (one BLAS thread): the entropic model and a Baum-Welch model
from the same initialization, with their perplexity, held-out entropy rate and
surviving states. For each of the training lines (at most ``TRAIN_LINES``)
and the held-out lines: Brand's Err (Eq. 7) and the RMS against the recorded
curves of the reconstruction from the facial state sequence (Viterbi on the
recorded [pose, velocity], then Eq. 5–6), and of synthesis driven by voice
alone, by phonemes, by both, and of ``viseme-lerp``. Err is taken per line
over its motion relative to the training mean face, Σ_t |x_t − y_t|² / Σ_t
|x_t + y_t|² (Brand's ratio with the line's frames as one vector; per frame,
frames near the mean face would divide by nearly nothing). Speed: voice-driven
synthesis of every held-out line at 60 fps, speech features included, as a
real-time factor (audio seconds per CPU second of the process, one BLAS
thread; the median of ``SPEED_RUNS`` passes), offline (``lag_ms`` and
``window_ms`` null, the paper's whole-utterance method) and on each rung; and
the first-frame latency of a request fed audio alone in 10 ms chunks as if
live, in process: the audio it needed before its first frame and the time of
that call (over a real WebSocket: ``lipstream.bench.hmm_first_frame``).

The speed figures alone, on the demo corpus (its entropic model trained on the
train split, or ``--model``):

    python -m lipstream.bench.hmm [--corpus DIR] [--model DIR] [--runs 5]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ..audio import Audio
from ..config import load_settings
from ..corpus import Corpus, Utterance, load_corpus
from ..engines import load_model
from ..engines.base import Model
from ..engines.hmm import HmmEngine, HmmModel
from ..engines.hmm.em import BAUM_WELCH
from ..engines.hmm.engine import observations
from ..engines.hmm.synthesizer import hmm_frame
from ..engines.hmm.trajectory import solve
from ..engines.viseme_lerp import VisemeLerpEngine
from ..numerics.trellis import viterbi
from ..training import DEMO_CORPUS_DIR

TRAIN_LINES = 30
SPEED_RUNS = 5
FPS = 60.0
CHUNK_S = 0.01
PAPER = {"state sequence": (0.1255, 0.1698), "vocal features": (0.1731, 0.2115)}


def brand_error(recorded: np.ndarray, synthesized: np.ndarray, mean: np.ndarray) -> float:
    """Eq. 7 over a line's motion relative to ``mean``."""
    n = min(len(recorded), len(synthesized))
    x, y = recorded[:n] - mean, synthesized[:n] - mean
    return float(np.sum((x - y) ** 2) / max(float(np.sum((x + y) ** 2)), 1e-12))


def reconstruction(model: HmmModel, utterance: Utterance) -> np.ndarray:
    """The line rebuilt from the Viterbi states of its own recorded curves."""
    seen = observations(utterance, model.basis, model.hmm_fps, model.sample_offset)
    path, _ = viterbi(model.log_start, model.log_transition, model.facial.log_density(seen))
    frames = np.arange(utterance.n_frames)
    ratio = model.hmm_fps / model.synthesis_fps
    states = path[np.minimum(hmm_frame(frames, ratio), len(path) - 1)]
    return model.basis.reconstruct(solve(model.dynamics, states))


def _methods(model: HmmModel, lerp: Model) -> dict[str, Callable[[Utterance], np.ndarray]]:
    def at(u: Utterance) -> dict[str, Any]:
        return {"fps": u.fps, "emotion": u.emotion}

    return {
        "state sequence": lambda u: reconstruction(model, u),
        "vocal features": lambda u: model.synthesize([], audio=u.audio, **at(u)).frames,
        "phonemes": lambda u: model.synthesize(u.phones, **at(u)).frames,
        "phonemes + voice": lambda u: model.synthesize(u.phones, audio=u.audio, **at(u)).frames,
        "viseme-lerp": lambda u: lerp.synthesize(u.phones, **at(u)).frames,
    }


def _errors(
    methods: dict[str, Callable[[Utterance], np.ndarray]], lines: list[Utterance], mean: np.ndarray
) -> dict[str, dict[str, float]]:
    table: dict[str, dict[str, float]] = {}
    for name, method in methods.items():
        err, rms = [], []
        for utterance in lines:
            frames = np.asarray(method(utterance), dtype=np.float64)
            n = min(len(frames), utterance.n_frames)
            err.append(brand_error(utterance.frames, frames, mean))
            rms.append(float(np.sqrt(np.mean((frames[:n] - utterance.frames[:n]) ** 2))))
        table[name] = {"err": float(np.mean(err)), "rms": float(np.mean(rms))}
    return table


def real_time_factor(
    model: HmmModel, lines: list[Utterance], options: dict[str, Any], runs: int = SPEED_RUNS
) -> float:
    """Audio seconds of ``lines`` synthesized from their voice per CPU second (the median
    pass of ``runs``, after one warm-up)."""
    audio_s = sum(u.audio.duration for u in lines if u.audio is not None)
    passes = []
    for _ in range(runs + 1):
        started = time.process_time()
        for utterance in lines:
            model.synthesize([], FPS, utterance.audio, utterance.emotion, **options)
        passes.append(time.process_time() - started)
    return audio_s / max(statistics.median(passes[1:]), 1e-9)


def speeds(model: HmmModel, lines: list[Utterance], runs: int = SPEED_RUNS) -> dict[str, float]:
    """``real_time_factor`` offline (the whole-utterance method) and on every rung."""
    voiced = [u for u in lines if u.audio is not None]
    found = {"offline": real_time_factor(model, voiced, {"lag_ms": None, "window_ms": None}, runs)}
    for rung in model.fidelity_ladder():
        found[rung.name] = real_time_factor(model, voiced, dict(rung.options), runs)
    return found


def _first_frame(model: HmmModel, audio: Audio, options: dict[str, Any]) -> dict[str, float]:
    synthesizer = model.start(fps=FPS, **options)
    step = max(1, round(CHUNK_S * audio.sample_rate))
    for first in range(0, len(audio.samples), step):
        chunk = Audio(audio.samples[first : first + step], audio.sample_rate)
        started = time.perf_counter()
        synthesizer.feed([], chunk)
        frames = synthesizer.frames()
        elapsed = time.perf_counter() - started
        if len(frames):
            heard = (first + len(chunk.samples)) / audio.sample_rate
            return {"audio_needed_ms": 1000.0 * heard, "call_ms": 1000.0 * elapsed}
    return {"audio_needed_ms": float("nan"), "call_ms": float("nan")}


def _training_figures(model: HmmModel, fit_s: float) -> dict[str, Any]:
    metrics = model.manifest.metrics
    return {
        "fit_s": fit_s,
        "states": metrics["states"],
        "states_initial": metrics["states_initial"],
        "transitions": metrics["transitions"],
        "perplexity": metrics["perplexity"],
        "heldout_entropy_rate_bits": metrics["heldout_entropy_rate_bits"],
        "log_posterior": metrics["log_posterior"],
    }


def run_hmm_bench(corpus: Corpus) -> dict[str, Any]:
    train, heldout = corpus.split()
    results: dict[str, Any] = {"estimators": {}}
    with threadpool_limits(limits=1):
        models: dict[str, HmmModel] = {}
        for engine in (HmmEngine(), HmmEngine(estimator=BAUM_WELCH)):
            started = time.perf_counter()
            models[engine.estimator] = engine.fit(train)
            figures = _training_figures(models[engine.estimator], time.perf_counter() - started)
            results["estimators"][engine.estimator] = figures
        model = models["entropic"]
        lerp = VisemeLerpEngine().fit(train)
        mean = np.concatenate([u.frames for u in train.utterances]).mean(axis=0)
        step = max(1, len(train.utterances) // TRAIN_LINES)
        lines = {"train": train.utterances[::step], "heldout": heldout.utterances}
        results["errors"] = {
            split: _errors(_methods(model, lerp), chosen, mean) for split, chosen in lines.items()
        }
        results["baum_welch_errors"] = _errors(
            {"vocal features": _methods(models[BAUM_WELCH], lerp)["vocal features"]},
            heldout.utterances,
            mean,
        )
        voiced = [u for u in heldout.utterances if u.audio is not None]
        first_audio = voiced[0].audio
        assert first_audio is not None
        results["real_time_factor"] = speeds(model, voiced)
        latency = {}
        for rung in model.fidelity_ladder():
            latency[rung.name] = _first_frame(model, first_audio, dict(rung.options))
        results["first_frame"] = latency
    return results


def format_hmm_bench(results: dict[str, Any]) -> str:
    lines = ["estimator    states  transitions  perplexity  held-out entropy rate (bits)  fit s"]
    for name, figures in results["estimators"].items():
        lines.append(
            f"{name:<12} {figures['states']:>3}/{figures['states_initial']:<3} "
            f"{figures['transitions']:>11}  {figures['perplexity']:>10.3f}  "
            f"{figures['heldout_entropy_rate_bits']:>28.4f}  {figures['fit_s']:>5.1f}"
        )
    lines.append("")
    lines.append("method            Err train  Err held-out  RMS train  RMS held-out  paper Err")
    train, held = results["errors"]["train"], results["errors"]["heldout"]
    for name in held:
        paper = PAPER.get(name)
        quoted = f"{paper[0]:.4f}/{paper[1]:.4f}" if paper else ""
        lines.append(
            f"{name:<17} {train[name]['err']:>9.4f}  {held[name]['err']:>12.4f}  "
            f"{train[name]['rms']:>9.4f}  {held[name]['rms']:>12.4f}  {quoted}"
        )
    lines.append("")
    lines.append(_speed_line(results["real_time_factor"]))
    for name, figures in results["first_frame"].items():
        lines.append(
            f"first frame, {name}: after {figures['audio_needed_ms']:.0f} ms of audio, "
            f"call {figures['call_ms']:.2f} ms"
        )
    return "\n".join(lines)


def _speed_line(found: dict[str, float]) -> str:
    figures = ", ".join(f"{k} {v:,.0f}x" for k, v in found.items())
    return f"voice-driven real-time factor (features included, one core): {figures}"


def main(argv: list[str] | None = None) -> int:
    settings = load_settings()
    parser = argparse.ArgumentParser(description="hmm voice-driven real-time factor")
    parser.add_argument("--corpus", type=Path, default=settings.demo_dir / DEMO_CORPUS_DIR)
    parser.add_argument("--model", type=Path, default=None, help="default: train on the split")
    parser.add_argument("--runs", type=int, default=SPEED_RUNS)
    parser.add_argument("--json", action="store_true", help="print JSON instead of a line")
    args = parser.parse_args(argv)
    train, heldout = load_corpus(args.corpus).split()
    with threadpool_limits(limits=1):
        model = load_model(args.model) if args.model else HmmEngine().fit(train)
        assert isinstance(model, HmmModel)
        found = speeds(model, heldout.utterances, args.runs)
    print(json.dumps(found, indent=2) if args.json else _speed_line(found))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
