"""Tables written as text: the parser, and entries of the converted tables that
published sources fix (CMUdict, Kirshenbaum, Azure's SAPI visemes, Unreal's
EARFaceBlendShape order)."""

from __future__ import annotations

import pytest

from lipstream.bench.tts_shapes import AZURE_VISEME_OF, IPA_OF
from lipstream.capture.pose import LEFT_EYE_OUTER, RIGHT_EYE_OUTER, RIGID
from lipstream.frontends.espeak_ipa import _KIRSHENBAUM
from lipstream.frontends.viseme_spans import AZURE_VISEMES, POLLY_VISEMES
from lipstream.output.rig_names import A2F_TONGUE, UNIFIED_LIP_JAW
from lipstream.phonemes import ARPABET, normalize_phoneme
from lipstream.tables import names, pairs
from lipstream_client.sinks.livelink import LIVELINK_BLENDSHAPES, LIVELINK_ROTATIONS


def test_names_split_on_any_whitespace_in_order() -> None:
    assert names("\n    b a\n  c\td\n") == ("b", "a", "c", "d")
    assert names("") == ()


def test_pairs_read_alternate_tokens_as_key_and_value() -> None:
    table = pairs("""
        z 1  a 2
        r\\ R  'r" R
    """)
    assert table == {"z": "1", "a": "2", "r\\": "R", "'r\"": "R"}
    assert list(table) == ["z", "a", "r\\", "'r\""]


def test_pairs_refuse_a_key_without_value() -> None:
    with pytest.raises(ValueError, match="'c' has no value"):
        pairs("a 1  b 2  c")


def test_pairs_refuse_a_repeated_key() -> None:
    with pytest.raises(ValueError, match=r"repeat: \['a'\]"):
        pairs("a 1  b 2  a 3")


def test_arpabet_is_cmudicts_39_phonemes() -> None:
    assert len(ARPABET) == len(set(ARPABET)) == 39
    assert ARPABET[:6] == ("AA", "AE", "AH", "AO", "AW", "AY")
    assert ARPABET[-3:] == ("Y", "Z", "ZH")


@pytest.mark.parametrize(
    ("label", "source", "expected"),
    [("ʃ", "ipa", "SH"), ("ɾ̃", "ipa", "N"), ("r\\", "sampa", "R"), ('r"', "espeak", "R")],
)
def test_text_tables_keep_keys_with_marks_and_quotes(
    label: str, source: str, expected: str
) -> None:
    assert normalize_phoneme(label, source) == expected


def test_kirshenbaum_ascii_ipa() -> None:
    assert (_KIRSHENBAUM["@"], _KIRSHENBAUM["S"], _KIRSHENBAUM["N"], _KIRSHENBAUM["T"]) == (
        "ə",
        "ʃ",
        "ŋ",
        "θ",
    )


def test_azure_visemes_are_sapis() -> None:
    assert [AZURE_VISEME_OF[p] for p in ("P", "B", "M", "T", "sil")] == [21, 21, 21, 19, 0]
    assert (AZURE_VISEMES["21"], AZURE_VISEMES["0"], len(AZURE_VISEMES)) == ("P", "sil", 22)
    assert (POLLY_VISEMES["p"], POLLY_VISEMES["sil"]) == ("P", "sil")
    assert IPA_OF["CH"] == "tʃ"


def test_livelink_packet_order_is_unreals() -> None:
    assert len(LIVELINK_BLENDSHAPES) == len(set(LIVELINK_BLENDSHAPES)) == 52
    assert LIVELINK_BLENDSHAPES.index("jawOpen") == 17
    assert (LIVELINK_BLENDSHAPES[0], LIVELINK_BLENDSHAPES[-1]) == ("eyeBlinkLeft", "tongueOut")
    assert LIVELINK_ROTATIONS[:3] == ("headYaw", "headPitch", "headRoll")


def test_rig_name_lists() -> None:
    assert len(A2F_TONGUE) == 16 and A2F_TONGUE[0] == "TongueTipUp"
    assert len(UNIFIED_LIP_JAW) == len(set(UNIFIED_LIP_JAW)) == 41
    assert UNIFIED_LIP_JAW[-1] == "MouthTightenerLeft"


def test_rigid_landmarks_are_integers_holding_the_eye_corners() -> None:
    assert all(isinstance(index, int) for index in RIGID)
    assert len(RIGID) == len(set(RIGID)) == 20
    assert {RIGHT_EYE_OUTER, LEFT_EYE_OUTER, 10} <= set(RIGID)
