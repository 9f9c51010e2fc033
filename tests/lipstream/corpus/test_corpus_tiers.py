"""TextGrids from several aligners: MFA's ``phones``, WebMAUS's ``MAU`` (SAMPA, ``<p:>``),
``phone`` and ``segments`` tiers, and a tier named by ``--tier`` or ``corpus.json``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from lipstream.corpus import load_corpus, read_textgrid_phones
from lipstream.corpus.textgrid import read_textgrid_tier
from lipstream.errors import CorpusError
from lipstream.timeline import PhonemeSpan

WORDS = [(0.0, 0.2, ""), (0.2, 0.9, "hello"), (0.9, 1.0, "")]
# "hello" as WebMAUS writes it in SAMPA, with its pause marker.
MAU = [
    (0.0, 0.2, "<p:>"),
    (0.2, 0.3, "h"),
    (0.3, 0.5, "@"),
    (0.5, 0.6, "l"),
    (0.6, 0.9, "@U"),
    (0.9, 1.0, "<p:>"),
]
HELLO = [
    PhonemeSpan("sil", 0.0, 0.2),
    PhonemeSpan("HH", 0.2, 0.3),
    PhonemeSpan("AH", 0.3, 0.5),
    PhonemeSpan("L", 0.5, 0.6),
    PhonemeSpan("OW", 0.6, 0.9),
    PhonemeSpan("sil", 0.9, 1.0),
]
ARPABET = [
    (0.0, 0.2, ""),
    (0.2, 0.3, "HH"),
    (0.3, 0.5, "AH0"),
    (0.5, 0.6, "L"),
    (0.6, 0.9, "OW1"),
    (0.9, 1.0, "sil"),
]
IPA = [
    (0.0, 0.2, ""),
    (0.2, 0.3, "h"),
    (0.3, 0.5, "ə"),
    (0.5, 0.6, "l"),
    (0.6, 0.9, "oʊ"),
    (0.9, 1.0, ""),
]


def write_grid(build: Any, path: Path, tiers: dict[str, Any], short: bool = False) -> Path:
    path.write_text(
        build.textgrid_short(tiers) if short else build.textgrid_long(tiers), encoding="utf-8"
    )
    return path


@pytest.mark.parametrize("short", [False, True])
def test_webmaus_mau_tier_reads_sampa_and_pauses(build: Any, tmp_path: Path, short: bool) -> None:
    path = write_grid(build, tmp_path / "a.TextGrid", {"ORT-MAU": WORDS, "MAU": MAU}, short)
    assert read_textgrid_phones(path) == HELLO
    tier = read_textgrid_tier(path)
    assert (tier.name, tier.source) == ("MAU", "sampa")


@pytest.mark.parametrize(
    ("name", "intervals", "source"),
    [("phone", ARPABET, "arpabet"), ("segments", IPA, "ipa"), ("mau", MAU, "sampa")],
)
def test_other_aligners_tiers_are_found_and_their_notation_detected(
    build: Any, tmp_path: Path, name: str, intervals: Any, source: str
) -> None:
    path = write_grid(build, tmp_path / "a.TextGrid", {"words": WORDS, name: intervals})
    assert read_textgrid_phones(path) == HELLO
    assert read_textgrid_tier(path).source == source


def test_phones_is_preferred_over_mau(build: Any, tmp_path: Path) -> None:
    mfa = [(0.0, 0.5, "AA1"), (0.5, 1.0, "")]
    path = write_grid(build, tmp_path / "a.TextGrid", {"MAU": MAU, "phones": mfa})
    assert read_textgrid_phones(path) == [PhonemeSpan("AA", 0.0, 0.5), PhonemeSpan("sil", 0.5, 1.0)]
    assert read_textgrid_phones(path, tier="MAU") == HELLO


def test_a_named_tier_of_any_name_has_its_notation_detected(build: Any, tmp_path: Path) -> None:
    sampa = [(start, end, label) for start, end, label in MAU if label != "<p:>"]
    path = write_grid(build, tmp_path / "a.TextGrid", {"PhonAlign": sampa, "words": WORDS})
    assert read_textgrid_phones(path, tier="PhonAlign") == [
        PhonemeSpan("HH", 0.2, 0.3),
        PhonemeSpan("AH", 0.3, 0.5),
        PhonemeSpan("L", 0.5, 0.6),
        PhonemeSpan("OW", 0.6, 0.9),
    ]
    with pytest.raises(CorpusError) as error:
        read_textgrid_phones(path)
    assert "no phone tier" in error.value.message and "'PhonAlign', 'words'" in error.value.message
    with pytest.raises(CorpusError) as error:
        read_textgrid_phones(path, tier="phones")
    assert error.value.message == "no tier named 'phones'; tiers found: 'PhonAlign', 'words'"
    assert error.value.where == "a.TextGrid"


def test_unknown_sampa_label_names_its_line(build: Any, tmp_path: Path) -> None:
    bad = [*MAU[:2], (0.3, 0.5, "@@@"), *MAU[3:]]
    path = write_grid(build, tmp_path / "a.TextGrid", {"MAU": bad})
    line = build.line_of(path, 'text = "@@@"')
    with pytest.raises(Exception, match="unknown phoneme '@@@' for source 'sampa'") as error:
        read_textgrid_phones(path)
    assert getattr(error.value, "where", None) == f"a.TextGrid:line {line - 2}"


def test_corpus_json_tier_and_the_load_override(build: Any, tmp_path: Path) -> None:
    mfa = [(0.0, 0.5, "AA1"), (0.5, 1.0, "")]
    for stem in ("a", "b"):
        build.write_utterance(tmp_path, stem)
        write_grid(build, tmp_path / f"{stem}.TextGrid", {"phones": mfa, "KAN": MAU})
    assert load_corpus(tmp_path).utterances[0].phones[0].phoneme == "AA"
    (tmp_path / "corpus.json").write_text(json.dumps({"tier": "KAN"}))
    assert load_corpus(tmp_path).utterances[1].phones == HELLO
    assert load_corpus(tmp_path, tier="phones").utterances[1].phones[0].phoneme == "AA"
    (tmp_path / "corpus.json").write_text(json.dumps({"tier": ""}))
    with pytest.raises(CorpusError, match="key 'tier' must be a non-empty string"):
        load_corpus(tmp_path)
