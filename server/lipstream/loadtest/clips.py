"""Speech-like phoneme clips of an exact length for the load test.

Sketch: Audio2Face-3D's benchmark streams recorded speech clips of 5, 10 and
20 s. lipstream takes phonemes, so the load test builds clips with the
timing statistics of conversational English instead: words of 2 to 6
phonemes alternating consonants (40 to 110 ms) and vowels (70 to 200 ms),
with a silence of 80 to 300 ms between words, drawn from a seeded generator
so every run sends the same clips. The clip opens with a short silence and
its last phoneme is stretched or cut so the clip ends exactly at its length.
"""

from __future__ import annotations

import random

from ..errors import InvalidRequestError
from ..phonemes import ARPABET, SILENCE

VOWELS: tuple[str, ...] = tuple(p for p in ARPABET if p[0] in "AEIOU")
CONSONANTS: tuple[str, ...] = tuple(p for p in ARPABET if p not in VOWELS)
CONSONANT_MS = (40.0, 110.0)
VOWEL_MS = (70.0, 200.0)
PAUSE_MS = (80.0, 300.0)
WORD_PHONEMES = (2, 6)
LEADING_SILENCE_S = 0.1
MIN_LAST_S = 0.03
MAX_CLIP_S = 600.0

Span = tuple[str, float, float]


def _draw_ms(generator: random.Random, bounds: tuple[float, float]) -> float:
    return generator.uniform(*bounds) / 1000.0


def synthetic_clip(duration_s: float, seed: int = 0) -> list[Span]:
    """Contiguous (ARPAbet phoneme, start s, end s) spans from 0 to ``duration_s``."""
    if not 0.2 <= duration_s <= MAX_CLIP_S:
        raise InvalidRequestError(
            f"clip length must be in [0.2, {MAX_CLIP_S:g}] s, got {duration_s!r}", where="clip"
        )
    generator = random.Random(seed)
    spans: list[Span] = [(SILENCE, 0.0, LEADING_SILENCE_S)]
    clock = LEADING_SILENCE_S
    while clock < duration_s:
        for position in range(generator.randint(*WORD_PHONEMES)):
            vowel = position % 2 == 1
            label = generator.choice(VOWELS if vowel else CONSONANTS)
            length = _draw_ms(generator, VOWEL_MS if vowel else CONSONANT_MS)
            spans.append((label, clock, clock + length))
            clock += length
        pause = _draw_ms(generator, PAUSE_MS)
        spans.append((SILENCE, clock, clock + pause))
        clock += pause
    return _cut(spans, duration_s)


def _cut(spans: list[Span], duration_s: float) -> list[Span]:
    """Keep the spans that start early enough and end the last one at ``duration_s``."""
    kept = [span for span in spans if span[1] <= duration_s - MIN_LAST_S]
    label, start, _ = kept[-1]
    kept[-1] = (label, start, duration_s)
    return kept
