"""The demo character's face: articulatory synthesis of ARKit-style blendshape curves.

Sketch (see docs/explanation/demo-character.md):
1. ``planning`` turns phoneme spans into per-articulator targets (window model
   for jaw and lip aperture, look-ahead for rounding and spreading, held lip
   contacts) and ``targets`` holds the per-phoneme windows.
2. Targets are personalised: per-token variation, speaker scales and resting
   pose, the emotion's amplitude, plus band-limited motor noise.
3. ``dynamics`` moves each articulator towards its target as a critically
   damped spring with a maximum speed, at the frame rate.
4. Articulator positions become channels. Lip aperture below zero is lips
   pressed together: the visible gap is clamped at 0 and the excess shows as
   mouthPress. Lips apart = jawOpen - mouthClose, as in ARKit.
5. Expression (emotion style with a slowly varying intensity), brow drift and
   emphasis raises on long vowels, and Poisson eye blinks are added on top.

Everything is drawn from generators seeded by (seed, speaker seed, emotion), so
the output is a pure function of the arguments.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..errors import InvalidRequestError
from ..tables import names
from ..timeline import PhonemeSpan
from .blinks import blink_track
from .dynamics import track_targets
from .expression import EMOTION_STYLES, EmotionStyle, emotion_style
from .noise import band_limited_noise
from .planning import CONTACT_ARTICULATORS, Segment, build_segments, plan_targets, sample_plan
from .speakers import DEMO_SPEAKERS, Speaker
from .targets import VOWELS, Articulator

__all__ = [
    "ARTICULATOR_MAX_SPEED",
    "DEMO_CHANNELS",
    "DEMO_SPEAKERS",
    "JAW_MAX_SPEED",
    "Speaker",
    "generate_face",
]

DEMO_CHANNELS: tuple[str, ...] = names("""
    jawOpen mouthClose mouthFunnel mouthPucker
    mouthStretchLeft mouthStretchRight mouthSmileLeft mouthSmileRight
    mouthPressLeft mouthPressRight mouthRollLower mouthRollUpper
    mouthLowerDownLeft mouthLowerDownRight mouthUpperUpLeft mouthUpperUpRight
    mouthShrugLower mouthShrugUpper cheekPuff browInnerUp
    browDownLeft browDownRight browOuterUpLeft browOuterUpRight
    eyeBlinkLeft eyeBlinkRight eyeSquintLeft eyeSquintRight
