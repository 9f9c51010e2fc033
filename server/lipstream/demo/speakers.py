"""The demo character's speakers: per-person articulation, voice and habits.

Sketch: a speaker is a handful of physical traits (how far each articulator
moves, the resting pose, how noisy and how quick the motion is, how far ahead
the lips anticipate rounding, a left/right asymmetry, blink rate) plus an
espeak-ng voice. ``Speaker.from_seed`` draws every trait from fixed ranges with
a seeded generator, so a speaker is reproducible from its name and seed alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from ..errors import InvalidRequestError

_LIMITS: dict[str, tuple[float, float]] = {
    "pitch": (0, 100),
    "rate_factor": (0.5, 2.0),
    "jaw_scale": (0.1, 3.0),
    "lips_scale": (0.1, 3.0),
    "rounding_scale": (0.1, 3.0),
    "spread_scale": (0.1, 3.0),
    "rest_jaw": (0.0, 0.3),
    "rest_lips": (-0.1, 0.2),
    "rest_smile": (0.0, 0.5),
    "rest_brow": (0.0, 0.5),
    "asymmetry": (-0.3, 0.3),
    "noise_level": (0.0, 0.1),
    "stiffness_scale": (0.3, 3.0),
    "lookahead_s": (0.0, 1.0),
    "blinks_per_minute": (0.0, 60.0),
}


@dataclass(frozen=True)
class Speaker:
    """One person of the demo character.

    Scales multiply articulator excursions; ``rest_*`` are resting-pose offsets
    in channel units; ``noise_level`` is the motor-noise standard deviation in
    jawOpen units; ``lookahead_s`` bounds anticipatory lip rounding; ``pitch``
    (espeak 0..100) and ``rate_factor`` (times the emotion's words per minute)
    shape the voice.
    """

    name: str
    seed: int
    voice: str = "en-us"
    pitch: int = 50
    rate_factor: float = 1.0
    jaw_scale: float = 1.0
    lips_scale: float = 1.0
    rounding_scale: float = 1.0
    spread_scale: float = 1.0
    rest_jaw: float = 0.03
    rest_lips: float = 0.0
    rest_smile: float = 0.0
    rest_brow: float = 0.0
    asymmetry: float = 0.0
    noise_level: float = 0.01
    stiffness_scale: float = 1.0
    lookahead_s: float = 0.08
    blinks_per_minute: float = 17.0

    def __post_init__(self) -> None:
        where = f"speaker {self.name!r}"
        if not isinstance(self.name, str) or not self.name:
            raise InvalidRequestError("speaker name must be a non-empty string", where="speaker")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise InvalidRequestError(
                f"seed must be a non-negative integer, got {self.seed!r}", where=where
            )
        for item in fields(self):
            if item.name in _LIMITS:
                self._check(item.name, where)

    def _check(self, name: str, where: str) -> None:
        value = getattr(self, name)
        low, high = _LIMITS[name]
        if (
            not isinstance(value, (int, float))
            or not math.isfinite(value)
            or not low <= value <= high
        ):
            raise InvalidRequestError(
                f"{name} must be in [{low}, {high}], got {value!r}", where=where
            )

    @classmethod
    def from_seed(cls, name: str, seed: int, voice: str = "en-us") -> Speaker:
        """A speaker whose traits are drawn deterministically from ``seed``."""
        rng = np.random.default_rng(seed)

        def draw(low: float, high: float) -> float:
            return round(float(rng.uniform(low, high)), 4)

        return cls(
            name=name,
            seed=seed,
            voice=voice,
            pitch=int(rng.integers(38, 63)),
            rate_factor=draw(0.92, 1.08),
            jaw_scale=draw(0.85, 1.15),
            lips_scale=draw(0.85, 1.15),
            rounding_scale=draw(0.8, 1.2),
            spread_scale=draw(0.8, 1.2),
            rest_jaw=draw(0.01, 0.05),
            rest_lips=draw(-0.015, 0.03),
            rest_smile=draw(0.0, 0.08),
            rest_brow=draw(0.0, 0.08),
            asymmetry=draw(-0.08, 0.08),
            noise_level=draw(0.006, 0.014),
            stiffness_scale=draw(0.9, 1.1),
            lookahead_s=draw(0.06, 0.1),
            blinks_per_minute=draw(15.0, 20.0),
        )


DEMO_SPEAKERS: tuple[Speaker, ...] = (
    Speaker.from_seed("ava", 1701, voice="en-us+f3"),
    Speaker.from_seed("ben", 2718, voice="en-us+m3"),
    Speaker.from_seed("cora", 3141, voice="en-us+f4"),
)
