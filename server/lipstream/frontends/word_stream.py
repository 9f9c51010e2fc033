"""Timings that arrive in chunks, as a TTS sends them while it speaks: complete words out,
the word at a chunk's edge held.

Method: a chunk's last word is held when it may not be over: a character chunk that ends
without white space may be cut inside a word, and a Polly word mark's end is the next
word's start. The next chunk completes it: its first word is joined to the held one
when that chunk starts without white space (the characters of one word), else the held
word ends where the next word starts if its end was not known. ``finish`` (the request's
end) releases the held word as it is: its end, if still unknown, comes from the duration
model. Phoneme and viseme chunks need no holding: they release any held word first.
"""

from __future__ import annotations

from dataclasses import replace

from .timings import SpeechTimings, TimedWord
from .words_to_spans import DEFAULT_VOICE


class WordStream:
    """One request's stream of timings; at most one word held."""

    def __init__(self) -> None:
        self.held: TimedWord | None = None
        self.held_format = ""
        self.voice = DEFAULT_VOICE
        """The espeak-ng voice of the stream's words (the last one a chunk named)."""

    def take(self, timings: SpeechTimings) -> list[SpeechTimings]:
        """What ``timings`` (the next chunk) completes, in order (possibly nothing)."""
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
        """The held word, if any, released as it is."""
        if self.held is None:
            return []
        held, self.held = self.held, None
        return [SpeechTimings(self.held_format, words=(held,))]


def _joined(first: TimedWord, rest: TimedWord) -> TimedWord:
    return TimedWord(
        first.text + rest.text,
        first.start,
        rest.end,
        first.where,
        first.characters + rest.characters,
    )
