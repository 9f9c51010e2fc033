"""Viseme schemes against their published groupings."""

from __future__ import annotations

from typing import Any

import pytest

from lipstream.errors import LipstreamError, UnknownPhonemeError
from lipstream.phonemes import PHONEMES
from lipstream.visemes import SCHEMES, get_scheme, oculus_viseme_name

# Deng & Neumann 2008, Appendix A, Table VI, in lower case as printed ("yl" is
# the extracted text's spelling of /y/). /ax/ /el/ /em/ /en/ fold into AH L M N.
DENG_TABLE_VI = [
    "pau",
    "r",
    "k g ng",
    "ae ax ah aa",
    "f v",
    "ch sh jh",
    "ao yl iy ih ay aw",
    "ow oy",
    "n d t l",
    "ey eh el em en er",
    "th dh",
    "s z zh",
    "b p m",
    "hh",
    "w uw uh",
]
PAPER_TO_CANONICAL = {"pau": "sil", "yl": "Y", "ax": None, "el": None, "em": None, "en": None}

OCULUS_ORDER = [
    "sil",
    "PP",
    "FF",
    "TH",
    "DD",
    "kk",
    "CH",
    "SS",
    "nn",
    "RR",
    "aa",
    "E",
    "I",
    "O",
    "U",
]


@pytest.mark.parametrize("name", ["deng15", "oculus15", "preston-blair"])
def test_every_canonical_phoneme_maps_in_every_scheme(name: str) -> None:
    scheme = SCHEMES[name]
    for phoneme in PHONEMES:
        assert scheme.viseme_of(phoneme) in scheme.classes
    assert sum(len(scheme.members(c)) for c in scheme.classes) == 40
    assert all(scheme.members(c) for c in scheme.classes)


def test_class_counts() -> None:
    assert len(SCHEMES["deng15"].classes) == 15
    assert len(SCHEMES["oculus15"].classes) == 15
    assert SCHEMES["preston-blair"].classes == tuple("ABCDEFGHX")


def test_deng15_reproduces_table_vi() -> None:
    scheme = get_scheme("deng15")
    groups = []
    for row in DENG_TABLE_VI:
        labels = [PAPER_TO_CANONICAL.get(p, p.upper()) for p in row.split()]
        groups.append({p for p in labels if p is not None})
    assert sorted(map(sorted, groups)) == sorted(sorted(scheme.members(c)) for c in scheme.classes)
    assert [set(scheme.members(c)) for c in scheme.classes] == groups  # same order too


@pytest.mark.parametrize(
    ("together", "apart"),
    [
        ("P B M", "F"),
        ("F V", "TH"),
        ("TH DH", "S"),
        ("S Z ZH", "SH"),
        ("CH SH JH", "ZH"),
        ("K G NG", "HH"),
        ("N D T L", "R"),
        ("W UW UH", "OW"),
        ("OW OY", "AO"),
        ("AO Y IY IH AY AW", "EY"),
        ("EY EH ER", "AE"),
        ("AE AH AA", "sil"),
    ],
)
def test_deng15_pairs(together: str, apart: str) -> None:
    scheme = get_scheme("deng15")
    classes = {scheme.viseme_of(p) for p in together.split()}
    assert len(classes) == 1
    assert scheme.viseme_of(apart) not in classes


def test_oculus_order_and_names() -> None:
    scheme = get_scheme("oculus15")
    assert list(scheme.classes) == OCULUS_ORDER
    for index, name in enumerate(OCULUS_ORDER):
        assert scheme.class_name(f"viseme_{name}") == name
        assert oculus_viseme_name(name) == name
        assert scheme.classes.index(oculus_viseme_name(f"viseme_{name}")) == index
    assert [oculus_viseme_name(n) for n in ("ih", "oh", "ou", "viseme_I", "IH", "OU")] == [
        "I",
        "O",
        "U",
        "I",
        "I",
        "U",
    ]


@pytest.mark.parametrize(
    ("phonemes", "viseme"),
    # The Oculus viseme reference: example phonemes and words for each viseme.
    [
        ("P B M", "PP"),
        ("F V", "FF"),
        ("TH DH", "TH"),
        ("T D", "DD"),
        ("K G", "kk"),
        ("CH JH SH", "CH"),
        ("S Z", "SS"),
        ("N L", "nn"),
        ("R", "RR"),
        ("AA", "aa"),
        ("EH", "E"),
        ("IH", "I"),
        ("OW", "O"),
        ("UH", "U"),
        ("sil", "sil"),
    ],
)
def test_oculus_reference_examples(phonemes: str, viseme: str) -> None:
    scheme = get_scheme("oculus15")
    assert {scheme.viseme_of(p) for p in phonemes.split()} == {viseme}


@pytest.mark.parametrize(
    ("phonemes", "shape"),
    # Rhubarb Lip Sync's shape descriptions.
    [
        ("P B M", "A"),
        ("K S T IY", "B"),
        ("EH AE", "C"),
        ("AA", "D"),
        ("AO ER", "E"),
        ("UW OW W", "F"),
        ("F V", "G"),
        ("L", "H"),
        ("sil", "X"),
    ],
)
def test_preston_blair_rhubarb_shapes(phonemes: str, shape: str) -> None:
    scheme = get_scheme("preston-blair")
    assert {scheme.viseme_of(p) for p in phonemes.split()} == {shape}


def test_viseme_of_accepts_any_source_notation() -> None:
    deng = get_scheme("deng15")
    assert deng.viseme_of("aa1") == deng.viseme_of("AA")
    assert deng.viseme_of("D", source="espeak") == "th-dh"
    assert deng.viseme_of("D") == "n-d-t-l"
    assert deng.viseme_of("h#") == "pau"
    assert deng.viseme_of("bcl", source="timit") == "b-p-m"
    assert get_scheme("oculus15").index_of("'aI@", source="espeak") == OCULUS_ORDER.index("aa")
    assert get_scheme("oculus15").index_of("sp", source="mfa") == 0
    with pytest.raises(UnknownPhonemeError) as caught:
        deng.viseme_of("XX", where="clip.json:spans[3]")
    assert caught.value.where == "clip.json:spans[3]"


def test_scheme_lookup() -> None:
    assert get_scheme("Oculus15") is SCHEMES["oculus15"]
    assert get_scheme("ovr") is SCHEMES["oculus15"]
    assert get_scheme("rhubarb") is SCHEMES["preston-blair"]
    with pytest.raises(LipstreamError) as caught:
        get_scheme("disney12", where="model.json:hyperparameters.scheme")
    assert caught.value.code == "unknown_viseme_scheme"
    assert "'disney12'" in str(caught.value)
    assert caught.value.where == "model.json:hyperparameters.scheme"


def test_unknown_viseme_name() -> None:
    with pytest.raises(LipstreamError) as caught:
        oculus_viseme_name("viseme_XX", where="rig.fbx")
    assert caught.value.code == "unknown_viseme"
    assert "'viseme_XX'" in str(caught.value) and caught.value.where == "rig.fbx"


def test_schemes_are_read_only() -> None:
    scheme: Any = get_scheme("deng15")
    with pytest.raises(TypeError):
        scheme.mapping["AA"] = "pau"
    with pytest.raises(AttributeError):
        scheme.name = "other"
    assert scheme.mapping["AA"] == "ae-ax-ah-aa" and scheme.name == "deng15"
