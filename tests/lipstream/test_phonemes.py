"""Phoneme normalization, checked against hand-written and espeak-ng-produced labels."""

from __future__ import annotations

import ctypes
import ctypes.util
import shutil
import struct
import subprocess
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from lipstream.errors import LipstreamError, UnknownPhonemeError
from lipstream.phonemes import (
    ARPABET,
    PHONEME_INDEX,
    PHONEMES,
    SILENCE,
    SOURCE_ALIASES,
    SOURCES,
    detect_source,
    is_silence,
    kept_labels,
    normalize_phoneme,
    normalize_phonemes,
)


def labels(text: str) -> list[str]:
    """Space-separated labels, as they appear in transcription files."""
    return text.split()


CMUDICT_PHONEMES = labels(
    "AA AE AH AO AW AY B CH D DH EH ER EY F G HH IH IY JH K L M N NG "
    "OW OY P R S SH T TH UH UW V W Y Z ZH"
)

# Harvard sentences lists 1-3 plus words that exercise rarer phonemes.
TEXT = """The birch canoe slid on the smooth planks. Glue the sheet to the dark blue
background. It's easy to tell the depth of a well. These days a chicken leg is a rare dish.
Rice is often served in round bowls. The juice of lemons makes fine punch. The box was
thrown beside the parked truck. The hogs were fed chopped corn and garbage. Four hours of
steady work faced us. A large size in stockings is hard to sell. The boy was there when the
sun rose. A rod is used to catch pink salmon. The source of the huge river is the clear
spring. Kick the ball straight and follow through. Help the woman get back to her feet. A pot
of tea helps to pass the evening. Smoky fires lack flame and heat. The soft cushion broke the
man's fall. The salt breeze came across from the sea. The girl at the booth sold fifty bonds.
The small pup gnawed a hole in the sock. The fish twisted and turned on the bent hook. Press
the pants and sew a button on the vest. The swan dive was far short of perfect. The beauty of
the view stunned the young boy. Two blue fish swam in the tank. Her purse was full of useless
trash. The colt reared and threw the tall rider. It snowed, rained, and hailed the same
morning. Read verse out loud for pleasure. Vision, measure, thought, judge, church, loch,
garage, rhythm, little bottle, hour, fire, tour, poor, here, where, cure, oil, choir, idea,
usual, genre, why, what, whether, anything, accompanying, certainly, written, into, along,
after, asked, car, more, near, hurry, Utah, restaurant!"""

ESPEAK_DATA = Path("/usr/lib/x86_64-linux-gnu/espeak-ng-data")
needs_espeak = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng missing")


def espeak_tokens(text: str, voice: str, mode: str = "-x") -> list[str]:
    """Phoneme names espeak-ng prints for ``text`` (``-x`` mnemonics or ``--ipa``)."""
    result = subprocess.run(
        ["espeak-ng", "-q", "-v", voice, mode, "--sep= ", text],
        capture_output=True,
        text=True,
        check=True,
    )
    return result.stdout.split()


def test_canonical_inventory() -> None:
    assert ARPABET == tuple(CMUDICT_PHONEMES)
    assert len(set(ARPABET)) == 39
    assert PHONEMES == ARPABET + ("sil",) and SILENCE == "sil"
    assert [PHONEME_INDEX[p] for p in PHONEMES] == list(range(40))


@pytest.mark.parametrize(
    "source", ["auto", "arpabet", "mfa", "timit", "mocha", "espeak", "ipa", "sampa"]
)
def test_silence_label_is_accepted_by_every_source(source: str) -> None:
    assert normalize_phoneme("sil", source) == "sil"


@pytest.mark.parametrize(
    ("label", "expected"),
    [
        ("AA1", "AA"),
        ("aa1", "AA"),
        ("Er0", "ER"),
        ("IY2", "IY"),
        ("ah", "AH"),
        ("ZH", "ZH"),
        (" OW1 ", "OW"),
        ("AX0", "AH"),
        ("AXR", "ER"),
        ("IX", "IH"),
        ("DX", "D"),
        ("EN", "N"),
        ("WH", "W"),
        ("Q", "sil"),
    ],
)
def test_arpabet_strips_stress_and_folds_extended_symbols(label: str, expected: str) -> None:
    assert normalize_phoneme(label, "arpabet") == expected


@pytest.mark.parametrize("label", ["AA3", "AA12", "K1", "1", "", "A A", "AAX"])
def test_arpabet_rejects_malformed_labels(label: str) -> None:
    with pytest.raises(UnknownPhonemeError):
        normalize_phoneme(label, "arpabet")


