"""Voice-driven ``hmm`` on voices and characters it was not trained on (issue 24 §5).

Sketch: each configuration of the ``hmm`` engine (raw or speaker-normalized speech
features; the demo lines as the demo speaks them, or spoken again in
``demo.voices.TRAINING_VOICES`` too) is trained on the demo corpus's train split, with
``viseme-lerp`` trained on the same lines as the baseline. Each is driven by audio alone
(on the ``full``, ``causal_lead`` and ``causal`` rungs) and scored by RMS against the recorded
curves, as a ratio to ``viseme-lerp``'s RMS fed the true phones, on:

- **demo**: the demo corpus's held-out lines;
- **second character**: ``SECOND_LINES`` lines of a generated character with its own
  articulation, rate, pitch and voice (``SECOND_CHARACTER``), its held-out lines, by the
  demo-trained models; and, as issue 24 first measured it, by models trained on the
  character's own train split (``self-trained``), beside a ``viseme-lerp`` trained there;
- **held-out voice**: the demo's held-out lines spoken in ``HELDOUT_VOICE``, which no
  training line is spoken in;
- **real speech**: the GRID clips that ship their sound (``swwp2s.mp4``, the others'
  ``clips/<stem>.ogg``; ``bench.aligner_real.grid_sound``), the aperture r
  (``bench.real_faces``) of the audio-driven face against the tracked lips, beside
  ``viseme-lerp`` fed the clip's force-aligned phones, clip by clip and as the mean over
  the clips.

Phoneme-driven ``hmm`` (``full`` and ``causal``) is reported beside the voice-driven
one: a gap between them is the audio side's. Vocal-tract-length warping is measured on
the last configuration: each line analysed at every warp of ``features.WARPS``
(``features.warped``), the warp its whole audio makes most likely under the model's
vocal Gaussians (an equal mixture, ``features.most_likely_warp``) chosen per line, which
a stream could only choose once it has heard the line (more than a causal choice
knows), and each fixed warp for all lines. One BLAS thread.

    python -m lipstream.bench.hmm_voices [--corpus DIR] [--grid DIR] [--results FILE]
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.special import logsumexp
from threadpoolctl import threadpool_limits

from ..audio import Audio
from ..config import load_settings
from ..corpus import EMOTIONS, Corpus, Utterance, load_corpus
from ..demo.face import DEMO_CHANNELS
from ..demo.generate import (
    DemoUtterancePlan,
    build_demo_utterance,
    demo_stem,
    heldout_indices,
    plan_demo_utterances,
    synthesizer_for,
)
from ..demo.sentences import load_sentences
from ..demo.speakers import Speaker
from ..demo.speech_batch import speak_batch
from ..demo.voices import HELDOUT_VOICE, TRAINING_VOICES, revoiced_utterances
from ..engines.base import Model
from ..engines.hmm import HmmEngine, HmmModel
from ..engines.viseme_lerp import VisemeLerpEngine
from ..evaluation import lip_aperture
from ..features import WARPS, most_likely_warp, speech_features, warped
from ..results_file import recorded, write_results
from ..training import DEMO_CORPUS_DIR
from .aligner_real import grid_sound, read_sound
from .real_faces import Clip, pearson_r, real_clips

SECOND_CHARACTER = Speaker(
    "zed",
    9001,
    voice="en-us+m7",
    pitch=30,
    rate_factor=1.25,
    jaw_scale=1.35,
    lips_scale=0.8,
    rounding_scale=1.3,
    spread_scale=0.8,
    rest_jaw=0.05,
    stiffness_scale=1.3,
    lookahead_s=0.2,
)
"""Neither its voice (``+m7``, low pitch, fast) nor its articulation is the demo's."""
SECOND_LINES = 120
GRID_DIR = Path("tests/data/grid")
CAUSAL_LEAD = {"lag_ms": 100.0, "window_ms": 0.0}
CAUSAL = {"lag_ms": 0.0, "window_ms": 0.0}
"""The ``causal_lead`` and ``causal`` rungs' options: frame at a time, decoded 100 ms late
or at once (greedy)."""
CONFIGURATIONS: dict[str, tuple[bool, bool]] = {  # name: (speaker normalization, more voices)
    "raw features, demo voices": (False, False),
    "normalized, demo voices": (True, False),
    "raw features, demo + 3 voices": (False, True),
    "normalized, demo + 3 voices": (True, True),
}


