"""The in-memory corpus: utterances on one uniform frame grid, with phones.

Sketch: every utterance holds control frames sampled at ``i / fps`` seconds
(frame ``i``), a contiguous list of phoneme spans on the same clock, optional
audio and an emotion label. A ``Corpus`` ties utterances sharing one fps and
one ordered channel list; it can fingerprint itself (``digest``) so a trained
model can tell whether its corpus changed, and split off held-out utterances.
"""

from __future__ import annotations

import hashlib
import struct
from collections.abc import Iterable
from dataclasses import dataclass, field, replace

import numpy as np

from ..audio import Audio
from ..errors import CorpusError
from ..timeline import EMOTIONS, PhonemeSpan

HELDOUT_EVERY = 10


@dataclass
class Utterance:
    """One recorded utterance.

    ``frames``: (n_frames, n_channels) float32; frame ``i`` is at ``i / fps`` s.
    ``phones``: contiguous spans in seconds (gaps already filled with silence).
    ``text``: the transcript, when the corpus carries one (not used in training).
    ``alignment_confidence``: in [0, 1], when a forced aligner placed the phones (``lipstream
    capture``); not used in training nor in ``Corpus.digest``.
    """

    stem: str
    frames: np.ndarray
    phones: list[PhonemeSpan]
    fps: float
    audio: Audio | None = None
    emotion: str = "neutral"
    speaker: str | None = None
    text: str | None = None
    alignment_confidence: float | None = None

    def __post_init__(self) -> None:
        where = f"utterance {self.stem!r}"
        frames = np.asarray(self.frames)
        if frames.ndim != 2 or frames.shape[0] < 1:
            raise CorpusError(
                f"frames must have shape (n_frames >= 1, n_channels), got {frames.shape}",
                where=where,
            )
        if not np.issubdtype(frames.dtype, np.number) or np.issubdtype(
            frames.dtype, np.complexfloating
        ):
            raise CorpusError(f"frames must be real numbers, got dtype {frames.dtype}", where=where)
        if not np.all(np.isfinite(frames)):
            raise CorpusError("frames hold NaN or infinite values", where=where)
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise CorpusError(f"fps must be a positive number, got {self.fps}", where=where)
        if self.emotion not in EMOTIONS:
            raise CorpusError(
                f"emotion must be one of {', '.join(EMOTIONS)}, got {self.emotion!r}", where=where
            )
        self.frames = np.ascontiguousarray(frames, dtype=np.float32)
        self.fps = float(self.fps)

    @property
    def n_frames(self) -> int:
        return int(self.frames.shape[0])

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame: ``(n_frames - 1) / fps``."""
        return (self.n_frames - 1) / self.fps

    def times(self) -> np.ndarray:
        """Frame times in seconds, shape (n_frames,)."""
        return np.arange(self.n_frames, dtype=np.float64) / self.fps


@dataclass
class Corpus:
    """Utterances sharing ``fps`` and the ordered ``channels`` of their frame columns."""

    name: str
    fps: float
    channels: tuple[str, ...]
    utterances: list[Utterance]
    heldout: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        self.channels = tuple(self.channels)
        self.heldout = tuple(self.heldout)
        self.fps = float(self.fps)
        if len(set(self.channels)) != len(self.channels):
            raise CorpusError("channel names must be unique", where=f"corpus {self.name!r}")
        stems = [utterance.stem for utterance in self.utterances]
        if len(set(stems)) != len(stems):
            raise CorpusError("utterance stems must be unique", where=f"corpus {self.name!r}")
        for utterance in self.utterances:
            self._check_member(utterance)
        unknown = sorted(set(self.heldout) - set(stems))
        if unknown:
            raise CorpusError(
                f"held-out stems not in the corpus: {', '.join(unknown)}",
                where=f"corpus {self.name!r}",
            )

    def _check_member(self, utterance: Utterance) -> None:
        where = f"utterance {utterance.stem!r}"
        if utterance.fps != self.fps:
            raise CorpusError(
                f"fps {utterance.fps} differs from corpus fps {self.fps}", where=where
            )
        if utterance.frames.shape[1] != len(self.channels):
            raise CorpusError(
                f"frames have {utterance.frames.shape[1]} columns "
                f"but the corpus has {len(self.channels)} channels",
                where=where,
            )

    def __len__(self) -> int:
        return len(self.utterances)

    @property
    def stems(self) -> tuple[str, ...]:
        return tuple(utterance.stem for utterance in self.utterances)

    def utterance(self, stem: str) -> Utterance:
        for candidate in self.utterances:
            if candidate.stem == stem:
                return candidate
        raise CorpusError(f"no utterance with stem {stem!r}", where=f"corpus {self.name!r}")

    def digest(self) -> str:
        """SHA-256 hex over channels, fps, held-out stems and every utterance's
        stem, frames, phones, emotion and audio (the corpus name is left out)."""
        hasher = hashlib.sha256()
        _feed_text(hasher, "lipstream-corpus-v1")
        _feed_strings(hasher, self.channels)
        hasher.update(struct.pack("<d", self.fps))
        _feed_strings(hasher, self.heldout)
        hasher.update(struct.pack("<q", len(self.utterances)))
        for utterance in self.utterances:
            _feed_utterance(hasher, utterance)
        return hasher.hexdigest()

    def heldout_stems(self) -> tuple[str, ...]:
        """The held-out stems: ``heldout`` if given, else every 10th in sorted stem order."""
        if self.heldout:
            return self.heldout
        ordered = sorted(self.stems)
        return tuple(
            stem for index, stem in enumerate(ordered) if index % HELDOUT_EVERY == HELDOUT_EVERY - 1
        )

    def split(self) -> tuple[Corpus, Corpus]:
        """(train, heldout) corpora; both keep name, fps and channels, neither keeps ``heldout``."""
        held = set(self.heldout_stems())
        train = [utterance for utterance in self.utterances if utterance.stem not in held]
        test = [utterance for utterance in self.utterances if utterance.stem in held]
        return replace(self, utterances=train, heldout=()), replace(
            self, utterances=test, heldout=()
        )

    def subset(self, stems: Iterable[str]) -> Corpus:
        """The utterances named by ``stems``, in corpus order; unknown stems raise."""
        wanted = set(stems)
        unknown = sorted(wanted - set(self.stems))
        if unknown:
            raise CorpusError(
                f"stems not in the corpus: {', '.join(unknown)}", where=f"corpus {self.name!r}"
            )
        chosen = [utterance for utterance in self.utterances if utterance.stem in wanted]
        heldout = tuple(stem for stem in self.heldout if stem in wanted)
        return replace(self, utterances=chosen, heldout=heldout)


def _feed_text(hasher: hashlib._Hash, text: str) -> None:
    encoded = text.encode("utf-8")
    hasher.update(struct.pack("<q", len(encoded)))
    hasher.update(encoded)


def _feed_strings(hasher: hashlib._Hash, items: Iterable[str]) -> None:
    values = list(items)
    hasher.update(struct.pack("<q", len(values)))
    for value in values:
        _feed_text(hasher, value)


def _feed_array(hasher: hashlib._Hash, array: np.ndarray, dtype: str) -> None:
    data = np.ascontiguousarray(array, dtype=dtype)
    hasher.update(struct.pack("<q", data.ndim))
    hasher.update(struct.pack(f"<{data.ndim}q", *data.shape))
    hasher.update(data.tobytes())


def _feed_utterance(hasher: hashlib._Hash, utterance: Utterance) -> None:
    _feed_text(hasher, utterance.stem)
    _feed_text(hasher, utterance.emotion)
    _feed_array(hasher, utterance.frames, "<f4")
    hasher.update(struct.pack("<q", len(utterance.phones)))
    for span in utterance.phones:
        _feed_text(hasher, span.phoneme)
        hasher.update(struct.pack("<dd", span.start, span.end))
    if utterance.audio is None:
        hasher.update(b"\x00")
    else:
        hasher.update(b"\x01" + struct.pack("<q", utterance.audio.sample_rate))
        _feed_array(hasher, utterance.audio.samples, "<f4")
