"""Prompt sentences: greedy set cover in rounds, against hand-worked tables, and the shipped
script's choice covering every phoneme it holds."""

from __future__ import annotations

import pytest

from lipstream.errors import LipstreamError
from lipstream.recording.prompts import checked_sentences, choose_prompts, cover, script_phonemes


def table(*rows: tuple[str, str]) -> list[tuple[str, frozenset[str]]]:
    return [(text, frozenset(phonemes.split())) for text, phonemes in rows]


def test_each_round_covers_every_phoneme_before_the_next_begins() -> None:
    rows = table(("a", "A B"), ("b", "C"), ("c", "A B C"), ("d", "D"))
    # Round 1: c gives three new phonemes, then d the last one. Round 2: a gives A and B a
    # second time, then b gives C.
    assert cover(rows, 2) == ["c", "d"]
    assert cover(rows, 4) == ["c", "d", "a", "b"]
    assert cover(rows, 10) == ["c", "d", "a", "b"]


def test_ties_go_to_the_shorter_sentence_then_the_first() -> None:
    rows = table(("c-long", "A B C"), ("base", "A B D E"), ("c-short", "C"), ("c-also", "C"))
    # base gives four; then c-long, c-short and c-also each give C: c-short has fewest
    # phonemes and comes before c-also.
    assert cover(rows, 2) == ["base", "c-short"]
    assert cover(table(("first", "A B"), ("second", "B A")), 1) == ["first"]


def test_the_script_prompts_cover_every_phoneme_it_holds_deterministically() -> None:
    script = script_phonemes()
    held = frozenset().union(*(phonemes for _, phonemes in script))
    chosen = choose_prompts(20)
    assert chosen == choose_prompts(20) and len(set(chosen)) == 20
    phonemes = dict(script)
    assert frozenset().union(*(phonemes[text] for text in chosen)) == held
    assert {"P", "B", "M", "F", "V", "UW", "IY", "AA"} <= held


def test_a_clients_sentences_are_checked() -> None:
    assert checked_sentences(["  Hello   there ", "Two"], 3) == ["Hello there", "Two"]
    for value, code, where in (
        ([], "invalid_request", "sentences"),
        ("text", "invalid_request", "sentences"),
        (["a", "b", "c", "d"], "too_many_takes", "sentences"),
        (["ok", " "], "invalid_request", "sentences[1]"),
        (["ok", 3], "invalid_request", "sentences[1]"),
        (["x" * 301], "invalid_request", "sentences[0]"),
    ):
        with pytest.raises(LipstreamError) as error:
            checked_sentences(value, 3)
        assert (error.value.code, error.value.where) == (code, where)
