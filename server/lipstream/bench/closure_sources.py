"""Where the demo models' closure lag on real lips comes from: the character or the engines.

Sketch: every clip of the real-face set is also rendered by the demo character's own
generator (``demo.face.generate_face``, neutral, once per demo speaker, at the generator's
120 fps, read on the clip's frames by ``np.interp``, the speakers' apertures averaged) from
the clip's own force-aligned phones. Every /p b m/ closure is then timed three times, as
``evaluation.closure_lags`` times it (plateau centres within the span widened by
``LAG_WINDOW_S``): on the real lips, on the character and on each engine's prediction.
An engine's lag on the real lips splits exactly into

- **the engine behind the character**: how late the engine closes against the very
  character it was trained on, driven by the same phones; and
- **the character behind the real lips**: how late the character closes against the real
  face, on the same phones (one figure for every engine).

The character's lip aperture is also set against the real one as ``bench --real`` scores
an engine (Pearson r over each clip's speech frames, averaged over the clips), beside a
context-free predictor for scale: each phoneme's mean real aperture over the other clips.

Each part is reported pooled and by context: a /p b m/ *after silence* (it opens the
utterance or follows a pause, where its acoustic onset ends a silent stretch) or *after
speech*. Means in ms with their standard error (sd / sqrt(n)).

``python -m lipstream.bench.closure_sources --models DIR --json bench/closure_sources.json``
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.ndimage import gaussian_filter1d
from threadpoolctl import threadpool_limits

from ..corpus import load_corpus
from ..demo.face import DEMO_CHANNELS, generate_face
from ..demo.speakers import DEMO_SPEAKERS
from ..engines.base import Model
from ..evaluation import BILABIALS, closure_lags
from ..phonemes import SILENCE
from ..results_file import recorded, script_command, write_results
from ..timeline import PhonemeSpan
from .real_faces import Clip, demo_models, pearson_r, predicted_apertures, real_clips
from .real_set import real_set_parser

MODULE = "lipstream.bench.closure_sources"
GENERATOR_FPS = 120.0
CONTEXTS = ("after_silence", "after_speech")


def bilabial_contexts(phones: Sequence[PhonemeSpan]) -> list[tuple[PhonemeSpan, str]]:
    """Each /p b m/ span with its context: ``after_silence`` when it opens the utterance or
    follows a silence, else ``after_speech``."""
    out = []
    for index, span in enumerate(phones):
        if span.phoneme not in BILABIALS:
            continue
        quiet = index == 0 or phones[index - 1].phoneme == SILENCE
        out.append((span, CONTEXTS[0] if quiet else CONTEXTS[1]))
    return out


def character_aperture(
    phones: Sequence[PhonemeSpan], n_frames: int, fps: float, seed: int
) -> np.ndarray:
    """The demo character's lip aperture (n_frames,) for ``phones`` on a grid of ``fps``:
    each demo speaker, neutral, rendered at ``GENERATOR_FPS`` (``seed``) and read by
    ``np.interp``, averaged over the speakers."""
    times = np.arange(n_frames) / fps
    duration = max(float(times[-1]), 1.0 / GENERATOR_FPS)
    jaw, close = DEMO_CHANNELS.index("jawOpen"), DEMO_CHANNELS.index("mouthClose")
    curves = []
    for speaker in DEMO_SPEAKERS:
        frames = generate_face(
            phones, duration, emotion="neutral", speaker=speaker, fps=GENERATOR_FPS, seed=seed
        )
        aperture = frames[:, jaw].astype(np.float64) - frames[:, close]
        curves.append(np.interp(times, np.arange(len(aperture)) / GENERATOR_FPS, aperture))
    return np.asarray(np.mean(curves, axis=0))


@dataclass(frozen=True)
class LagSummary:
    """Mean and standard error (ms) of closure lags, and their count."""

    mean_ms: float | None
    se_ms: float | None
    count: int


def summarize_lags(lags_s: Sequence[float]) -> LagSummary:
    values = 1000.0 * np.asarray(lags_s, dtype=np.float64)
    se = float(values.std(ddof=1) / np.sqrt(len(values))) if len(values) > 1 else None
    return LagSummary(float(values.mean()) if len(values) else None, se, len(values))


def lags_by_context(
    clips: Sequence[Clip], reference: Sequence[np.ndarray], timed: Sequence[np.ndarray], fps: float
) -> dict[str, list[float]]:
    """Per context (and ``all``), the closure lags (s) of ``timed`` behind ``reference``
    (one aperture per clip each) at the clips' /p b m/ spans."""
    out: dict[str, list[float]] = {"all": [], **{context: [] for context in CONTEXTS}}
    for clip, base, curve in zip(clips, reference, timed, strict=True):
        for span, context in bilabial_contexts(clip.phones):
            lags = closure_lags(base, curve, [span], fps)
            out["all"].extend(lags)
            out[context].extend(lags)
    return out


