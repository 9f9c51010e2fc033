"""The sentences a visitor is asked to read: few, and covering the phonemes evenly.

Sketch: every sentence of the demo script (``demo/sentences.txt``) is spoken once by
espeak-ng (one batch in its worker, kept for the process's life) and reduced to its set of
phonemes (silence aside). Then greedy set cover, in rounds: round ``k`` wants every phoneme
the script holds in at least ``k`` chosen sentences, and each pick is the sentence that
gives the most phonemes still short of ``k`` (ties: fewer phonemes, so shorter to read,
then the script's order); when a round is met the next begins. The choice is deterministic.
A client may instead give its own sentences (``checked_sentences``).
"""

from __future__ import annotations

import functools
from collections import Counter
from collections.abc import Sequence

from ..demo.sentences import load_sentences
from ..errors import LipstreamError
from ..phonemes import SILENCE
from ..speech.espeak import read_mnemonic
from ..speech.worker import SpeechRequest, speak_in_worker

SPEECH_TIMEOUT_S = 120.0
MAX_SENTENCE_CHARS = 300


@functools.cache
def script_phonemes() -> tuple[tuple[str, frozenset[str]], ...]:
    """Each demo sentence with the set of phonemes espeak-ng says in it (read once)."""
    sentences = load_sentences()
    spoken = speak_in_worker([SpeechRequest(text) for text in sentences], SPEECH_TIMEOUT_S)
    table = []
    for text, (_pcm, _rate, events) in zip(sentences, spoken, strict=True):
        phonemes = {
            phoneme
            for name, _ms in events
            for phoneme in read_mnemonic(name, "prompts")
            if phoneme != SILENCE
        }
        table.append((text, frozenset(phonemes)))
    return tuple(table)


def cover(table: Sequence[tuple[str, frozenset[str]]], count: int) -> list[str]:
    """``count`` sentences of ``table`` by greedy set cover in rounds (see the module)."""
    wanted = frozenset().union(*(phonemes for _, phonemes in table)) if table else frozenset()
    seen: Counter[str] = Counter()
    left = list(range(len(table)))
    chosen: list[str] = []
    level = 1
    while left and len(chosen) < count:
        if all(seen[phoneme] >= level for phoneme in wanted):
            level += 1
            continue

        best = min(left, key=lambda index: _rank(table[index][1], seen, level, index))
        left.remove(best)
        chosen.append(table[best][0])
        seen.update(table[best][1])
    return chosen


def _rank(
    phonemes: frozenset[str], seen: Counter[str], level: int, index: int
) -> tuple[int, int, int]:
    """The pick goes to the smallest rank: most phonemes short of ``level``, then fewest
    phonemes, then first."""
    short = sum(1 for phoneme in phonemes if seen[phoneme] < level)
    return (-short, len(phonemes), index)


def choose_prompts(count: int) -> list[str]:
    """``count`` demo sentences covering the phonemes evenly (runs espeak-ng the first time:
    call off the event loop)."""
    return cover(script_phonemes(), count)


def checked_sentences(value: object, max_count: int) -> list[str]:
    """A client's own prompt sentences: a non-empty list of at most ``max_count`` printable
    strings of at most ``MAX_SENTENCE_CHARS``; ``invalid_request`` or ``too_many_takes``
    naming the item."""
    from .errors import TOO_MANY_TAKES

    if not isinstance(value, list) or not value:
        raise LipstreamError(
            "must be a non-empty list of sentences", where="sentences", code="invalid_request"
        )
    if len(value) > max_count:
        raise LipstreamError(
            f"{len(value)} sentences; a session takes at most {max_count} recordings",
            where="sentences",
            code=TOO_MANY_TAKES,
        )
    sentences = []
    for index, sentence in enumerate(value):
        where = f"sentences[{index}]"
        if not isinstance(sentence, str) or not sentence.strip():
            raise LipstreamError("must be a non-empty string", where=where, code="invalid_request")
        text = " ".join(sentence.split())
        if len(text) > MAX_SENTENCE_CHARS or not text.isprintable():
            raise LipstreamError(
                f"must be printable text of at most {MAX_SENTENCE_CHARS} characters",
                where=where,
                code="invalid_request",
            )
        sentences.append(text)
    return sentences
