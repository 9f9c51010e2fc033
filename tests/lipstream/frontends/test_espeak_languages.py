"""A request's ``lang`` against espeak-ng's own voice list."""

from __future__ import annotations

import shutil

import pytest

from lipstream.errors import LipstreamError
from lipstream.frontends.espeak_languages import (
    EspeakLanguage,
    espeak_languages,
    espeak_variants,
    parse_voices,
    resolve_language,
    resolve_variant,
)
from lipstream.speech.text_frontend import choose_voice

pytestmark = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing")

# Three lines as espeak-ng 1.51 prints them (`espeak-ng --voices`, header removed).
LISTING = [
    " 5  cmn             --/M      Chinese_(Mandarin,_latin_as_English) sit/cmn              (zh-cmn 5)(zh 5)",
    " 5  de              --/M      German             gmw/de               ",
    " 2  en-gb           --/M      English_(Great_Britain) gmw/en               (en 2)",
]


def test_the_listing_is_read_field_by_field() -> None:
    voices = parse_voices(LISTING)
    assert voices[0] == (
        EspeakLanguage("cmn", "Chinese (Mandarin, latin as English)", "sit/cmn", 5),
        [("zh-cmn", 5), ("zh", 5)],
    )
    assert voices[1] == (EspeakLanguage("de", "German", "gmw/de", 5), [])
    assert voices[2][0].english and not voices[1][0].english
    assert voices[1][0].voice("f3") == "gmw/de+f3"


@pytest.mark.parametrize(
    ("lang", "code", "file"),
    [
        ("de", "de", "gmw/de"),
        ("FR", "fr-fr", "roa/fr"),
        ("fr-fr", "fr-fr", "roa/fr"),
        ("zh", "cmn", "sit/cmn"),
        ("en", "en-gb", "gmw/en"),
        ("pt-BR", "pt-br", "roa/pt-BR"),
    ],
)
def test_a_language_or_one_a_voice_serves_resolves_to_its_voice(
    lang: str, code: str, file: str
) -> None:
    language = resolve_language(lang)
    assert (language.code, language.file) == (code, file)


def test_unknown_languages_and_variants_are_coded_errors_naming_them() -> None:
    with pytest.raises(LipstreamError) as raised:
        resolve_language("xx-nowhere")
    assert raised.value.code == "unknown_language" and raised.value.where == "lang"
    assert "'xx-nowhere'" in raised.value.message
    with pytest.raises(LipstreamError) as variant:
        resolve_variant("nobody")
    assert variant.value.code == "invalid_request" and variant.value.where == "voice"
    assert resolve_variant("F3") == "f3" and "klatt" in espeak_variants()
    assert len(espeak_languages()) > 100


def test_how_a_voice_is_chosen_and_read() -> None:
    assert choose_voice(None, None).voice == "en-us" and not choose_voice(None, None).ipa_names
    assert choose_voice("en-us+f3", None).ipa_names is False
    german = choose_voice("m1", "de")
    assert (german.voice, german.lang, german.ipa_names) == ("gmw/de+m1", "de", True)
    assert choose_voice("de+f3", None).ipa_names  # a whole voice name of another language
    english = choose_voice(None, "en-us")
    assert (english.voice, english.ipa_names) == ("gmw/en-US", False)
