"""Timings that arrive in chunks, as a TTS sends them while it speaks: complete words out,
the word at a chunk's edge held.

Method: a chunk's last word is held when it may not be over: a character chunk that ends
without white space may be cut inside a word, and a Polly word mark's end is the next
word's start. The next chunk completes it: its first word is joined to the held one
when that chunk starts without white space (the characters of one word), else the held
word ends where the next word starts if its end was not known. ``finish`` (the request's
end) releases the held word as it is: its end, if still unknown, comes from the duration
model. Phoneme and viseme chunks need no holding: they release any held word first.

Word timings with visemes (Azure word boundaries with viseme events, Polly word marks
with viseme marks) come in time order across chunks, and a word's visemes may come in a
later chunk than the word. So the chunk's last word is held until an event at or after
its end arrives (a later chunk's word or viseme) or the request ends, and a later
chunk's visemes said within it join it (``viseme_anchors.within_words``, as if both had
come in one chunk; a Polly word without an end ends at the next word or ``sil``
viseme). Visemes between words are passed over, as in one chunk; a viseme before the
end of a word already released came out of time order: ``non_monotonic_times``. Silence
visemes before anything is said (Azure's viseme 0 at 0 s) wait for the next chunk, which
says whether words come (they are passed over) or visemes alone (they lead them).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

from lipstream_client.errors import NON_MONOTONIC_TIMES

from ..errors import LipstreamError
from ..phonemes import SILENCE
from .formats.polly import word_end as polly_word_end
from .timing_checks import OVERLAP_TOLERANCE_S
from .timings import SpeechTimings, TimedViseme, TimedWord
from .viseme_anchors import VISEME_OF, WORD_EDGE_S, within_words
from .words_to_spans import DEFAULT_VOICE

MARKED_FORMATS = ("azure", "polly")
"""Word formats whose visemes come beside the words (possibly in a later chunk)."""


class WordStream:
    """One request's stream of timings; at most one word held."""

    def __init__(self) -> None:
        self.held: TimedWord | None = None
        self.held_format = ""
        self.voice = DEFAULT_VOICE
        """The espeak-ng voice of the stream's words (the last one a chunk named)."""
        self.marked_words = False
        """Azure or Polly words have come: their formats' visemes belong to words."""
        self.released_until = 0.0
        """The end of the last word with visemes released: no viseme may come before it."""
        self.leading: tuple[TimedViseme, ...] = ()
        """Silence visemes before anything was said: whether words follow is not known."""

    def take(self, timings: SpeechTimings) -> list[SpeechTimings]:
        """What ``timings`` (the next chunk) completes, in order (possibly nothing)."""
        if timings.format in MARKED_FORMATS and not self.marked_words and not timings.words:
            if all(_silent(viseme) for viseme in timings.visemes):
                self.leading += timings.visemes
                return []
        if self.leading:
            leading, self.leading = self.leading, ()
            timings = replace(timings, visemes=leading + timings.visemes)
        if timings.format in MARKED_FORMATS and (timings.words or self.marked_words):
            return self._take_marked(timings)
        if not timings.words:
            said = timings.phonemes or timings.visemes
            return self.finish() + ([timings] if said else [])
        words = list(timings.words)
        if self.held is not None:
            held, self.held = self.held, None
            if timings.continues_word and self.held_format == timings.format:
                words[0] = _joined(held, words[0])
            else:
                if held.end is None:
                    held = replace(held, end=words[0].start)
                words.insert(0, held)
        if timings.last_word_open:
            self.held, self.held_format = words.pop(), timings.format
        return [replace(timings, words=tuple(words))] if words else []

    def finish(self) -> list[SpeechTimings]:
        """The held word, if any, released as it is (or the leading silence visemes)."""
        if self.leading:
            leading, self.leading = self.leading, ()
            return [SpeechTimings(leading[0].scheme, visemes=leading)]
        if self.held is None:
            return []
        held, self.held = self.held, None
        return [SpeechTimings(self.held_format, words=(held,))]

    def _take_marked(self, timings: SpeechTimings) -> list[SpeechTimings]:
        """An Azure or Polly chunk: words, visemes or both (module sketch)."""
        self._refuse_late(timings.visemes)
        released = self.finish() if self.held_format != timings.format else []
        self.marked_words = True
        words = list(timings.words)
        visemes = list(timings.visemes)
        if self.held is not None:
            held, self.held = self.held, None
            words.insert(0, held)
            visemes = list(held.visemes) + visemes
        if not words:
            return released
        words = _regrouped(timings.format, words, visemes)
        if not _over(words[-1], timings.visemes):
            self.held, self.held_format = words.pop(), timings.format
        if not words:
            return released
        self.released_until = max(self.released_until, *(w.end or w.start for w in words))
        return [*released, SpeechTimings(timings.format, words=tuple(words))]

    def _refuse_late(self, visemes: Sequence[TimedViseme]) -> None:
        for viseme in visemes:
            if viseme.start < self.released_until - OVERLAP_TOLERANCE_S:
                raise LipstreamError(
                    f"a viseme at {viseme.start:.6g} s came after the words up to "
                    f"{self.released_until:.6g} s were released: visemes must come in time "
                    "order, at the latest in the chunk after their word's",
                    where=viseme.where,
                    code=NON_MONOTONIC_TIMES,
                )


def _regrouped(
    scheme: str, words: list[TimedWord], visemes: Sequence[TimedViseme]
) -> list[TimedWord]:
    """``words`` with their ends closed where the events now known close them, and each
    with the ``visemes`` said within it."""
    closed = []
    for index, word in enumerate(words):
        following = words[index + 1].start if index + 1 < len(words) else None
        if word.end is None:
            end = polly_word_end(word.start, following, visemes) if scheme == "polly" else following
            word = replace(word, end=end)
        closed.append(word)
    said = within_words([w.start for w in closed], [w.end for w in closed], visemes)
    return [replace(word, visemes=group) for word, group in zip(closed, said)]


def _silent(viseme: TimedViseme) -> bool:
    return viseme.viseme == VISEME_OF[viseme.scheme][SILENCE]


def _over(word: TimedWord, visemes: Sequence[TimedViseme]) -> bool:
    """Whether no viseme of ``word`` can come later: its end is known and an event of
    the chunk starts at or after it."""
    end = word.end
    return end is not None and any(v.start >= end - WORD_EDGE_S for v in visemes)


def _joined(first: TimedWord, rest: TimedWord) -> TimedWord:
    return TimedWord(
        first.text + rest.text,
        first.start,
        rest.end,
        first.where,
        first.characters + rest.characters,
    )
