"""Model probes: its face at each phoneme, at rest in each emotion, and lips closed in context.

Sketch: viseme projections and rig presets take their key poses from the
model's own frames. Each canonical phoneme is held 200 ms alone between
silences and the frame at its centre is taken (``probe_phoneme_poses``;
``key_poses`` averages them per viseme class); each emotion's rest pose is
the frame in the middle of a second of silence in that emotion
(``probe_rest_poses``); each bilabial is said between other sounds and the
frame at its centre taken (``probe_closures``). The server probes once per
model at start-up and hands the probes (``RigProbe``) to every preset; the
command line probes only when a preset it builds needs it. Only mouth
channels (``mouth_channels``) enter mouth key poses.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..engines.base import Model, SynthesisRequest
from ..engines.work import WorkGuard
from ..errors import ModelStoreError
from ..phonemes import PHONEMES, SILENCE
from ..timeline import EMOTIONS, PhonemeSpan
from ..visemes import OCULUS15, VisemeScheme

NEUTRAL = "neutral"
BILABIALS = ("P", "B", "M")
CLOSURE_VOWELS = ("AA", "IY", "UW", "OW")
CLOSURE_CONTEXTS: tuple[tuple[str, str, str], ...] = tuple(
    (before, bilabial, after)
    for before in (SILENCE, *CLOSURE_VOWELS)
    for after in CLOSURE_VOWELS
    for bilabial in BILABIALS
)
"""(before, bilabial, after): each bilabial after a silence or a vowel and before a vowel. An
engine that coarticulates closes the lips in the shape of the sounds around them (rounded
before /uw/, spread in /iy/), so a closure looks different in each of the 60 contexts."""
PROBE_FPS = 100.0
PROBE_HOLD_S = 0.2
PROBE_GAP_S = 0.3
REST_PROBE_S = 1.0
MOUTH_PREFIXES = ("jaw", "mouth", "cheek", "tongue")
_BILABIAL_S = 0.1


def mouth_channels(channels: tuple[str, ...]) -> np.ndarray:
    """Boolean mask (n_channels,) of the mouth channels; all True if the rig names none."""
    mask = np.array([name.lower().startswith(MOUTH_PREFIXES) for name in channels], dtype=bool)
    return mask if mask.any() else np.ones(len(channels), dtype=bool)


def probe_phoneme_poses(model: Model, guard: WorkGuard | None = None) -> dict[str, np.ndarray]:
    """Each canonical phoneme's pose, float64 (n_channels,): ``model``'s frame at the centre
    of the phoneme held alone between silences (silence: the centre of the first gap),
    synthesized under ``guard`` when given."""
    spans: list[PhonemeSpan] = []
    centres: dict[str, float] = {SILENCE: PROBE_GAP_S / 2}
    start = PROBE_GAP_S
    for phoneme in PHONEMES:
        if phoneme == SILENCE:
            continue
        spans.append(PhonemeSpan(phoneme, start, start + PROBE_HOLD_S))
        centres[phoneme] = start + PROBE_HOLD_S / 2
        start += PROBE_HOLD_S + PROBE_GAP_S
    spans.append(PhonemeSpan(SILENCE, start, start + PROBE_GAP_S))
    synthesizer = model.start(SynthesisRequest(fps=PROBE_FPS, guard=guard or WorkGuard()))
    synthesizer.feed(spans)
    frames = np.asarray(synthesizer.finish(), dtype=np.float64)
    return {phoneme: frames[round(centre * PROBE_FPS)] for phoneme, centre in centres.items()}


def probe_rest_poses(model: Model, guard: WorkGuard | None = None) -> dict[str | None, np.ndarray]:
    """The rest pose per emotion, synthesized under ``guard``; a model whose silence is not
    finite is refused."""
    silence = [PhonemeSpan(SILENCE, 0.0, REST_PROBE_S)]
    poses: dict[str | None, np.ndarray] = {}
    for emotion in (None, *EMOTIONS):
        fps = float(model.manifest.fps)
        request = SynthesisRequest(fps=fps, emotion=emotion, guard=guard or WorkGuard())
        synthesizer = model.start(request)
        synthesizer.feed(silence)
        frames = synthesizer.finish()
        if not np.isfinite(frames).all():
            raise ModelStoreError(
                f"synthesizes NaN or infinite frames for silence (emotion {emotion})",
                where=f"model {model.manifest.engine}/{model.name}",
            )
        poses[emotion] = np.asarray(frames[len(frames) // 2], dtype=np.float32)
    return poses


def key_poses(phoneme_poses: dict[str, np.ndarray], scheme: VisemeScheme) -> np.ndarray:
    """Key poses float64 (n_classes, n_channels), rows in ``scheme.classes`` order: the mean
    pose of each class's phonemes."""
    return np.stack(
        [
            np.mean([phoneme_poses[phoneme] for phoneme in scheme.members(viseme)], axis=0)
            for viseme in scheme.classes
        ]
    )


def probe_key_poses(model: Model, scheme: VisemeScheme = OCULUS15) -> np.ndarray:
    """Key poses float64 (n_classes, n_channels) of ``scheme``, probed from ``model``."""
    return key_poses(probe_phoneme_poses(model), scheme)


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
    rests = probe_rest_poses(model, guard)
    return RigProbe(
        tuple(model.channels),
        probe_phoneme_poses(phoneme_source or model, guard),
        {emotion: pose for emotion, pose in rests.items() if emotion is not None},
        probe_closures(model, guard),
    )


def probe_closures(model: Model, guard: WorkGuard | None = None) -> np.ndarray:
    """``model``'s frame at the centre of each bilabial of ``CLOSURE_CONTEXTS``, each context
    said between silences (a vowel 200 ms, the bilabial 100 ms); float64
    (len(CLOSURE_CONTEXTS), n_channels)."""
    spans: list[PhonemeSpan] = []
    centres: list[float] = []
    start = PROBE_GAP_S
    for before, bilabial, after in CLOSURE_CONTEXTS:
        if before != SILENCE:
            spans.append(PhonemeSpan(before, start, start + PROBE_HOLD_S))
            start += PROBE_HOLD_S
        spans.append(PhonemeSpan(bilabial, start, start + _BILABIAL_S))
        centres.append(start + _BILABIAL_S / 2)
        start += _BILABIAL_S
        spans.append(PhonemeSpan(after, start, start + PROBE_HOLD_S))
        start += PROBE_HOLD_S + PROBE_GAP_S
    spans.append(PhonemeSpan(SILENCE, start, start + PROBE_GAP_S))
    synthesizer = model.start(SynthesisRequest(fps=PROBE_FPS, guard=guard or WorkGuard()))
    synthesizer.feed(spans)
    frames = np.asarray(synthesizer.finish(), dtype=np.float64)
    return frames[[round(centre * PROBE_FPS) for centre in centres]]
