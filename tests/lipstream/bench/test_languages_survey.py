"""The languages survey's row for one language, from events written here."""

from __future__ import annotations

from lipstream.bench.languages import survey_language
from lipstream.frontends.espeak_languages import EspeakLanguage


def test_a_row_maps_every_name_once_and_lists_those_that_do_not_map() -> None:
    language = EspeakLanguage("xx", "Test", "art/xx", 5)
    events = [("", 0), ("a", 10), ("ʬ", 20), ("(en)", 30), ("a", 40), ("s.", 50), ("_:", 60)]
    row = survey_language(language, events)
    assert row["names"] == "ipa" and row["maps_fully"] is False
    assert row["phonemes"] == {
        "a": {"ipa": "a", "maps_to": ["AE"]},
        "s.": {"ipa": "ʂ", "maps_to": ["SH"]},
    }
    assert list(row["unmapped"]) == ["ʬ"] and "U+02AC" in row["unmapped"]["ʬ"]
    english = survey_language(EspeakLanguage("en-us", "English", "gmw/en-US", 5), [("h", 0)])
    assert english["names"] == "mnemonic" and english["phonemes"]["h"]["maps_to"] == ["HH"]
    assert english["maps_fully"] is True
