"""What espeak-ng said, word by word: each written word's phonemes with their times.

Sketch: espeak-ng reports a word event (the word's first character in the text, and
its start in the audio) before the phoneme events of that word. Merged in time order
(a word event before a phoneme event at the same millisecond), every phoneme event
after a word event and before the next belongs to the written token (white-space
separated) holding that word's first character; pause phonemes belong to none. A token
espeak-ng expands ("$42") collects every word spoken from it. Each phoneme lasts until
the next phoneme event, so a token runs from its first phoneme's start to its last
phoneme's end. These are espeak-ng's own timings, the reference the word-timing front
ends are measured against.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from ..audio import Audio
from ..timeline import PhonemeSpan
from .espeak import EventReader, speech_result
from .text_frontend import choose_voice, event_reader
from .worker import SpeechRequest, WordedSpeech, speak_words_in_worker


@dataclass(frozen=True)
class SpokenWord:
    """A written token and the phonemes espeak-ng spoke for it, in seconds."""

    text: str
    phonemes: tuple[PhonemeSpan, ...]

    @property
    def start(self) -> float:
        return self.phonemes[0].start

    @property
    def end(self) -> float:
        return self.phonemes[-1].end


@dataclass(frozen=True)
class SpokenUtterance:
    """espeak-ng's audio for a text, its contiguous spans and its spoken words."""

    text: str
    audio: Audio
    spans: list[PhonemeSpan]
    words: list[SpokenWord]


def speak_words(
    texts: Sequence[str], voice: str = "en-us", rate: int = 175
) -> list[SpokenUtterance]:
    """Each text spoken (one worker process for all) with its words; ``voice`` an
    espeak-ng voice, of any language (``text_frontend.choose_voice``)."""
    choice = choose_voice(voice, None)
    requests = [
        SpeechRequest(text, choice.voice, rate, ipa_names=choice.ipa_names) for text in texts
    ]
    read = event_reader(choice)
    spoken = speak_words_in_worker(requests)
    return [_utterance(text, result, read) for text, result in zip(texts, spoken)]


def _utterance(text: str, spoken: WordedSpeech, read: EventReader) -> SpokenUtterance:
    pcm, sample_rate, events = spoken.raw
    audio, spans = speech_result(text, pcm, sample_rate, events, read)
    tokens = _tokens(text)
    marks = sorted(
        [(ms, 0, first - 1) for first, _, ms in spoken.words]
        + [(ms, 1, index) for index, (_, ms) in enumerate(events)],
        key=lambda mark: (mark[0], mark[1]),
    )
    owner: dict[int, int] = {}
    current: int | None = None
    for _, kind, value in marks:
        if kind == 0:
            current = next(
                (i for i, (start, end) in enumerate(tokens) if start <= value < end), None
            )
        elif current is not None and not events[value][0].startswith("_"):
            owner[value] = current
    starts = [ms / 1000.0 for _, ms in events]
    ends = starts[1:] + [audio.duration]
    by_token: dict[int, list[PhonemeSpan]] = {}
    for index, token in owner.items():
        start, end = starts[index], min(ends[index], audio.duration)
        labels = read(events[index][0], f"speak({text!r})") if end > start else ()
        step = (end - start) / max(len(labels), 1)
        for k, label in enumerate(labels):  # an event of several phonemes shares its time
            span = PhonemeSpan(
                label, start + k * step, end if k == len(labels) - 1 else start + (k + 1) * step
            )
            by_token.setdefault(token, []).append(span)
    words = [
        SpokenWord(text[tokens[token][0] : tokens[token][1]], tuple(by_token[token]))
        for token in sorted(by_token)
    ]
    return SpokenUtterance(text, audio, spans, words)


def _tokens(text: str) -> list[tuple[int, int]]:
    tokens, start = [], None
    for index, char in enumerate(text + " "):
        if char.isspace():
            if start is not None:
                tokens.append((start, index))
            start = None
        elif start is None:
            start = index
    return tokens