def summarize_contexts(lags: dict[str, list[float]]) -> dict[str, dict[str, Any]]:
    return {context: asdict(summarize_lags(values)) for context, values in lags.items()}


def split_lags(
    clips: Sequence[Clip],
    character: Sequence[np.ndarray],
    predicted: Mapping[str, Sequence[np.ndarray]],
    fps: float,
) -> dict[str, Any]:
    """The character behind the real lips and, per engine of ``predicted`` (engine ->
    apertures), the engine behind the character and behind the real lips."""
    real = [clip.aperture for clip in clips]
    return {
        "character_behind_real": summarize_contexts(lags_by_context(clips, real, character, fps)),
        "engines": {
            engine: {
                "behind_character": summarize_contexts(
                    lags_by_context(clips, character, curves, fps)
                ),
                "behind_real": summarize_contexts(lags_by_context(clips, real, curves, fps)),
            }
            for engine, curves in predicted.items()
        },
    }


def character_apertures(clips: Sequence[Clip], fps: float) -> list[np.ndarray]:
    """``character_aperture`` on each clip's frames from its phones (clip i with seed i)."""
    return [
        character_aperture(clip.phones, len(clip.aperture), fps, seed)
        for seed, clip in enumerate(clips)
    ]


@dataclass(frozen=True)
class RealPhones:
    """The real-face set's clips with the character rendered on their force-aligned phones:
    what an engine's closures are timed against on real speech's phone sequences, with the
    real lips or without them (``timed``)."""

    name: str
    clips: Sequence[Clip]
    character: Sequence[np.ndarray]
    fps: float

    @classmethod
    def load(cls, real_set: Path) -> RealPhones:
        corpus = load_corpus(real_set)
        clips = real_clips(corpus)
        return cls(corpus.name, clips, character_apertures(clips, corpus.fps), corpus.fps)

    def timed(self, model: Model, lead_s: float = 0.0) -> dict[str, Any]:
        """``model`` run once on the clips' phones led by ``lead_s``: its closure lag at
        every /p b m/ (ms: mean, standard error, count) behind the character
        (``behind_character``) and behind the real lips (``behind_real``), and its lip
        aperture's r against the real lips (``aperture_r``)."""
        predicted = predicted_apertures(model, self.clips, self.fps, lead_s)
        real = [clip.aperture for clip in self.clips]
        return {
            side: asdict(
                summarize_lags(lags_by_context(self.clips, reference, predicted, self.fps)["all"])
            )
            for side, reference in (("behind_character", self.character), ("behind_real", real))
        } | {"aperture_r": aperture_r(self.clips, predicted)}


def aperture_r(clips: Sequence[Clip], curves: Sequence[np.ndarray]) -> float:
    """Pearson r of each curve (one per clip, on its frames) and the clip's real aperture
    over its speech frames, averaged over the clips where both move."""
    values = [
        pearson_r(curve[clip.speech], clip.aperture[clip.speech])
        for clip, curve in zip(clips, curves, strict=True)
    ]
    return float(np.mean([r for r in values if r is not None]))