""")

ARTICULATOR_MAX_SPEED = np.array([4.5, 11.0, 3.5, 3.5, 20.0])
"""Fastest motion of (jaw, lips, round, spread, tuck) in units per second."""
JAW_MAX_SPEED = float(ARTICULATOR_MAX_SPEED[Articulator.JAW])
BASE_STIFFNESS = np.array([43.7, 55.2, 29.9, 34.5, 92.0])
"""Spring stiffness w (rad/s) per articulator towards a tolerant target."""
REQUIRED_STIFFNESS_GAIN = 1.25
"""Requirements (narrow windows) are approached more briskly."""
CONTACT_STIFFNESS_GAIN = 2.0
"""Lip closures and lip-on-teeth are ballistic: faster still."""
MOTOR_NOISE_SHAPE = np.array([1.0, 0.8, 0.6, 0.5, 0.3])
MOTOR_NOISE_HZ = 4.0
TOKEN_VARIATION = 0.06
FULL_PRESS = 0.12
"""Lip aperture this far below contact is a full lip press."""
ROUND_LIPS_OPEN = 0.25
"""Lip aperture at which rounding is all funnel and no pucker."""
MAX_FPS = 1000.0


def _check_arguments(duration_s: float, fps: float, seed: int, speaker: Speaker) -> None:
    if not isinstance(speaker, Speaker):
        raise InvalidRequestError(
            f"speaker must be a Speaker, got {type(speaker).__name__}", where="speaker"
        )
    if not (math.isfinite(fps) and 0 < fps <= MAX_FPS):
        raise InvalidRequestError(f"fps must be in (0, {MAX_FPS:g}], got {fps}", where="fps")
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise InvalidRequestError(
            f"duration must be positive, got {duration_s}", where="duration_s"
        )
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise InvalidRequestError(
            f"seed must be a non-negative integer, got {seed!r}", where="seed"
        )


def _personalise(
    values: np.ndarray, speaker: Speaker, style: EmotionStyle, rng: np.random.Generator
) -> np.ndarray:
    """Speaker- and emotion-specific targets from nominal ones, both (n_segments, 5)."""
    variation = 1.0 + TOKEN_VARIATION * rng.standard_normal(values.shape)
    nominal = np.where(values > 0, values * variation, values)
    shape_gain = 0.5 + 0.5 * style.amplitude
    out = nominal.copy()
    out[:, Articulator.JAW] = (
        speaker.rest_jaw + speaker.jaw_scale * style.amplitude * nominal[:, Articulator.JAW]
    )
    lips = nominal[:, Articulator.LIPS]
    out[:, Articulator.LIPS] = np.where(
        lips >= 0, speaker.rest_lips + speaker.lips_scale * style.amplitude * lips, lips
    )
    out[:, Articulator.ROUND] = speaker.rounding_scale * shape_gain * nominal[:, Articulator.ROUND]
    out[:, Articulator.SPREAD] = speaker.spread_scale * shape_gain * nominal[:, Articulator.SPREAD]
    return out


def _articulate(
    segments: Sequence[Segment],
    times: np.ndarray,
    speaker: Speaker,
    style: EmotionStyle,
    rngs: Sequence[np.random.Generator],
    fps: float,
) -> np.ndarray:
    """Articulator positions, shape (n_frames, 5)."""
    plan = plan_targets(segments, speaker.lookahead_s)
    values = _personalise(plan.values, speaker, style, rngs[0])
    gain = np.where(plan.narrow, REQUIRED_STIFFNESS_GAIN, 1.0)
    for articulator in CONTACT_ARTICULATORS:
        gain[plan.contact, articulator] = CONTACT_STIFFNESS_GAIN
    stiffness = BASE_STIFFNESS[None, :] * gain * speaker.stiffness_scale * style.stiffness
    targets = sample_plan(plan.onsets, values, times)
    noise_amplitude = speaker.noise_level * MOTOR_NOISE_SHAPE
    targets += band_limited_noise(rngs[1], len(times), fps, MOTOR_NOISE_HZ, noise_amplitude, 5)
    return track_targets(
        targets, sample_plan(plan.onsets, stiffness, times), ARTICULATOR_MAX_SPEED, fps
    )


def _mouth_channels(state: np.ndarray) -> dict[str, np.ndarray]:
    """Symmetric mouth channels from articulator positions (n_frames, 5)."""
    jaw = np.clip(state[:, Articulator.JAW], 0.0, 1.0)
    aperture = np.clip(state[:, Articulator.LIPS], 0.0, None)
    lips_apart = np.minimum(aperture, jaw)
    excess = np.clip(aperture - jaw, 0.0, 1.0)
    press = np.clip(-state[:, Articulator.LIPS] / FULL_PRESS, 0.0, 1.0)
    rounding = np.clip(state[:, Articulator.ROUND], 0.0, 1.0)
    spread = np.clip(state[:, Articulator.SPREAD], 0.0, 1.0)
    tuck = np.clip(state[:, Articulator.TUCK], 0.0, 1.0)
    openness = np.clip(aperture / ROUND_LIPS_OPEN, 0.0, 1.0)
    return {
        "jawOpen": jaw,
        "mouthClose": jaw - lips_apart,
        "mouthFunnel": rounding * openness,
        "mouthPucker": rounding * (1.0 - openness),
        "mouthStretch": 0.6 * spread,
        "mouthSmile": 0.2 * spread,
        "mouthPress": 0.55 * press,
        "mouthRollLower": 0.65 * tuck + 0.15 * press,
        "mouthRollUpper": 0.12 * press + 0.05 * tuck,
        "mouthLowerDown": 1.2 * excess + 0.15 * spread,
        "mouthUpperUp": 0.8 * excess + 0.15 * tuck + 0.1 * spread,
        "mouthShrugLower": 0.3 * tuck + 0.15 * rounding,
        "mouthShrugUpper": 0.2 * rounding + 0.05 * tuck,
        "cheekPuff": 0.12 * press,
    }


def _emphasis(
    segments: Sequence[Segment], times: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """Brow raises on the one or two longest vowels, shape (n_frames,)."""
    vowels = sorted(
        (segment for segment in segments if segment.phoneme in VOWELS),
        key=lambda segment: segment.end - segment.start,
        reverse=True,
    )
    raise_curve = np.zeros_like(times)
    for segment in vowels[: int(rng.integers(1, 3))]:
        phase = np.clip((times - segment.centre) / 0.4, -1.0, 1.0)
        raise_curve += float(rng.uniform(0.08, 0.2)) * 0.5 * (1.0 + np.cos(np.pi * phase))
    return raise_curve


def _expression(
    mouth: dict[str, np.ndarray],
    segments: Sequence[Segment],
    times: np.ndarray,
    speaker: Speaker,
    style: EmotionStyle,
    rngs: Sequence[np.random.Generator],
    fps: float,
) -> dict[str, np.ndarray]:
    """Adds emotion, brows and lids to ``mouth``; keys are channel stems or names."""
    n_frames = len(times)
    intensity = np.clip(1.0 + band_limited_noise(rngs[2], n_frames, fps, 0.3, 0.12)[:, 0], 0.7, 1.3)
    drift = band_limited_noise(rngs[3], n_frames, fps, 0.4, 0.025, 3)
    emphasis = _emphasis(segments, times, rngs[4]) * style.amplitude
    face = dict(mouth)
    face["mouthSmile"] = mouth["mouthSmile"] + speaker.rest_smile + style.smile * intensity
    face["mouthPress"] = mouth["mouthPress"] + style.press * intensity
    face["mouthStretch"] = mouth["mouthStretch"] + style.stretch * intensity
    face["mouthUpperUp"] = mouth["mouthUpperUp"] + style.upper_lip_raise * intensity
    face["mouthShrugLower"] = mouth["mouthShrugLower"] + style.chin_raise * intensity
    face["browInnerUp"] = (
        speaker.rest_brow + style.brow_inner_up * intensity + 0.6 * emphasis + drift[:, 0]
    )
    face["browDown"] = style.brow_down * intensity + drift[:, 1]
    face["browOuterUp"] = (
        speaker.rest_brow + style.brow_outer_up * intensity + emphasis + drift[:, 2]
    )
    face["eyeSquint"] = style.squint * intensity
    lid = style.lid_droop + 0.25 * face["eyeSquint"]
    blinks = blink_track(rngs[5], n_frames, fps, speaker.blinks_per_minute)
    face["eyeBlinkLeft"] = lid + (1.0 - lid) * blinks[:, 0]
    face["eyeBlinkRight"] = lid + (1.0 - lid) * blinks[:, 1]
    return face


def _assemble(face: dict[str, np.ndarray], asymmetry: float) -> np.ndarray:
    columns = []
    for channel in DEMO_CHANNELS:
        if channel in face:
            columns.append(face[channel])
        elif channel.endswith("Left"):
            columns.append(face[channel[: -len("Left")]] * (1.0 + asymmetry))
        else:
            columns.append(face[channel[: -len("Right")]] * (1.0 - asymmetry))
    return np.asarray(np.clip(np.stack(columns, axis=1), 0.0, 1.0), dtype=np.float32)


def generate_face(
    spans: Sequence[PhonemeSpan],
    duration_s: float,
    *,
    emotion: str,
    speaker: Speaker,
    fps: float = 120.0,
    seed: int,
) -> np.ndarray:
    """Blendshape curves for one utterance, shape (floor(duration_s * fps) + 1, len(DEMO_CHANNELS)).

    Frame ``i`` is at ``i / fps`` seconds; values are float32 in [0, 1], columns
    in ``DEMO_CHANNELS`` order. ``spans`` are canonical ARPAbet/``sil`` spans in
    seconds; time not covered by a span is silence.
    """
    _check_arguments(duration_s, fps, seed, speaker)
    style = emotion_style(emotion)
    n_frames = math.floor(duration_s * fps + 1e-9) + 1
    times = np.arange(n_frames) / fps
    entropy = [seed, speaker.seed, list(EMOTION_STYLES).index(emotion)]
    rngs = [np.random.default_rng(child) for child in np.random.SeedSequence(entropy).spawn(6)]
    segments = build_segments(spans, duration_s, speaker.lookahead_s)
    state = _articulate(segments, times, speaker, style, rngs, fps)
    face = _expression(_mouth_channels(state), segments, times, speaker, style, rngs, fps)
    return _assemble(face, speaker.asymmetry)
