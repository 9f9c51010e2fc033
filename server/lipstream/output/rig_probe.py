"""What the rig presets read from a model: its face at each phoneme and at rest in each emotion.

Sketch: the presets' key poses are the model's own poses. Each canonical
phoneme is held alone between silences and the frame at its centre is taken
(``probe_phoneme_poses``); each emotion's rest pose is the frame in the middle
of a second of silence in that emotion (``probe_rest_poses``). The server
probes once per model at start-up and hands the probe to every preset; the
command line probes only when a preset it builds needs it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..engines.base import Model, SynthesisRequest
from ..engines.work import WorkGuard
from ..phonemes import SILENCE
from ..timeline import PhonemeSpan
from .visemes import OCULUS15

NEUTRAL = "neutral"
BILABIALS = ("P", "B", "M")
CLOSURE_VOWELS = ("AA", "IY", "UW", "OW")
CLOSURE_CONTEXTS: tuple[tuple[str, str], ...] = tuple(
    (vowel, bilabial) for vowel in CLOSURE_VOWELS for bilabial in BILABIALS
)
"""Each bilabial between two of a vowel: an engine that coarticulates closes the lips in the
vowel's shape (rounded before /uw/, spread in /iy/)."""
PROBE_FPS = 100.0
_VOWEL_S = 0.2
_BILABIAL_S = 0.1
_GAP_S = 0.3


@dataclass(frozen=True, eq=False)
class RigProbe:
    """Poses float64 (n_channels,) of one model: ``phoneme_poses`` by canonical phoneme
    (``sil`` included), ``rest_poses`` by emotion (``neutral`` included), and
    ``closure_poses`` (len(CLOSURE_CONTEXTS), n_channels), the lips closed in context."""

    channels: tuple[str, ...]
    phoneme_poses: Mapping[str, np.ndarray]
    rest_poses: Mapping[str, np.ndarray]
    closure_poses: np.ndarray

    @property
    def silence(self) -> np.ndarray:
        return np.asarray(self.phoneme_poses[SILENCE], dtype=np.float64)

    @cached_property
    def viseme_poses(self) -> np.ndarray:
        """The 15 Oculus viseme key poses float64 (15, n_channels), in ``OCULUS15`` order."""
        from ..server.viseme_projection import key_poses

        return key_poses(dict(self.phoneme_poses), OCULUS15)

    def emotion_delta(self, emotion: str) -> np.ndarray:
        """How ``emotion`` changes the rest pose from neutral, float64 (n_channels,)."""
        delta: np.ndarray = np.subtract(
            self.rest_poses[emotion], self.rest_poses[NEUTRAL], dtype=np.float64
        )
        return delta


def probe_rig(
    model: Model, guard: WorkGuard | None = None, phoneme_source: Model | None = None
) -> RigProbe:
    """The probe of ``model`` (synthesized under ``guard`` when given), its phoneme poses
    probed from ``phoneme_source`` when given (the server's viseme source: the character's
    ``viseme-lerp`` model with the same channels)."""
    from ..server.viseme_projection import probe_phoneme_poses, probe_rest_poses

    rests = probe_rest_poses(model, guard)
    return RigProbe(
        tuple(model.channels),
        probe_phoneme_poses(phoneme_source or model, guard),
        {emotion: pose for emotion, pose in rests.items() if emotion is not None},
        probe_closures(model, guard),
    )


def probe_closures(model: Model, guard: WorkGuard | None = None) -> np.ndarray:
    """``model``'s frame at the centre of each bilabial of ``CLOSURE_CONTEXTS``, said as
    vowel-bilabial-vowel between silences; float64 (len(CLOSURE_CONTEXTS), n_channels)."""
    spans: list[PhonemeSpan] = []
    centres: list[float] = []
    start = _GAP_S
    for vowel, bilabial in CLOSURE_CONTEXTS:
        middle = start + _VOWEL_S
        spans += [
            PhonemeSpan(vowel, start, middle),
            PhonemeSpan(bilabial, middle, middle + _BILABIAL_S),
            PhonemeSpan(vowel, middle + _BILABIAL_S, middle + _BILABIAL_S + _VOWEL_S),
        ]
        centres.append(middle + _BILABIAL_S / 2)
        start = middle + _BILABIAL_S + _VOWEL_S + _GAP_S
    spans.append(PhonemeSpan(SILENCE, start, start + _GAP_S))
    synthesizer = model.start(SynthesisRequest(fps=PROBE_FPS, guard=guard or WorkGuard()))
    synthesizer.feed(spans)
    frames = np.asarray(synthesizer.finish(), dtype=np.float64)
    return frames[[round(centre * PROBE_FPS) for centre in centres]]