PHONEME_MEAN_SMOOTHING_S = 0.04


def _phone_labels(clip: Clip, fps: float) -> list[str]:
    times = np.arange(len(clip.aperture)) / fps
    labels = [SILENCE] * len(times)
    for span in clip.phones:
        for index in np.flatnonzero((times >= span.start) & (times < span.end)):
            labels[index] = span.phoneme
    return labels


def phoneme_mean_aperture_r(clips: Sequence[Clip], fps: float) -> float:
    """Aperture r of a context-free predictor, for scale: each frame gets its phoneme's
    mean real aperture over the *other* clips (each clip's aperture as a share of its
    speech range, 2nd to 98th percentile), smoothed by a Gaussian of
    ``PHONEME_MEAN_SMOOTHING_S``; Pearson r over the speech frames, averaged over clips."""
    labels = [_phone_labels(clip, fps) for clip in clips]
    shares = []
    for clip in clips:
        low, high = np.percentile(clip.aperture[clip.speech], (2.0, 98.0))
        shares.append((clip.aperture - low) / max(high - low, 1e-9))
    values = []
    for index, clip in enumerate(clips):
        sums: dict[str, list[float]] = {}
        for other, (names, share) in enumerate(zip(labels, shares, strict=True)):
            if other != index:
                for name, value in zip(names, share, strict=True):
                    sums.setdefault(name, []).append(float(value))
        means = {name: float(np.mean(found)) for name, found in sums.items()}
        overall = float(np.mean([v for found in sums.values() for v in found]))
        steps = np.array([means.get(name, overall) for name in labels[index]])
        curve = gaussian_filter1d(steps, PHONEME_MEAN_SMOOTHING_S * fps)
        r = pearson_r(curve[clip.speech], clip.aperture[clip.speech])
        if r is not None:
            values.append(r)
    return float(np.mean(values))


def run(real_set: Path, models_dir: Path, command: str) -> dict[str, Any]:
    corpus = load_corpus(real_set)
    clips = real_clips(corpus)
    character = character_apertures(clips, corpus.fps)
    with threadpool_limits(limits=1):
        predicted = {
            model.manifest.engine: predicted_apertures(model, clips, corpus.fps)
            for model in demo_models(models_dir)
        }
    return {
        **recorded(command),
        "corpus": {"name": corpus.name, "digest": corpus.digest(), "fps": corpus.fps},
        "clips": len(clips),
        "character_aperture_r": aperture_r(clips, character),
        "phoneme_mean_aperture_r": phoneme_mean_aperture_r(clips, corpus.fps),
        **split_lags(clips, character, predicted, corpus.fps),
    }


def format_split(results: dict[str, Any]) -> str:
    def cell(summary: dict[str, Any]) -> str:
        if summary["mean_ms"] is None:
            return f"{'n/a':>14}"
        se = "" if summary["se_ms"] is None else f"±{summary['se_ms']:.1f}"
        return f"{summary['mean_ms']:+7.1f}{se:>7}"

    lines = [f"{'':<34}{'all':>14}{'after silence':>14}{'after speech':>14}"]
    rows = [("character behind real", results["character_behind_real"])]
    for engine, parts in results["engines"].items():
        rows += [(f"{engine} behind character", parts["behind_character"])]
        rows += [(f"{engine} behind real", parts["behind_real"])]
    for name, by in rows:
        lines.append(f"{name:<34}" + "".join(cell(by[c]) for c in ("all", *CONTEXTS)))
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    parser = real_set_parser(f"python -m {MODULE}", __doc__)
    parser.add_argument("--models", type=Path, required=True, help="the demo models' directory")
    parser.add_argument("--json", type=Path, required=True, help="results file to write")
    args = parser.parse_args(argv)
    results = run(args.real, args.models, script_command(MODULE, argv))
    write_results(results, args.json)
    print(format_split(results))


if __name__ == "__main__":
    main()
