"""Any parsed timings to the phoneme spans every engine takes.

Sketch: phoneme timings are used as they are, with silence where nothing is said;
viseme-only timings become representative phonemes (``viseme_spans``); word and
character timings get each word's phonemes from the lexicon (``lexicon``, all words of
the input at once, so espeak-ng reads them in context) and the duration model spreads
them over the word (``spreading``). The result runs contiguously from 0 s.
"""

from __future__ import annotations

from lipstream_client.errors import EMPTY_TIMINGS

from ..errors import LipstreamError
from ..phonemes import SILENCE
from ..timeline import PhonemeSpan
from .lexicon import pronounce
from .spreading import PronouncedWord, spread_words
from .timings import SpeechTimings
from .viseme_spans import viseme_spans
from .word_durations import WordDurationModel

DEFAULT_VOICE = "en-us"


def timings_to_spans(
    timings: SpeechTimings, durations: WordDurationModel, voice: str = DEFAULT_VOICE
) -> list[PhonemeSpan]:
    """Contiguous spans for ``timings``; ``voice``: the espeak-ng voice of the words."""
    if timings.phonemes:
        spans = _with_silences(list(timings.phonemes))
    elif timings.visemes:
        spans = viseme_spans(durations, timings.visemes)
    else:
        texts = [word.text for word in timings.words]
        pronunciations = pronounce(texts, voice) if texts else []
        words = [
            PronouncedWord(pronunciation, word.start, word.end)
            for word, pronunciation in zip(timings.words, pronunciations)
        ]
        spans = spread_words(durations, words) if words else []
    if not any(span.phoneme != SILENCE for span in spans):
        raise LipstreamError(
            "the timings hold no word, viseme or phoneme that is spoken",
            where="input",
            code=EMPTY_TIMINGS,
        )
    return spans


def _with_silences(phonemes: list[PhonemeSpan]) -> list[PhonemeSpan]:
    spans: list[PhonemeSpan] = []
    clock = 0.0
    for span in phonemes:
        if span.start > clock:
            if spans and spans[-1].phoneme == SILENCE:
                spans[-1] = PhonemeSpan(SILENCE, spans[-1].start, span.start)
            else:
                spans.append(PhonemeSpan(SILENCE, clock, span.start))
        start = max(span.start, clock)
        if span.end > start:
            if spans and span.phoneme == SILENCE and spans[-1].phoneme == SILENCE:
                spans[-1] = PhonemeSpan(SILENCE, spans[-1].start, span.end)
            else:
                spans.append(PhonemeSpan(span.phoneme, start, span.end))
            clock = span.end
    return spans