@pytest.mark.parametrize("token", ["", "sil", "sp", "spn", "SIL", "  "])
def test_mfa_silence_tokens(token: str) -> None:
    assert normalize_phoneme(token, "mfa") == "sil"


def test_mfa_reads_arpabet_and_english_mfa_ipa_phones() -> None:
    arpa = ["", "DH", "AH0", "K", "AE1", "T", "sp", "S", "AE1", "T", "spn"]
    assert normalize_phonemes(arpa, "mfa") == labels("sil DH AH K AE T sil S AE T sil")
    # english_mfa pronunciations: "little" [l ɪ ɾ ɫ̩], "key" [cʰ i], "chair" [tʃ ɛː ɹ]
    ipa = ["l", "ɪ", "ɾ", "ɫ̩", "cʰ", "i", "tʃ", "ɛː", "ɹ", "aj", "ow", "ɔj", "ɚ", "ʔ", "n̩"]
    assert normalize_phonemes(ipa, "mfa") == labels("L IH D L K IY CH EH R AY OW OY ER T N")


@pytest.mark.parametrize(
    ("label", "expected"),
    [
        ("h#", "sil"),
        ("pau", "sil"),
        ("epi", "sil"),
        ("q", "sil"),
        ("bcl", "B"),
        ("pcl", "P"),
        ("dcl", "D"),
        ("tcl", "T"),
        ("gcl", "G"),
        ("kcl", "K"),
        ("ax", "AH"),
        ("axr", "ER"),
        ("ix", "IH"),
        ("ux", "UW"),
        ("ax-h", "AH"),
        ("dx", "D"),
        ("nx", "N"),
        ("en", "N"),
        ("em", "M"),
        ("el", "L"),
        ("eng", "NG"),
        ("hv", "HH"),
        ("hh", "HH"),
        ("jh", "JH"),
    ],
)
def test_timit_labels(label: str, expected: str) -> None:
    assert normalize_phoneme(label, "timit") == expected


def test_timit_transcription_of_sa2() -> None:
    # "Don't ask me to carry an oily rag like that." as TIMIT transcribes it.
    phn = labels(
        "h# d ow n ae s kcl k m iy dx ix kcl k ae r iy ix n oy l iy r ae gcl g "
        "l ay kcl k dh ae tcl t h#"
    )
    expected = labels(
        "sil D OW N AE S K K M IY D IH K K AE R IY IH N OY L IY R AE G G L AY K K DH AE T T sil"
    )
    assert normalize_phonemes(phn, "timit", "sa2.phn") == expected


def test_mocha_uses_the_mrpa_set() -> None:
    # Opening of MOCHA-TIMIT fsew0_001.lab: "This was easy ..."
    lab = labels("sil breath sil dh i s w @ z ii")
    assert normalize_phonemes(lab, "mocha") == labels("sil sil sil DH IH S W AH Z IY")
    assert normalize_phonemes(labels("@@ uh oo o ou ei ai oi au e@ i@ u@ #"), "mocha") == (
        labels("ER AH AO AA OW EY AY OY AW EH IY UH sil")
    )


def test_auto_order_resolves_collisions_as_documented() -> None:
    assert normalize_phoneme("D") == "D"  # ARPAbet first ...
    assert normalize_phoneme("D", "espeak") == "DH"  # ... espeak's D is /ð/
    assert normalize_phoneme("aa") == "AA"
    assert normalize_phoneme("aa", "espeak") == "AE"
    assert normalize_phoneme("q") == "sil"  # TIMIT before espeak
    assert normalize_phoneme("q", "espeak") == "K"
    assert normalize_phoneme("uh") == "UH"
    assert normalize_phoneme("uh", "mocha") == "AH"
    assert normalize_phoneme("") == "sil"
    assert normalize_phoneme("ax-h") == "AH"
    assert normalize_phoneme("'aI@") == "AY"
    assert normalize_phoneme("ˈɔɪ") == "OY"
    assert normalize_phoneme("AY", "request") == "AY"


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("'a", "AE"),
        (",aU", "AW"),
        ("%oU", "OW"),
        ("=n", "N"),
        ("aI@", "AY"),
        ("e@", "EH"),
        ("i@", "IY"),
        ("A@", "AA"),
        ("O@", "AO"),
        ("U@", "UH"),
        ("@L", "L"),
        ("n-", "N"),
        ("r-", "R"),
        ("t#", "T"),
        ("?", "T"),
        ("3:", "ER"),
        ("V", "AH"),
        ("N", "NG"),
        ("T", "TH"),
        ("S", "SH"),
        ("Z", "ZH"),
        ("tS", "CH"),
        ("dZ", "JH"),
        ("j", "Y"),
        ("_:", "sil"),
        ("_", "sil"),
        ("_!", "sil"),
        ("||", "sil"),
        ("_|", "sil"),
    ],
)
def test_espeak_names(name: str, expected: str) -> None:
    assert normalize_phoneme(name, "espeak") == expected