def second_character(n_lines: int = SECOND_LINES, fps: float = 120.0) -> Corpus:
    """``n_lines`` demo sentences spoken and performed by ``SECOND_CHARACTER`` alone."""
    plans = [
        DemoUtterancePlan(
            index, demo_stem(index), sentence, EMOTIONS[index % len(EMOTIONS)], SECOND_CHARACTER
        )
        for index, sentence in enumerate(load_sentences()[:n_lines])
    ]
    speech = speak_batch([(synthesizer_for(p.speaker, p.emotion), p.sentence) for p in plans])
    utterances = [build_demo_utterance(plan, said, fps) for plan, said in zip(plans, speech)]
    heldout = tuple(plans[index].stem for index in heldout_indices(len(plans)))
    return Corpus(
        name="second", fps=fps, channels=DEMO_CHANNELS, utterances=utterances, heldout=heldout
    )


def _plans(corpus: Corpus, stems: set[str]) -> list[DemoUtterancePlan]:
    plans = plan_demo_utterances(load_sentences()[: len(corpus.utterances)])
    return [plan for plan in plans if plan.stem in stems]


def rms_figures(hmm: Model, lerp: Model, lines: list[Utterance]) -> dict[str, float]:
    """Mean per-line RMS of ``hmm`` by audio and by phonemes and of ``lerp`` by phonemes, and
    the voice-driven ratio to ``lerp``."""
    drives: dict[str, Callable[[Utterance], np.ndarray]] = {
        "audio": lambda u: hmm.synthesize([], u.fps, u.audio, u.emotion).frames,
        "audio_causal_lead": lambda u: (
            hmm.synthesize([], u.fps, u.audio, u.emotion, **CAUSAL_LEAD).frames
        ),
        "audio_causal": lambda u: hmm.synthesize([], u.fps, u.audio, u.emotion, **CAUSAL).frames,
        "phonemes_causal": lambda u: (
            hmm.synthesize(u.phones, u.fps, None, u.emotion, **CAUSAL).frames
        ),
        "phonemes": lambda u: hmm.synthesize(u.phones, u.fps, None, u.emotion).frames,
        "viseme_lerp": lambda u: lerp.synthesize(u.phones, u.fps, None, u.emotion).frames,
    }
    found: dict[str, float] = {}
    for name, drive in drives.items():
        errors = []
        for utterance in lines:
            frames = np.asarray(drive(utterance), dtype=np.float64)
            n = min(len(frames), utterance.n_frames)
            errors.append(float(np.sqrt(np.mean((frames[:n] - utterance.frames[:n]) ** 2))))
        found[f"rms_{name}"] = float(np.mean(errors))
    found["audio_ratio"] = found["rms_audio"] / found["rms_viseme_lerp"]
    for rung_drive in ("audio_causal_lead", "audio_causal", "phonemes_causal"):
        found[f"{rung_drive}_ratio"] = found[f"rms_{rung_drive}"] / found["rms_viseme_lerp"]
    found["phonemes_ratio"] = found["rms_phonemes"] / found["rms_viseme_lerp"]
    return found


def _aperture_r(model: Model, frames: np.ndarray, clip: Clip) -> float | None:
    aperture = lip_aperture(np.asarray(frames), model.channels)
    assert aperture is not None
    padded = np.full(len(clip.aperture), aperture[-1])
    padded[: min(len(padded), len(aperture))] = aperture[: len(padded)]
    return pearson_r(padded[clip.speech], clip.aperture[clip.speech])


def grid_figures(
    hmm: Model, lerp: Model, clip: Clip, audio: Audio, fps: float
) -> dict[str, float | None]:
    """Aperture r of the voice- and phoneme-driven ``hmm`` and of ``lerp`` by phonemes."""
    return {
        "hmm_audio_r": _aperture_r(hmm, hmm.synthesize([], fps, audio).frames, clip),
        "hmm_phonemes_r": _aperture_r(hmm, hmm.synthesize(clip.phones, fps).frames, clip),
        "viseme_lerp_r": _aperture_r(lerp, lerp.synthesize(clip.phones, fps).frames, clip),
    }


