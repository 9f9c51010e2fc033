"""Letters aligned to phonemes, and the onsets character times give: hand-checked
alignments of English spellings, anchors only where the alignment is confident, and the
duration model filling the time between anchors."""

from __future__ import annotations

import pytest

from lipstream.frontends.letter_alignment import align_letters, letter_onsets
from lipstream.frontends.spreading import PronouncedWord, spread_words
from lipstream.frontends.timings import TimedCharacter
from lipstream.frontends.word_durations import WordDurationModel


@pytest.mark.parametrize(
    ("word", "phonemes", "groups"),
    [
        # (first letter, first phoneme) of each group, worked out by hand
        ("knights", "N AY T S", [(0, 0), (2, 1), (5, 2), (6, 3)]),
        ("photo", "F OW T OW", [(0, 0), (2, 1), (3, 2), (4, 3)]),
        ("box", "B AA K S", [(0, 0), (1, 1), (2, 2)]),
        ("shell", "SH EH L", [(0, 0), (2, 1), (3, 2)]),
        ("Queen's", "K W IY N Z", [(0, 0), (1, 1), (2, 2), (4, 3), (6, 4)]),
        ("make", "M EY K", [(0, 0), (1, 1), (2, 2)]),
    ],
)
def test_letters_align_with_the_phonemes_they_spell(
    word: str, phonemes: str, groups: list[tuple[int, int]]
) -> None:
    aligned = align_letters(word, phonemes.split())
    assert [(letter, phoneme) for letter, phoneme, _ in aligned] == groups
    assert all(confident for _, _, confident in aligned)


def test_a_letter_that_spells_no_phoneme_of_its_class_is_not_confident() -> None:
    # "zx" → AA T: z is a consonant with a vowel, no spelling the table knows.
    aligned = align_letters("zx", ["AA", "T"])
    assert not any(confident for _, _, confident in aligned)


def timed(word: str, starts: list[float], end: float) -> tuple[TimedCharacter, ...]:
    ends = starts[1:] + [end]
    return tuple(TimedCharacter(c, s, e) for c, s, e in zip(word, starts, ends))


def test_each_confident_phoneme_starts_with_its_first_letter() -> None:
    characters = timed("shop", [1.0, 1.03, 1.08, 1.2], 1.3)
    assert letter_onsets(characters, ["SH", "AA", "P"]) == (1.0, 1.08, 1.2)


def test_an_anchor_that_leaves_no_time_for_the_phonemes_before_it_is_dropped() -> None:
    # "box": x spells K S; o is timed 1 ms after b, too close to give B its time.
    characters = timed("box", [0.5, 0.501, 0.6], 0.8)
    assert letter_onsets(characters, ["B", "AA", "K", "S"]) == (0.5, None, 0.6, None)


def test_without_a_confident_anchor_there_is_nothing_to_anchor() -> None:
    assert letter_onsets(timed("zx", [0.0, 0.1], 0.2), ["AA", "T"]) == ()
    assert letter_onsets(timed("a", [0.0], 0.2), ["AH"]) == ()


def test_spans_start_at_the_anchors_and_fill_the_time_between_them(
    espeak_durations: WordDurationModel,
) -> None:
    phonemes = ("B", "AA", "K", "S")
    free = spread_words(espeak_durations, [PronouncedWord(phonemes, 0.5, 0.8)])
    assert {s.phoneme: s.start for s in free}["K"] != pytest.approx(0.62, abs=0.005)
    anchored = PronouncedWord(phonemes, 0.5, 0.8, (0.5, None, 0.62, None))
    spans = spread_words(espeak_durations, [anchored])
    assert [s.phoneme for s in spans] == ["sil", *phonemes]
    assert all(a.end == b.start for a, b in zip(spans, spans[1:]))
    b, aa, k, s = spans[1:]
    assert (b.start, k.start, s.end) == (0.5, 0.62, 0.8)
    assert b.end > b.start and aa.end > aa.start and s.start > k.start