@needs_espeak
@pytest.mark.parametrize(
    ("word", "expected"),
    [
        ("cat", "K AE T"),
        ("thought", "TH AO T"),
        ("judge", "JH AH JH"),
        ("measure", "M EH ZH ER"),
        ("sing", "S IH NG"),
        ("yes", "Y EH S"),
        ("boy", "B OY"),
        ("go", "G OW"),
        ("book", "B UH K"),
        ("food", "F UW D"),
        ("bird", "B ER D"),
        ("father", "F AA DH ER"),
        ("see", "S IY"),
        ("say", "S EY"),
        ("hat", "HH AE T"),
        ("about", "AH B AW T"),
        ("church", "CH ER CH"),
        ("this", "DH IH S"),
        ("vision", "V IH ZH AH N"),
        ("button", "B AH T N"),
        ("where", "W EH"),
    ],
)
def test_espeak_words_give_cmudict_sequences(word: str, expected: str) -> None:
    names = espeak_tokens(word, "en-us")
    assert normalize_phonemes(names, "espeak") == labels(expected)


@needs_espeak
@pytest.mark.parametrize("voice", ["en-us", "en", "en-gb-scotland", "en-029"])
def test_every_espeak_mnemonic_and_ipa_symbol_from_real_text_normalizes(voice: str) -> None:
    for mode, source in (("-x", "espeak"), ("--ipa", "ipa")):
        tokens = espeak_tokens(TEXT, voice, mode)
        assert len(tokens) > 700
        canonical = normalize_phonemes(tokens, source, f"{voice} {mode}")
        assert set(canonical) <= set(PHONEMES)


@needs_espeak
def test_espeak_mnemonics_and_ipa_agree_word_by_word() -> None:
    """Two independent tables must give the same phonemes for the same speech.

    espeak's IPA writes the American flap as [ɾ] (read as D) where the mnemonic
    is t# (read as T), and prints nothing for the ";" glide (read as Y).
    """
    words = {w.strip(".,!").lower() for w in TEXT.split()}
    for word in sorted(words):
        names = [n for n in espeak_tokens(word, "en-us") if n != ";"]
        ipa = espeak_tokens(word, "en-us", "--ipa")
        from_names = normalize_phonemes(names, "espeak", word)
        from_ipa = normalize_phonemes(ipa, "ipa", word)
        flap = [i for i, (a, b) in enumerate(zip(from_names, from_ipa)) if (a, b) == ("T", "D")]
        assert [p for i, p in enumerate(from_ipa) if i not in flap] == [
            p for i, p in enumerate(from_names) if i not in flap
        ], word


def _english_phoneme_table_names() -> set[str]:
    """Vowel and consonant mnemonics of espeak-ng's en* tables, read from ``phontab``."""
    data = (ESPEAK_DATA / "phontab").read_bytes()
    tables: list[tuple[str, int, list[tuple[int, str, int]]]] = []
    offset = 4
    for _ in range(data[0]):
        count, include = data[offset], data[offset + 1]
        name = data[offset + 4 : offset + 36].split(b"\0")[0].decode()
        offset += 36
        entries = []
        for _ in range(count):
            mnemonic, _flags, _program, code, kind = struct.unpack_from("<IIHBB", data, offset)
            text = struct.pack("<I", mnemonic).split(b"\0")[0].decode("latin-1")
            entries.append((code, text, kind))
            offset += 16
        tables.append((name, include, entries))
    by_name = {name: (include, entries) for name, include, entries in tables}
    names: set[str] = set()
    for table in (name for name, _, _ in tables if name.startswith("en")):
        effective: dict[int, tuple[str, int]] = {}
        chain = [table]
        while by_name[chain[-1]][0] and tables[by_name[chain[-1]][0] - 1][0] != chain[-1]:
            chain.append(tables[by_name[chain[-1]][0] - 1][0])
        for link in reversed(chain):
            effective |= {code: (text, kind) for code, text, kind in by_name[link][1] if code}
        names |= {text for text, kind in effective.values() if 2 <= kind <= 8}
    return names


