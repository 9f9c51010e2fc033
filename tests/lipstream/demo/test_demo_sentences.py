"""The shipped sentence list: size, shape, and phoneme coverage through espeak-ng."""

from __future__ import annotations

from collections import Counter

import pytest

from lipstream.demo.sentences import load_sentences, parse_sentences
from lipstream.demo.speech_batch import speak_batch
from lipstream.errors import CorpusError
from lipstream.phonemes import ARPABET
from lipstream.speech.espeak import EspeakSynthesizer


def test_at_least_300_distinct_sentences_of_6_to_20_words() -> None:
    sentences = load_sentences()
    assert len(sentences) >= 300
    assert len(set(sentences)) == len(sentences)
    for sentence in sentences:
        assert 6 <= len(sentence.split()) <= 20, sentence
        assert sentence[0].isupper() and sentence[-1] in ".?!", sentence


def test_every_arpabet_phoneme_is_spoken_many_times() -> None:
    synthesizer = EspeakSynthesizer()
    spoken = speak_batch([(synthesizer, sentence) for sentence in load_sentences()])
    counts = Counter(span.phoneme for _, spans in spoken for span in spans)
    assert len(ARPABET) == 39
    rare = {phoneme: counts[phoneme] for phoneme in ARPABET if counts[phoneme] < 20}
    assert not rare, f"phonemes spoken fewer than 20 times: {rare}"
    assert set(counts) <= set(ARPABET) | {"sil"}


def test_parse_skips_blank_and_comment_lines() -> None:
    assert parse_sentences("# header\n\nOne two three four five six.\n  Seven eight.  \n") == [
        "One two three four five six.",
        "Seven eight.",
    ]


def test_parse_rejects_control_characters_and_empty_lists() -> None:
    with pytest.raises(CorpusError, match="line 2"):
        parse_sentences("Fine line here.\nBad\x07line.\n", where="x.txt")
    with pytest.raises(CorpusError, match="no sentences"):
        parse_sentences("# only a comment\n")