def _warped_model(model: HmmModel, warp: float) -> HmmModel:
    """``model`` analysing its audio with the filterbank moved by ``warp``."""
    twin = copy.copy(model)
    twin.mfcc = warped(model.mfcc, warp)
    return twin


def _mixture(model: HmmModel) -> Callable[[np.ndarray], np.ndarray]:
    """log of an equal mixture of the model's vocal Gaussians over one stream's normalized
    features."""
    vocal = model.vocal
    assert vocal is not None

    def log_likelihood(rows: np.ndarray) -> np.ndarray:
        normalizer = model.normalizer()
        heard = rows if normalizer is None else normalizer.apply(rows)
        return np.asarray(logsumexp(vocal.log_density(heard), axis=1))

    return log_likelihood


def warp_figures(
    model: HmmModel,
    lerp: Model,
    sets: dict[str, list[Utterance]],
    sounded: list[tuple[Clip, Audio]],
    grid_fps: float,
) -> dict[str, Any]:
    """Voice-driven ratios with each line at its most likely warp, and at each fixed warp."""
    twins = {warp: _warped_model(model, warp) for warp in WARPS}
    score = _mixture(model)

    def chosen(audio: Audio) -> float:
        return most_likely_warp(
            audio.samples, audio.sample_rate, model.mfcc, score, WARPS, speech_features
        )

    found: dict[str, Any] = {"warps": list(WARPS), "fixed": {}, "most_likely": {}, "grid": {}}
    for name, lines in sets.items():
        picks = [chosen(u.audio) for u in lines if u.audio is not None]
        errors = []
        for utterance, warp in zip(lines, picks, strict=True):
            frames = twins[warp].synthesize([], utterance.fps, utterance.audio, utterance.emotion)
            n = min(len(frames.frames), utterance.n_frames)
            errors.append(float(np.sqrt(np.mean((frames.frames[:n] - utterance.frames[:n]) ** 2))))
        baseline = rms_figures(model, lerp, lines)["rms_viseme_lerp"]
        found["most_likely"][name] = {
            "audio_ratio": float(np.mean(errors)) / baseline,
            "warps_chosen": {f"{w:g}": picks.count(w) for w in WARPS if picks.count(w)},
        }
        found["fixed"][name] = {
            f"{warp:g}": rms_figures(twin, lerp, lines)["audio_ratio"]
            for warp, twin in twins.items()
        }
    for clip, audio in sounded:
        warp = chosen(audio)
        found["grid"][clip.stem] = {
            "warp": warp,
            "hmm_audio_r": grid_figures(twins[warp], lerp, clip, audio, grid_fps)["hmm_audio_r"],
        }
    found["grid_mean"] = mean_figures(found["grid"].values())
    return found


def mean_figures(clips: Iterable[dict[str, Any]]) -> dict[str, Any]:
    """Per figure of ``clips`` (each a dict of r values, None where r is undefined) the
    mean over the clips where it is defined, with how many clips that is."""
    rows = list(clips)
    names = sorted({name for row in rows for name in row if name.endswith("_r")})
    found: dict[str, Any] = {"clips": len(rows)}
    for name in names:
        known = [row[name] for row in rows if row.get(name) is not None]
        found[name] = float(np.mean(known)) if known else None
    return found


def _grid_with_sound(grid_dir: Path) -> tuple[Corpus, list[tuple[Clip, Audio]]]:
    corpus = load_corpus(grid_dir / "corpus")
    found = []
    for clip in real_clips(corpus):
        sound = grid_sound(grid_dir, clip.stem)
        if sound is not None:
            found.append((clip, read_sound(sound)))
    return corpus, found


