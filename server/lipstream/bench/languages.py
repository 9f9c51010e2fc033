"""Which of espeak-ng's languages map fully to the phoneme set: the languages table's survey.

Method: for every language ``espeak-ng --voices`` lists, espeak-ng speaks a
sample through the text front end's own worker, reading the phoneme names
the way a request in that language is read (IPA, or English mnemonics for
English): the numbers in ``NUMBERS`` (espeak-ng reads digits in each
language's own words, so every language has a sample without a hand-made
text), and, for the languages ``SENTENCES`` holds, a sentence too. Each
phoneme espeak-ng spoke is mapped as a request's would be; a language maps
fully when every one of them does. The result, with machine, date, command
and espeak-ng's version, goes to ``bench/languages.json``, and
``python -m lipstream.bench.report`` renders it into
docs/reference/languages.md.

    python -m lipstream.bench.languages [--json bench/languages.json]
"""

from __future__ import annotations

import argparse
import subprocess
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..errors import LipstreamError
from ..frontends.espeak_ipa import as_ipa, ipa_event_phonemes, is_language_switch
from ..frontends.espeak_languages import EspeakLanguage, espeak_languages
from ..results_file import recorded, write_results
from ..speech.espeak import read_mnemonic
from ..speech.worker import SpeechRequest, speak_in_worker

COMMAND = "python -m lipstream.bench.languages"
NUMBERS = "0 1 2 3 4 5 6 7 8 9 10 11 12 13 17 20 30 40 50 60 70 80 90 100 1000"
SENTENCES: dict[str, str] = {
    "de": "Über die Brücke fahren schöne Züge, und ich höre Vögel.",
    "fr-fr": "Un bon vin blanc, s'il vous plaît, et une brioche au beurre.",
    "es": "El perro de Rosa corre rápido por la calle mojada.",
    "it": "Gli gnocchi della nonna sono buonissimi con il burro.",
    "pt": "O pão de queijo é muito bom e a vida não é fácil.",
    "pt-br": "O pão de queijo é muito bom e a vida não é fácil.",
    "nl": "De gezellige kat slaapt in de zon op het dak.",
    "pl": "Cześć, szczęście i źdźbło trawy w Łodzi.",
    "ru": "Привет, мир! Щука живёт в широкой реке.",
    "ja": "わたしはにほんごをはなします。",
    "cmn": "我是十月生，爱吃，少说。",
    "cmn-latn-pinyin": "wo3 shi4 zhong1 guo2 ren2, ni3 hao3",
    "hi": "मैं हिंदी बोलता हूँ और चाय पीता हूँ।",
    "ar": "أنا أتكلم العربية قليلا.",
}
SERVED = ("de", "fr-fr", "es", "it", "pt", "nl", "pl", "ru", "ja", "cmn", "hi", "ar")
"""The languages issue 25 names; each is tested end to end (tests/lipstream/frontends)."""


def _read(name: str, language: EspeakLanguage) -> tuple[str, ...] | str:
    """The phonemes of one event name, or the error message if it does not map."""
    try:
        if language.english:
            return read_mnemonic(name, "survey")
        return ipa_event_phonemes(name, language.code, "survey")
    except LipstreamError as exc:
        return exc.message


def survey_language(language: EspeakLanguage, events: Sequence[tuple[str, int]]) -> dict[str, Any]:
    """One language's row: its distinct phoneme names, how each maps (``phonemes``: name ->
    its IPA and phonemes), and those that do not (``unmapped``: name -> why)."""
    names = [name for name, _ in events if name and not name.startswith("_")]
    names = [name for name in dict.fromkeys(names) if not is_language_switch(name)]
    mapping: dict[str, list[str]] = {}
    unmapped: dict[str, str] = {}
    for name in names:
        read = _read(name, language)
        if isinstance(read, str):
            unmapped[name] = read
        else:
            mapping[name] = list(read)
    return {
        "code": language.code,
        "title": language.title,
        "file": language.file,
        "names": "mnemonic" if language.english else "ipa",
        "sample": SENTENCES.get(language.code, ""),
        "phonemes": {
            name: {"ipa": name if language.english else as_ipa(name), "maps_to": phonemes}
            for name, phonemes in mapping.items()
        },
        "unmapped": unmapped,
        "maps_fully": not unmapped,
    }


def _speak_all(languages: Sequence[EspeakLanguage], ipa_names: bool) -> list[dict[str, Any]]:
    requests = [
        SpeechRequest(
            f"{SENTENCES[language.code]} {NUMBERS}" if language.code in SENTENCES else NUMBERS,
            language.voice(),
            ipa_names=ipa_names,
        )
        for language in languages
    ]
    rows = []
    for language, request in zip(languages, requests):
        try:
            (spoken,) = speak_in_worker([request])
        except LipstreamError as exc:
            rows.append({"code": language.code, "title": language.title, "error": exc.message})
            continue
        rows.append(survey_language(language, spoken[2]))
    return rows


def espeak_version() -> str:
    """espeak-ng's version line (``eSpeak NG text-to-speech: 1.51 ...``), first words."""
    finished = subprocess.run(["espeak-ng", "--version"], capture_output=True, check=False)
    return finished.stdout.decode("utf-8", "replace").split("Data at")[0].strip()


def survey() -> dict[str, Any]:
    """Every language's row, in espeak-ng's order, with where the figures come from."""
    languages = espeak_languages()
    english = [language for language in languages if language.english]
    others = [language for language in languages if not language.english]
    rows = {row["code"]: row for row in _speak_all(english, False) + _speak_all(others, True)}
    return _factored(
        {
            **recorded(COMMAND),
            "espeak_ng": espeak_version(),
            "numbers": NUMBERS,
            "served": list(SERVED),
            "languages": [rows[language.code] for language in languages],
        }
    )


def _factored(results: dict[str, Any]) -> dict[str, Any]:
    """The survey with each phoneme name's mapping listed once (``phonemes``: kind of name ->
    name -> its IPA and phonemes), each language keeping the list of its names."""
    mappings: dict[str, dict[str, Any]] = {"ipa": {}, "mnemonic": {}}
    for row in results["languages"]:
        if "phonemes" in row:
            mappings[row["names"]].update(row["phonemes"])
            row["phonemes"] = list(row["phonemes"])
    results["phonemes"] = {kind: dict(sorted(names.items())) for kind, names in mappings.items()}
    return results


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--json", type=Path, default=Path("bench/languages.json"), help="where to write"
    )
    args = parser.parse_args(argv)
    results = survey()
    write_results(results, args.json)
    fully = sum(1 for row in results["languages"] if row.get("maps_fully"))
    print(f"{fully} of {len(results['languages'])} languages map fully; wrote {args.json}")


if __name__ == "__main__":
    main()
