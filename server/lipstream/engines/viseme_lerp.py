"""Baseline ``viseme-lerp``: static viseme key poses, linearly interpolated.

Method (what most lip-sync tools do): each viseme class gets one key pose,
the mean of every training frame that falls inside a phoneme of that class.
At synthesis a key is placed at the centre of each phoneme span and the
channels are interpolated linearly between consecutive centres, holding the
first and last keys flat. Every other engine is measured against this one.
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..audio import Audio
from ..errors import CorpusError, LipstreamError
from ..model_checks import ArrayReader, FieldReader
from ..phonemes import PHONEMES, SILENCE
from ..store import ARRAYS_NAME, MANIFEST_NAME, ModelManifest
from ..timeline import PhonemeSpan
from ..visemes import get_scheme
from .base import Engine, Lookahead, Model, SynthesisRequest


class VisemeLerpModel(Model):
    """Key poses ``poses`` float32 (n_visemes, n_channels), rows in ``scheme.classes`` order."""

    engine = "viseme-lerp"

    def __init__(self, manifest: ModelManifest, poses: np.ndarray) -> None:
        super().__init__(manifest)
        self.scheme = get_scheme(manifest.hyperparameters["scheme"])
        # A small copy, not the memmap: fancy indexing off a memmap is slow.
        self.poses = np.array(poses, dtype=np.float32)
        self._pose_row = {p: self.scheme.classes.index(self.scheme.viseme_of(p)) for p in PHONEMES}

    @property
    def lookahead(self) -> Lookahead:
        """The key after t sits at the centre of the next span."""
        return Lookahead(phonemes=1)

    def render(
        self,
        spans: Sequence[PhonemeSpan],
        times: np.ndarray,
        request: SynthesisRequest,
        audio: Audio | None,
    ) -> np.ndarray:
        window = spans[_first_key(spans, times[0]) : _last_key(spans, times[-1]) + 1]
        centres = np.array([span.centre for span in window])
        keys = self.poses[[self._pose_row[span.phoneme] for span in window]]
        if len(window) == 1:
            return np.repeat(keys, len(times), axis=0).astype(np.float32)
        # np.interp per channel, for all channels at once: the segment left of each time
        # (held flat beyond the first and last centres), and the weight of its right key.
        left = np.clip(np.searchsorted(centres, times, side="right") - 1, 0, len(window) - 2)
        width = centres[left + 1] - centres[left]
        weight = np.minimum(np.maximum((times - centres[left]) / width, 0.0), 1.0)[:, None]
        frames = keys[left] * (1.0 - weight) + keys[left + 1] * weight
        return np.asarray(frames, dtype=np.float32)

    def arrays(self) -> dict[str, np.ndarray]:
        return {"poses": self.poses}

    @classmethod
    def from_arrays(
        cls, manifest: ModelManifest, arrays: Mapping[str, np.ndarray], path: Path
    ) -> VisemeLerpModel:
        fields = FieldReader(str(path / MANIFEST_NAME))
        field = "hyperparameters.scheme"
        name = fields.string(fields.member(manifest.hyperparameters, "scheme", field), field)
        try:
            scheme = get_scheme(name)
        except LipstreamError as error:
            raise fields.error(field, error.message) from None
        reader = ArrayReader(arrays, str(path / ARRAYS_NAME))
        poses = reader.floats("poses", (len(scheme.classes), len(manifest.channels)))
        return cls(manifest, poses)


class VisemeLerpEngine(Engine):
    """Fits one mean pose per viseme class of ``scheme`` (see ``lipstream.visemes``)."""

    name = "viseme-lerp"
    model_class = VisemeLerpModel

    def __init__(self, scheme: str = "oculus15") -> None:
        self.scheme = scheme

    def fit(self, corpus: Any, *, progress: bool = False) -> VisemeLerpModel:
        scheme = get_scheme(self.scheme)
        n_channels = len(corpus.channels)
        sums = np.zeros((len(scheme.classes), n_channels))
        counts = np.zeros(len(scheme.classes))
        for utterance in corpus.utterances:
            for span in utterance.phones:
                first = int(np.ceil(span.start * corpus.fps))
                stop = min(int(np.ceil(span.end * corpus.fps)), len(utterance.frames))
                row = scheme.classes.index(scheme.viseme_of(span.phoneme))
                sums[row] += utterance.frames[first:stop].sum(axis=0)
                counts[row] += max(0, stop - first)
        poses = _mean_poses(sums, counts, scheme.classes.index(scheme.viseme_of(SILENCE)))
        manifest = self.new_manifest(
            corpus, metrics={"frames_per_viseme": counts.astype(int).tolist()}
        )
        return VisemeLerpModel(manifest, poses)


def _first_key(spans: Sequence[PhonemeSpan], t: float) -> int:
    """Index of the last span whose centre is at or before ``t`` (0 if none)."""
    return max(0, bisect_right(spans, t, key=lambda span: span.centre) - 1)


def _last_key(spans: Sequence[PhonemeSpan], t: float) -> int:
    """Index of the first span whose centre is after ``t`` (the last span if none)."""
    return min(len(spans) - 1, bisect_right(spans, t, key=lambda span: span.centre))


def _mean_poses(sums: np.ndarray, counts: np.ndarray, rest_row: int) -> np.ndarray:
    """Per-class means; a class never seen in training falls back to the rest pose."""
    seen = counts > 0
    if not seen.any():
        raise CorpusError("the corpus has no frames inside any phoneme span")
    poses = np.zeros_like(sums)
    poses[seen] = sums[seen] / counts[seen, None]
    fallback = poses[rest_row] if seen[rest_row] else poses[seen].mean(axis=0)
    poses[~seen] = fallback
    return poses.astype(np.float32)
