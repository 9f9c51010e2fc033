"""Any parsed timings to the phoneme spans every engine takes.

Sketch: phoneme timings are used as they are, with silence where nothing is said;
viseme-only timings become representative phonemes (``viseme_spans``); word and
character timings get each word's phonemes from the lexicon (``lexicon``, all words of
the input at once, so espeak-ng reads them in context) and the duration model spreads
them over the word (``spreading``), between the onsets that an English word's character
times fix where its letters align with its phonemes with confidence
(``letter_alignment``), or that the viseme events said within a word fix where they
pair with its phonemes (``viseme_anchors``). The result runs contiguously from 0 s, or
from where earlier input ended (a stream of timings, ``word_stream``).
"""

from __future__ import annotations

from lipstream_client.errors import EMPTY_TIMINGS, NON_MONOTONIC_TIMES

from ..errors import LipstreamError
from ..phonemes import SILENCE
from ..timeline import PhonemeSpan
from .letter_alignment import letter_onsets
from .lexicon import pronounce
from .spreading import PronouncedWord, spread_words
from .timing_checks import OVERLAP_TOLERANCE_S
from .timings import SpeechTimings
from .viseme_anchors import viseme_onsets
from .viseme_spans import viseme_spans
from .word_durations import WordDurationModel

DEFAULT_VOICE = "en-us"


def timings_to_spans(
    timings: SpeechTimings,
    durations: WordDurationModel,
    voice: str = DEFAULT_VOICE,
    after: float = 0.0,
    *,
    require_speech: bool = True,
) -> list[PhonemeSpan]:
    """Contiguous spans for ``timings`` from ``after`` (the end of earlier input; a time
    before it is ``non_monotonic_times``); ``voice``: the espeak-ng voice of the words.
    ``require_speech``: timings with nothing spoken are ``empty_timings`` (a chunk of a
    stream may be only a pause)."""
    first = timings.start_s
    if first is not None and first < after - OVERLAP_TOLERANCE_S:
        raise LipstreamError(
            f"the timings start at {first:.6g} s, before the input so far ends at {after:.6g} s",
            where="input",
            code=NON_MONOTONIC_TIMES,
        )
    if timings.phonemes:
        spans = _with_silences(list(timings.phonemes), after)
    elif timings.visemes and not timings.words:
        spans = viseme_spans(durations, timings.visemes, after)
    else:
        texts = [word.text for word in timings.words]
        pronunciations = pronounce(texts, voice) if texts else []
        english = voice.lower().startswith("en")
        words = [
            PronouncedWord(
                pronunciation,
                word.start,
                word.end,
                (letter_onsets(word.characters, pronunciation) if english else ())
                or viseme_onsets(word.visemes, pronunciation, word.start, word.end),
            )
            for word, pronunciation in zip(timings.words, pronunciations)
        ]
        spans = spread_words(durations, words, after) if words else []
    if require_speech and not any(span.phoneme != SILENCE for span in spans):
        raise LipstreamError(
            "the timings hold no word, viseme or phoneme that is spoken",
            where="input",
            code=EMPTY_TIMINGS,
        )
    return spans


def _with_silences(phonemes: list[PhonemeSpan], after: float) -> list[PhonemeSpan]:
    spans: list[PhonemeSpan] = []
    clock = after
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
