"""``lipstream bench --real``: every engine of the demo character scored against real lips.

Each clip of a real-face corpus (``lipstream capture`` output, such as the shipped GRID
set) is synthesized from its own force-aligned phones, and the predicted lip aperture
(``jawOpen - mouthClose``) is set against the tracked one:

- **aperture r**: Pearson r over the speech frames (those inside a non-silence phone),
  averaged over the clips. A linear map with positive slope leaves r unchanged, so r is
  taken on the prediction as it comes;
- **closure rate**: the share of /p b m/ spans whose predicted aperture, mapped into the
  speaker's own units, falls below the threshold ``evaluation.closure_threshold`` learns
  from the real recordings. The map (real ≈ slope × predicted + offset) is fitted by least
  squares on the speaker's speech frames: on the speaker's other clips where there are
  any (leave one clip out), else on the clip itself, and the results count each kind;
- **closure timing**: ``evaluation.closure_lags`` (the predicted plateau centre less the
  real one), mean, standard deviation and the mean's standard error (sd / sqrt(n), the
  closures taken as independent) in ms.

Engines that use audio are driven by the phones alone: the shipped set holds no sound.
"""

from __future__ import annotations

import platform
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from .._version import __version__
from ..bilabial_lead import lead_bilabials
from ..corpus import Corpus, Utterance
from ..engines import load_model
from ..engines.base import Model
from ..errors import LipstreamError
from ..evaluation import closure_counts, closure_lags, closure_threshold, lip_aperture
from ..models import model_dirs
from ..phonemes import SILENCE
from ..timeline import PhonemeSpan

BASELINE = "viseme-lerp"


@dataclass(frozen=True)
class LinearMap:
    """``slope * x + offset``, fitted by least squares."""

    slope: float
    offset: float

    def __call__(self, values: np.ndarray) -> np.ndarray:
        return self.slope * values + self.offset


def fit_linear_map(source: np.ndarray, target: np.ndarray) -> LinearMap:
    """The least-squares map of ``source`` (n,) onto ``target`` (n,); a constant source maps
    to the target's mean."""
    x = np.asarray(source, dtype=np.float64)
    y = np.asarray(target, dtype=np.float64)
    spread = float(np.sum((x - x.mean()) ** 2))
    slope = float(np.sum((x - x.mean()) * (y - y.mean())) / spread) if spread > 0 else 0.0
    return LinearMap(slope, float(y.mean() - slope * x.mean()))


def pearson_r(first: np.ndarray, second: np.ndarray) -> float | None:
    """Pearson's r of two (n,) series; None when either is constant."""
    a = np.asarray(first, dtype=np.float64) - np.mean(first)
    b = np.asarray(second, dtype=np.float64) - np.mean(second)
    norm = float(np.sqrt(np.sum(a**2) * np.sum(b**2)))
    return float(np.sum(a * b) / norm) if norm > 0 else None


def speech_mask(spans: Sequence[PhonemeSpan], fps: float, n_frames: int) -> np.ndarray:
    """(n_frames,) bool: frames whose time falls inside a non-silence phone."""
    times = np.arange(n_frames) / fps
    mask = np.zeros(n_frames, dtype=bool)
    for span in spans:
        if span.phoneme != SILENCE:
            mask |= (times >= span.start) & (times < span.end)
    return mask


@dataclass(frozen=True)
class Clip:
    """One real clip's aperture (n_frames,), its speech frames and its phones."""

    stem: str
    speaker: str
    aperture: np.ndarray
    speech: np.ndarray
    phones: Sequence[PhonemeSpan]


def real_clips(corpus: Corpus) -> list[Clip]:
    clips = []
    for utterance in corpus.utterances:
        aperture = lip_aperture(utterance.frames, corpus.channels)
        if aperture is None:
            raise LipstreamError(
                "the real-face corpus has no jawOpen and mouthClose channels",
                where=corpus.name,
                code="invalid_corpus",
            )
        speech = speech_mask(utterance.phones, corpus.fps, len(aperture))
        clips.append(
            Clip(_stem(utterance), _speaker(utterance), aperture, speech, utterance.phones)
        )
    return clips


def _stem(utterance: Utterance) -> str:
    return str(utterance.stem)


def _speaker(utterance: Utterance) -> str:
    return str(utterance.speaker or utterance.stem)


def speaker_maps(
    clips: Sequence[Clip], predicted: Sequence[np.ndarray]
) -> tuple[list[LinearMap], int]:
    """Per clip, the map of the predicted aperture onto the speaker's real one, fitted on
    the speaker's other clips (leave one clip out) where it has any, else on the clip
    itself; and how many clips were fitted on themselves."""
    maps, own = [], 0
    for index, clip in enumerate(clips):
        others = [
            i for i, other in enumerate(clips) if other.speaker == clip.speaker and i != index
        ]
        if not others:
            others, own = [index], own + 1
        source = np.concatenate([predicted[i][clips[i].speech] for i in others])
        target = np.concatenate([clips[i].aperture[clips[i].speech] for i in others])
        maps.append(fit_linear_map(source, target))
    return maps, own


@dataclass
class RealFaceRow:
    """One engine's figures against real lips."""

    engine: str
    aperture_r: float | None
    closure_rate: float | None
    closure_lag_ms: float | None
    closure_lag_sd_ms: float | None
    closure_lag_se_ms: float | None
    closures_timed: int
    clips_mapped_on_themselves: int
    aperture_r_by_clip: dict[str, float | None]