def run_hmm_voices(corpus: Corpus, grid_dir: Path, command: list[str]) -> dict[str, Any]:
    began = time.perf_counter()
    train, heldout = corpus.split()
    voices_began = time.perf_counter()
    revoiced = revoiced_utterances(_plans(corpus, set(train.stems)), TRAINING_VOICES, corpus.fps)
    unheard = revoiced_utterances(_plans(corpus, set(heldout.stems)), [HELDOUT_VOICE], corpus.fps)
    voices_s = time.perf_counter() - voices_began
    many = replace(train, utterances=list(train.utterances) + revoiced)
    second_train, second_heldout = second_character().split()
    grid, sounded = _grid_with_sound(grid_dir)
    results: dict[str, Any] = {"configurations": {}}
    with threadpool_limits(limits=1):
        lerp = VisemeLerpEngine().fit(train)
        second_lerp = VisemeLerpEngine().fit(second_train)
        for name, (normalized, more_voices) in CONFIGURATIONS.items():
            started = time.perf_counter()
            hmm = HmmEngine(speaker_normalization=normalized).fit(many if more_voices else train)
            fit_s = time.perf_counter() - started
            sets = {
                "demo": rms_figures(hmm, lerp, heldout.utterances),
                "second_character": rms_figures(hmm, lerp, second_heldout.utterances),
                "heldout_voice": rms_figures(hmm, lerp, unheard),
            }
            if not more_voices:
                own = HmmEngine(speaker_normalization=normalized).fit(second_train)
                sets["second_character_self_trained"] = rms_figures(
                    own, second_lerp, second_heldout.utterances
                )
            real = {
                clip.stem: grid_figures(hmm, lerp, clip, audio, grid.fps) for clip, audio in sounded
            }
            results["configurations"][name] = {
                "speaker_normalization": normalized,
                "voices": _voice_names(more_voices),
                "training_lines": len((many if more_voices else train).utterances),
                "fit_s": round(fit_s, 1),
                "sets": sets,
                "grid": real,
                "grid_mean": mean_figures(real.values()),
            }
            print(f"{name}: {_summary(results['configurations'][name])}", file=sys.stderr)
        results["warps"] = warp_figures(
            hmm,
            lerp,
            {
                "demo": heldout.utterances,
                "second_character": second_heldout.utterances,
                "heldout_voice": unheard,
            },
            sounded,
            grid.fps,
        )
    return {
        **recorded(" ".join(command)),
        "corpus": {"name": corpus.name, "digest": corpus.digest(), "lines": len(corpus.utterances)},
        "second_character": _speaker_fields(SECOND_CHARACTER, len(second_train.utterances)),
        "heldout_voice": {
            "variant": HELDOUT_VOICE.variant,
            "pitch_shift": HELDOUT_VOICE.pitch_shift,
        },
        "grid": {
            "clips": len(real_clips(grid)),
            "clips_with_sound": [clip.stem for clip, _ in sounded],
        },
        "revoicing_s": round(voices_s, 1),
        "total_s": round(time.perf_counter() - began, 1),
        **results,
    }


def _voice_names(more_voices: bool) -> list[str]:
    demo = ["demo speakers' own (en-us+f3, +m3, +f4)"]
    extra = [f"+{v.variant} (pitch {v.pitch_shift:+d})" for v in TRAINING_VOICES]
    return demo + extra if more_voices else demo


def _speaker_fields(speaker: Speaker, training_lines: int) -> dict[str, Any]:
    return {
        "voice": speaker.voice,
        "pitch": speaker.pitch,
        "rate_factor": speaker.rate_factor,
        "jaw_scale": speaker.jaw_scale,
        "lips_scale": speaker.lips_scale,
        "rounding_scale": speaker.rounding_scale,
        "stiffness_scale": speaker.stiffness_scale,
        "lines": SECOND_LINES,
        "training_lines": training_lines,
    }


def _summary(configuration: dict[str, Any]) -> str:
    ratios = ", ".join(
        f"{name} {figures['audio_ratio']:.3f}" for name, figures in configuration["sets"].items()
    )
    return ratios


def main(argv: list[str] | None = None) -> int:
    settings = load_settings()
    parser = argparse.ArgumentParser(description="voice-driven hmm on unseen voices")
    parser.add_argument("--corpus", type=Path, default=settings.demo_dir / DEMO_CORPUS_DIR)
    parser.add_argument("--grid", type=Path, default=GRID_DIR)
    parser.add_argument("--results", type=Path, default=Path("bench/hmm_voices.json"))
    args = parser.parse_args(argv)
    command = ["python", "-m", "lipstream.bench.hmm_voices", *(argv or sys.argv[1:])]
    results = run_hmm_voices(load_corpus(args.corpus), args.grid, command)
    write_results(results, args.results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
