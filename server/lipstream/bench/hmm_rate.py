"""How ``hmm``'s frame rate moves its closures on real phones, its quality and its cost.

Sketch: ``hmm`` is trained on the demo corpus's train split at each HMM frame rate of
``--rates`` (``hmm_fps``), with the demo model's other hyperparameters, from each EM seed of
``--seeds``. What is counted in HMM frames is scaled with the rate so that it means the same
time: ``max_training_frames`` the same seconds of speech as the demo model's, and the speaker
prior's ``prior_frames`` the same seconds of speech frames. Each model is then

- driven by phonemes on the held-out lines on every rung (``hmm.model.RUNGS``): closure
  lag (plateau centre less the recording's, ``closure_timing.time_frames``) and RMS;
- driven by the held-out lines' audio alone (``full`` rung): RMS as a ratio to
  ``viseme-lerp``'s from the phonemes, the unseen-voice measure of ``hmm_voices``;
- run on the real-face set's force-aligned phones (``full`` rung): closure lag behind the
  character rendered on them and behind the real lips (``closure_sources.RealPhones``), and
  lip-aperture r against the real lips (Pearson r over each clip's speech frames, averaged
  over the clips, as ``bench --real`` scores it);
- timed: CPU seconds to fit, and CPU seconds per second of speech to synthesize from audio
  (``time.process_time``, one thread). Machines differ, so the report gives each rate's
  CPU as a ratio to the first rate's in the same run.

``python -m lipstream.bench.hmm_rate --home DIR --json bench/hmm_rate.json``
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ..corpus import Corpus, load_corpus
from ..engines import load_model
from ..engines.hmm.engine import HmmEngine
from ..engines.hmm.model import RUNGS, HmmModel
from ..evaluation import rms_error
from ..results_file import recorded, script_command, write_results
from .bilabial_lead_sweep import frames_on, rung_options, timed
from .closure_sources import RealPhones
from .real_set import real_set_parser

MODULE = "lipstream.bench.hmm_rate"
RATES = (40.0, 60.0, 80.0, 100.0)
SEEDS = (0, 1, 2, 3)
FULL = RUNGS[0][0]


def settings_at(base: dict[str, Any], rate: float, seed: int) -> dict[str, Any]:
    """``base`` (the hyperparameters of a model trained at ``base['hmm_fps']``) at HMM frame
    rate ``rate`` and EM seed ``seed``, its frame counts scaled to the same seconds."""
    scale = rate / float(base["hmm_fps"])
    return base | {
        "hmm_fps": rate,
        "seed": seed,
        "max_training_frames": round(int(base["max_training_frames"]) * scale),
        "prior_frames": float(base["prior_frames"]) * scale,
    }


def baseline_rms(model: Any, heldout: Corpus) -> float:
    """Mean RMS over ``heldout``'s lines of ``model`` driven by their phonemes."""
    pairs = zip(frames_on(model, heldout), heldout.utterances, strict=True)
    return float(np.mean([rms_error(frames, line.frames) for frames, line in pairs]))


def voice_rms(model: HmmModel, heldout: Corpus) -> tuple[float, float]:
    """Mean RMS over ``heldout``'s lines of ``model`` driven by their audio alone (``full``
    rung), and the CPU seconds it took per second of speech."""
    errors, spent = [], 0.0
    for line in heldout.utterances:
        started = time.process_time()
        frames = model.synthesize(
            [], fps=heldout.fps, audio=line.audio, emotion=line.emotion, drive="audio"
        ).frames
        spent += time.process_time() - started
        n = min(len(frames), len(line.frames))
        errors.append(rms_error(frames[:n], line.frames[:n]))
    speech_s = sum(line.duration for line in heldout.utterances)
    return float(np.mean(errors)), spent / speech_s


def measure(
    settings: dict[str, Any],
    corpora: tuple[Corpus, Corpus],
    real: RealPhones,
    reference_rms: float,
) -> dict[str, Any]:
    """One model trained with ``settings`` on the train split, measured as the sketch says."""
    train, heldout = corpora
    started = time.process_time()
    model = HmmEngine(**settings).fit(train)
    fit_cpu_s = time.process_time() - started
    assert isinstance(model, HmmModel)
    rungs = {
        name: timed(frames_on(model, heldout, **rung_options(name)), heldout)
        for name, _, _ in RUNGS
    }
    voice, voice_cpu = voice_rms(model, heldout)
    found = real.timed(model)
    return {
        "hmm_fps": model.hmm_fps,
        "seed": settings["seed"],
        "states": model.manifest.metrics.get("states"),
        "rungs": {name: {"lag_ms": r["lag_ms"], "rms": r["rms"]} for name, r in rungs.items()},
        "voice_rms_ratio": voice / reference_rms,
        "real_phones_lag_ms": found["behind_character"]["mean_ms"],
        "real": found["behind_real"],
        "aperture_r": found["aperture_r"],
        "fit_cpu_s": fit_cpu_s,
        "voice_cpu_per_speech_s": voice_cpu,
    }