def predicted_apertures(
    model: Model, clips: Sequence[Clip], fps: float, lead_s: float = 0.0
) -> list[np.ndarray]:
    """``model``'s lip aperture for each clip, from its phones (their bilabials led by
    ``lead_s``, ``bilabial_lead.lead_bilabials``), on the clip's frames (the last frame held
    should the synthesis end early)."""
    predicted = []
    for clip in clips:
        phones = lead_bilabials(clip.phones, lead_s) if lead_s > 0.0 else clip.phones
        frames = model.synthesize(phones, fps=fps, audio=None).frames
        aperture = lip_aperture(frames, model.channels)
        if aperture is None or len(aperture) == 0:
            raise LipstreamError(
                "the model gives no lip aperture (jawOpen and mouthClose)",
                where=model.manifest.engine,
                code="invalid_model",
            )
        n = len(clip.aperture)
        padded = np.full(n, aperture[-1])
        padded[: min(n, len(aperture))] = aperture[:n]
        predicted.append(padded)
    return predicted


def score_apertures(
    engine: str,
    clips: Sequence[Clip],
    predicted: Sequence[np.ndarray],
    fps: float,
    threshold: float,
) -> RealFaceRow:
    """The figures of predicted apertures (one (n_frames,) per clip) against the real ones."""
    maps, own = speaker_maps(clips, predicted)
    by_clip = {
        clip.stem: pearson_r(p[clip.speech], clip.aperture[clip.speech])
        for clip, p in zip(clips, predicted, strict=True)
    }
    known = [r for r in by_clip.values() if r is not None]
    closed = total = 0
    lags: list[float] = []
    for clip, prediction, linear in zip(clips, predicted, maps, strict=True):
        got, count = closure_counts(linear(prediction), clip.phones, fps, threshold)
        closed, total = closed + got, total + count
        lags.extend(closure_lags(clip.aperture, prediction, clip.phones, fps))
    lags_ms = 1000.0 * np.asarray(lags)
    sd = float(lags_ms.std(ddof=1)) if len(lags) > 1 else None
    return RealFaceRow(
        engine=engine,
        aperture_r=float(np.mean(known)) if known else None,
        closure_rate=closed / total if total else None,
        closure_lag_ms=float(lags_ms.mean()) if len(lags) else None,
        closure_lag_sd_ms=sd,
        closure_lag_se_ms=None if sd is None else sd / float(np.sqrt(len(lags))),
        closures_timed=len(lags),
        clips_mapped_on_themselves=own,
        aperture_r_by_clip=by_clip,
    )


def demo_models(models_dir: Path, engines: Sequence[str] | None = None) -> list[Model]:
    """The models under ``models_dir`` (of ``engines`` when given), ``viseme-lerp`` first."""
    models = [load_model(directory) for directory in model_dirs(models_dir)]
    if engines:
        models = [model for model in models if model.manifest.engine in engines]
    if not any(model.manifest.engine == BASELINE for model in models):
        raise LipstreamError(
            f"no {BASELINE} model to compare with", where=str(models_dir), code="invalid_request"
        )
    return sorted(
        models, key=lambda model: (model.manifest.engine != BASELINE, model.manifest.engine)
    )


def run_real_bench(
    corpus: Corpus, models: Sequence[Model], command: Sequence[str]
) -> dict[str, Any]:
    """Every model of ``models`` against the real clips of ``corpus``."""
    clips = real_clips(corpus)
    threshold = closure_threshold(((c.aperture, c.phones) for c in clips), corpus.fps)
    recorded_closed = recorded_total = 0
    for clip in clips:
        got, count = closure_counts(clip.aperture, clip.phones, corpus.fps, threshold)
        recorded_closed, recorded_total = recorded_closed + got, recorded_total + count
    with threadpool_limits(limits=1):
        rows = [
            score_apertures(
                model.manifest.engine,
                clips,
                predicted_apertures(model, clips, corpus.fps),
                corpus.fps,
                threshold,
            )
            for model in models
        ]
    return {
        "lipstream_version": __version__,
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "command": " ".join(command),
        "machine": {
            "python": platform.python_version(),
            "processor": platform.machine(),
            "system": platform.system(),
        },
        "corpus": {
            "name": corpus.name,
            "digest": corpus.digest(),
            "fps": corpus.fps,
            "clips": len(clips),
            "speakers": len({clip.speaker for clip in clips}),
        },
        "models": {
            model.manifest.engine: {
                "character": model.manifest.name,
                "corpus_digest": model.manifest.corpus_digest,
            }
            for model in models
        },
        "recorded": {
            "closure_threshold": threshold,
            "closure_rate": recorded_closed / recorded_total if recorded_total else None,
            "bilabials": recorded_total,
        },
        "engines": [asdict(row) for row in rows],
    }


def _fmt(value: float | None, pattern: str) -> str:
    return "n/a" if value is None else format(value, pattern)


def format_real_table(results: dict[str, Any]) -> str:
    header = f"{'engine':<16}{'aperture r':>11}{'closure':>9}{'lag ms':>9}{'± se':>7}{'sd':>7}"
    lines = [header, "-" * len(header)]
    for row in results["engines"]:
        lines.append(
            f"{row['engine']:<16}{_fmt(row['aperture_r'], '.3f'):>11}"
            f"{_fmt(row['closure_rate'], '.1%'):>9}{_fmt(row['closure_lag_ms'], '+.1f'):>9}"
            f"{_fmt(row.get('closure_lag_se_ms'), '.1f'):>7}"
            f"{_fmt(row['closure_lag_sd_ms'], '.1f'):>7}"
        )
    recorded = results["recorded"]
    lines.append(f"{'real lips':<16}{'':>11}{_fmt(recorded['closure_rate'], '.1%'):>9}")
    return "\n".join(lines)