@pytest.mark.skipif(not (ESPEAK_DATA / "phontab").exists(), reason="espeak-ng data missing")
def test_every_phoneme_of_the_installed_english_tables_is_mapped() -> None:
    names = _english_phoneme_table_names()
    assert {"aI@", "tS", "@L", "3:", "e@", "i@3", "0"} <= names
    unmapped = []
    for name in sorted(names):
        try:
            normalize_phoneme(name, "espeak")
        except UnknownPhonemeError:
            unmapped.append(name)
    assert unmapped == []


class _EspeakEvent(ctypes.Structure):
    class _Id(ctypes.Union):
        _fields_ = [
            ("number", ctypes.c_int),
            ("name", ctypes.c_char_p),
            ("string", ctypes.c_char * 8),
        ]

    _fields_ = [
        ("type", ctypes.c_int),
        ("unique_identifier", ctypes.c_uint),
        ("text_position", ctypes.c_int),
        ("length", ctypes.c_int),
        ("audio_position", ctypes.c_int),
        ("sample", ctypes.c_int),
        ("user_data", ctypes.c_void_p),
        ("id", _Id),
    ]


def _phoneme_event_names(text: str, voice: str) -> list[str]:
    """Names from libespeak-ng's espeakEVENT_PHONEME events (synchronous mode)."""
    library = ctypes.util.find_library("espeak-ng")
    if library is None:
        pytest.skip("libespeak-ng missing")
    lib = ctypes.CDLL(library)
    names: list[str] = []
    callback_type = ctypes.CFUNCTYPE(
        ctypes.c_int,
        ctypes.POINTER(ctypes.c_short),
        ctypes.c_int,
        ctypes.POINTER(_EspeakEvent),
    )

    def collect(_wav: object, _count: int, events: ctypes.Array[_EspeakEvent]) -> int:
        index = 0
        while events[index].type != 0:
            if events[index].type == 7:  # espeakEVENT_PHONEME
                names.append(events[index].id.string.decode())
            index += 1
        return 0

    callback = callback_type(collect)
    assert lib.espeak_Initialize(2, 0, None, 1) > 0  # SYNCHRONOUS, phoneme events on
    lib.espeak_SetSynthCallback(callback)
    assert lib.espeak_SetVoiceByName(voice.encode()) == 0
    encoded = text.encode() + b"\0"
    assert lib.espeak_Synth(encoded, len(encoded), 0, 1, 0, 1, None, None) == 0
    lib.espeak_Synchronize()
    return names


@needs_espeak
@pytest.mark.parametrize("voice", ["en-us", "en"])
def test_names_from_espeak_phoneme_events_normalize(voice: str) -> None:
    names = _phoneme_event_names(TEXT, voice)
    assert len(names) > 700
    assert normalize_phonemes(names[:4], "espeak") == ["DH", "AH", "B", "ER"]  # "The birch"
    canonical = normalize_phonemes(names, "espeak", voice)
    assert canonical.count("sil") >= 30  # one pause per sentence at least


def test_unknown_label_names_label_source_and_location() -> None:
    with pytest.raises(UnknownPhonemeError) as caught:
        normalize_phoneme("XQ7", "timit", where="utt01.TextGrid:line 42")
    error = caught.value
    assert error.code == "unknown_phoneme"
    assert error.where == "utt01.TextGrid:line 42"
    assert "'XQ7'" in str(error) and "'timit'" in str(error)
    assert str(error).startswith("utt01.TextGrid:line 42: ")


def test_sequence_errors_point_at_the_item() -> None:
    with pytest.raises(UnknownPhonemeError) as caught:
        normalize_phonemes(["AA1", "B", "??"], "arpabet", "words.txt:line 3")
    assert caught.value.where == "words.txt:line 3[2]"


def test_non_string_label_and_unknown_source_raise_lipstream_errors() -> None:
    with pytest.raises(UnknownPhonemeError, match="must be a string"):
        not_a_string: Any = 7
        normalize_phoneme(not_a_string, "arpabet")
    with pytest.raises(LipstreamError) as caught:
        normalize_phoneme("AA", "xsampa", where="config.toml:line 2")
    assert caught.value.code == "unknown_phoneme_source"
    assert "'xsampa'" in str(caught.value) and caught.value.where == "config.toml:line 2"