def rate_means(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per rate, the figures averaged over its seeds, with the real lag's least and most."""
    means = []
    for rate in sorted({row["hmm_fps"] for row in rows}):
        chosen = [row for row in rows if row["hmm_fps"] == rate]

        def mean(key: str, of: Sequence[Any]) -> float:
            return float(np.mean([value[key] for value in of]))

        real = [row["real"]["mean_ms"] for row in chosen]
        means.append(
            {
                "hmm_fps": rate,
                "seeds": len(chosen),
                "rungs": {
                    name: {
                        key: mean(key, [row["rungs"][name] for row in chosen])
                        for key in ("lag_ms", "rms")
                    }
                    for name in chosen[0]["rungs"]
                },
                "real_phones_lag_ms": mean("real_phones_lag_ms", chosen),
                "real_lag_ms": float(np.mean(real)),
                "real_lag_min_ms": float(np.min(real)),
                "real_lag_max_ms": float(np.max(real)),
                **{
                    key: mean(key, chosen)
                    for key in (
                        "voice_rms_ratio",
                        "aperture_r",
                        "fit_cpu_s",
                        "voice_cpu_per_speech_s",
                    )
                },
            }
        )
    return means


def run(
    home: Path,
    real_set: Path,
    rates: Sequence[float],
    seeds: Sequence[int],
    command: str,
) -> dict[str, Any]:
    corpus = load_corpus(home / "demo" / "corpus")
    corpora = corpus.split()
    real = RealPhones.load(real_set)
    with threadpool_limits(limits=1):
        built = load_model(home / "demo" / "models" / "hmm")
        base = dict(built.manifest.hyperparameters)
        reference = baseline_rms(load_model(home / "demo" / "models" / "viseme-lerp"), corpora[1])
        rows = [
            measure(settings_at(base, rate, seed), corpora, real, reference)
            for rate in rates
            for seed in seeds
        ]
    return {
        **recorded(command),
        "corpus": {"name": corpus.name, "digest": corpus.digest(), "fps": corpus.fps},
        "real_set": {"name": real.name, "clips": len(real.clips), "fps": real.fps},
        "default_hmm_fps": HmmEngine().hyperparameters()["hmm_fps"],
        "seeds": list(seeds),
        "rungs": [name for name, _, _ in RUNGS],
        "runs": rows,
        "rates": rate_means(rows),
    }


def format_rates(results: dict[str, Any]) -> str:
    lines = []
    for row in results["rates"]:
        full = row["rungs"][FULL]
        lines.append(
            f"{row['hmm_fps']:g} Hz: real lag {row['real_lag_ms']:+.1f} ms"
            f" ({row['real_lag_min_ms']:+.1f} .. {row['real_lag_max_ms']:+.1f}),"
            f" behind the character {row['real_phones_lag_ms']:+.1f} ms, aperture r"
            f" {row['aperture_r']:.3f}; held-out lag {full['lag_ms']:+.1f} ms, RMS"
            f" {full['rms']:.5f}; voice {row['voice_rms_ratio']:.3f} of viseme-lerp;"
            f" fit {row['fit_cpu_s']:.1f} s CPU"
        )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    parser = real_set_parser(f"python -m {MODULE}", __doc__, home=True)
    parser.add_argument(
        "--rates", type=float, nargs="+", default=list(RATES), help="HMM frame rates, Hz"
    )
    parser.add_argument(
        "--seeds", type=int, nargs="+", default=list(SEEDS), help="EM seeds to train hmm from"
    )
    parser.add_argument("--json", type=Path, required=True, help="results file to write")
    args = parser.parse_args(argv)
    results = run(args.home, args.real, args.rates, args.seeds, script_command(MODULE, argv))
    write_results(results, args.json)
    print(format_rates(results))


if __name__ == "__main__":
    main()
