"""The common type every timing format parses to: words, characters, visemes or phonemes
with times in seconds on the utterance clock.

Sketch: a format yields what it carries and nothing more. Word formats give
``TimedWord``s (an end may be unknown: Polly's word marks have only a start), character
formats give words whose ``characters`` carry their own times (and word formats with
visemes, words whose ``visemes`` are those said within them, and every viseme besides),
phoneme formats give ``PhonemeSpan``s directly and viseme-only formats give
``TimedViseme``s. ``where`` on
each item names its place in the input ("alignment.characters[12]"), so a later step's
error points back into the user's file.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from ..timeline import PhonemeSpan

TIMING_FORMATS: tuple[str, ...] = ("words", "elevenlabs", "azure", "polly", "ipa")
"""Every format ``formats.parse_timings`` reads; "auto" detects one from the content."""


@dataclass(frozen=True, slots=True)
class TimedCharacter:
    """One character of a word, spoken over [start, end] seconds."""

    char: str
    start: float
    end: float


@dataclass(frozen=True, slots=True)
class TimedViseme:
    """A viseme of ``scheme`` ("azure": IDs 0-21, "polly": Polly's viseme letters) that
    starts at ``start`` seconds and lasts until the next one."""

    scheme: str
    viseme: str
    start: float
    where: str


@dataclass(frozen=True, slots=True)
class TimedWord:
    """One written word spoken over [start, end] seconds; ``end`` None: not given (a later
    step estimates it); ``characters``: each character's own time, when the format has it;
    ``visemes``: the viseme events said within the word, when the format gives them
    beside its words (Azure, Polly)."""

    text: str
    start: float
    end: float | None
    where: str
    characters: tuple[TimedCharacter, ...] = ()
    visemes: tuple[TimedViseme, ...] = ()


@dataclass(frozen=True)
class SpeechTimings:
    """What one timing input carries, in time order; exactly what its format gives."""

    format: str
    words: tuple[TimedWord, ...] = ()
    visemes: tuple[TimedViseme, ...] = ()
    phonemes: tuple[PhonemeSpan, ...] = ()
    continues_word: bool = False
    """The first word may be the rest of a word cut at the previous chunk's end (a
    character chunk that starts without white space)."""
    last_word_open: bool = False
    """The last word may go on in the next chunk (a character chunk that ends without white
    space), or its end is not known yet (a Polly word mark)."""

    @property
    def start_s(self) -> float | None:
        """The earliest time the input states (None when it states none)."""
        times = [word.start for word in self.words[:1]] + [v.start for v in self.visemes[:1]]
        times += [span.start for span in self.phonemes[:1]]
        return min(times, default=None)

    def shifted(self, offset_s: float) -> SpeechTimings:
        """The same timings ``offset_s`` seconds later."""
        if not offset_s:
            return self
        return replace(
            self,
            words=tuple(_shifted_word(word, offset_s) for word in self.words),
            visemes=tuple(replace(v, start=v.start + offset_s) for v in self.visemes),
            phonemes=tuple(
                PhonemeSpan(s.phoneme, s.start + offset_s, s.end + offset_s, s.emotion)
                for s in self.phonemes
            ),
        )

    @property
    def end_s(self) -> float:
        """The latest time the input states (0 when it states none)."""
        times = [0.0]
        times += [word.end if word.end is not None else word.start for word in self.words]
        times += [viseme.start for viseme in self.visemes]
        times += [span.end for span in self.phonemes]
        return max(times)


def _shifted_word(word: TimedWord, offset_s: float) -> TimedWord:
    return replace(
        word,
        start=word.start + offset_s,
        end=None if word.end is None else word.end + offset_s,
        characters=tuple(
            TimedCharacter(c.char, c.start + offset_s, c.end + offset_s) for c in word.characters
        ),
        visemes=tuple(replace(v, start=v.start + offset_s) for v in word.visemes),
    )