def test_detect_source_reads_a_whole_file_of_labels() -> None:
    assert detect_source(labels("sil breath sil dh i s w @ z ii uh")) == "mocha"
    assert detect_source(labels("h# sh ix hv eh dcl jh ih dcl d ah uh q h#")) == "timit"
    assert detect_source(labels("HH AH0 L OW1 UH1")) == "arpabet"
    assert detect_source(["", "HH", "AH0", "L", "OW1", "spn"]) == "mfa"
    assert detect_source(["", "h", "ə", "l", "ow", "spn"]) == "mfa"
    assert detect_source(["D", "@2", "k", "'a", "t", "_:"]) == "espeak"
    assert detect_source(["ˈaɪ", "ɚ", "ʔ"]) == "ipa"
    with pytest.raises(UnknownPhonemeError, match="'zz9' in every source"):
        detect_source(["AA", "zz9"], where="a.lab")
    with pytest.raises(UnknownPhonemeError, match="mix notations"):
        detect_source(["ii", "h#"])


@pytest.mark.parametrize(
    ("label", "expected"),
    [
        ("{", "AE"),
        ("@U", "OW"),
        ("oU", "OW"),
        ("aI", "AY"),
        ("eI", "EY"),
        ("OI", "OY"),
        ("aU", "AW"),
        ("I@", "IY"),
        ("e@", "EH"),
        ("U@", "UH"),
        ("i:", "IY"),
        ("I", "IH"),
        ("E", "EH"),
        ("A:", "AA"),
        ("Q", "AA"),
        ("O:", "AO"),
        ("V", "AH"),
        ("@", "AH"),
        ("3:", "ER"),
        ("@`", "ER"),
        ("u:", "UW"),
        ("U", "UH"),
        ("E:", "EH"),
        ("tS", "CH"),
        ("dZ", "JH"),
        ("T", "TH"),
        ("D", "DH"),
        ("S", "SH"),
        ("Z", "ZH"),
        ("s", "S"),
        ("z", "Z"),
        ("t", "T"),
        ("d", "D"),
        ("N", "NG"),
        ("n", "N"),
        ("h", "HH"),
        ("j", "Y"),
        ("r\\", "R"),
        ("r", "R"),
        ("?", "T"),
        ("4", "D"),
        ("5", "L"),
        ("<p:>", "sil"),
        ("<p>", "sil"),
        ("<nib>", "sil"),
    ],
)
def test_sampa_as_webmaus_writes_it(label: str, expected: str) -> None:
    assert normalize_phoneme(label, "sampa") == expected


def test_sampa_words_and_its_refusals() -> None:
    thought_judge_ship = "T O: t dZ V dZ S I p".split()
    assert normalize_phonemes(thought_judge_ship, "sampa") == ("TH AO T JH AH JH SH IH P".split())
    for label in ("AA1", "sp", "<p", "ə"):
        with pytest.raises(UnknownPhonemeError, match="for source 'sampa'"):
            normalize_phoneme(label, "sampa")
    assert detect_source(["<p:>", "h", "@", "l", "@U", "<p:>"]) == "sampa"
    assert detect_source(["h", "{", "p", "i"]) == "sampa"


def test_is_silence() -> None:
    assert is_silence("sp", "mfa") and is_silence("h#") and is_silence("_:", "espeak")
    assert not is_silence("AA1") and not is_silence("bcl", "timit")


@given(label=st.text(max_size=6), source=st.sampled_from(SOURCES))
def test_any_text_gives_a_canonical_label_or_unknown_phoneme_error(label: str, source: str) -> None:
    try:
        assert normalize_phoneme(label, source) in PHONEMES
    except UnknownPhonemeError as error:
        assert repr(label) in str(error)


@pytest.mark.parametrize("source", ["auto", "arpabet", "mfa", "timit"])
def test_canonical_labels_are_fixed_points(source: str) -> None:
    assert [normalize_phoneme(p, source) for p in PHONEMES] == list(PHONEMES)


@pytest.mark.parametrize("source", SOURCES + tuple(SOURCE_ALIASES))
def test_kept_labels_are_exactly_the_labels_that_normalize_to_themselves(source: str) -> None:
    def kept(label: str) -> bool:
        try:
            return normalize_phoneme(label, source) == label
        except UnknownPhonemeError:
            return False

    candidates = list(PHONEMES) + ["AH0", "aa", "ax", "SIL", " AA", "@", "p", "zz", ""]
    expected = {label for label in candidates if kept(label)}
    assert {label for label in candidates if label in kept_labels(source)} == expected


def test_auto_keeps_every_canonical_label_and_sampa_not_arpabet_vowels() -> None:
    assert kept_labels("auto") == frozenset(PHONEMES)
    assert "AA" not in kept_labels("sampa") and SILENCE in kept_labels("sampa")
