"""Rhubarb Lip Sync's TSV, XML and JSON and Moho's .dat, against hand-written expected files."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.errors import InvalidRequestError
from lipstream.exports.cues import MouthCue, mouth_cues
from lipstream.exports.moho import moho_dat
from lipstream.exports.rhubarb import rhubarb_json, rhubarb_tsv, rhubarb_xml

# Channels deliberately out of A..X order: the exports must find each shape by name.
CHANNELS = ("X", "A", "B", "C", "D", "E", "F", "G", "H")


def frames_showing(shapes: str, *, mixed: bool = False) -> np.ndarray:
    """One frame per letter, its weight on that shape; ``mixed`` spreads some weight around
    (the shown shape still has the largest)."""
    frames = np.zeros((len(shapes), len(CHANNELS)), dtype=np.float32)
    for row, shape in enumerate(shapes):
        if mixed:
            frames[row] = 0.4 / (len(CHANNELS) - 1)
            frames[row, CHANNELS.index(shape)] = 0.6
        else:
            frames[row, CHANNELS.index(shape)] = 1.0
    return frames


# 20 fps: each frame holds 5 cs. X X D D D C B B X -> X 0-10, D 10-25, C 25-30, B 30-40, X 40-45.
HI = frames_showing("XXDDDCBBX", mixed=True)

HI_TSV = "0.00\tX\n0.10\tD\n0.25\tC\n0.30\tB\n0.40\tX\n0.45\tX\n"

HI_XML = """<?xml version="1.0" encoding="utf-8"?>
<rhubarbResult>
  <metadata>
    <soundFile>takes/hi &amp; bye.wav</soundFile>
    <duration>0.45</duration>
  </metadata>
  <mouthCues>
    <mouthCue start="0.00" end="0.10">X</mouthCue>
    <mouthCue start="0.10" end="0.25">D</mouthCue>
    <mouthCue start="0.25" end="0.30">C</mouthCue>
    <mouthCue start="0.30" end="0.40">B</mouthCue>
    <mouthCue start="0.40" end="0.45">X</mouthCue>
  </mouthCues>
</rhubarbResult>
"""

HI_JSON = """{
  "metadata": {
    "soundFile": "takes/hi \\"x\\".wav",
    "duration": 0.45
  },
  "mouthCues": [
    { "start": 0.00, "end": 0.10, "value": "X" },
    { "start": 0.10, "end": 0.25, "value": "D" },
    { "start": 0.25, "end": 0.30, "value": "C" },
    { "start": 0.30, "end": 0.40, "value": "B" },
    { "start": 0.40, "end": 0.45, "value": "X" }
  ]
}
"""

# Moho at 24 fps, frame = 1 + floor(24 t): 0 -> 1, 0.10 -> 3, 0.25 -> 7, 0.30 -> 8, 0.40 -> 10,
# end 0.45 -> 11.
HI_DAT = "MohoSwitch1\n1 X\n3 D\n7 C\n8 B\n10 X\n11 X\n"


def test_cues_are_runs_of_the_strongest_shape_in_centiseconds() -> None:
    cues = mouth_cues(HI, CHANNELS, 20.0)
    assert cues.cues == (
        MouthCue(0, 10, "X"),
        MouthCue(10, 25, "D"),
        MouthCue(25, 30, "C"),
        MouthCue(30, 40, "B"),
        MouthCue(40, 45, "X"),
    )
    assert cues.end == 45


def test_tsv_xml_json_and_dat_match_rhubarbs_layout() -> None:
    cues = mouth_cues(HI, CHANNELS, 20.0)
    assert rhubarb_tsv(cues) == HI_TSV
    assert rhubarb_xml(cues, "takes/hi & bye.wav") == HI_XML
    assert rhubarb_json(cues, 'takes/hi "x".wav') == HI_JSON
    assert moho_dat(cues) == HI_DAT


def test_moho_leaves_out_cues_on_a_taken_frame_and_moves_the_end_past_it() -> None:
    # 50 fps, X A B B B B B B: X 0-2, A 2-4, B 4-16; at 24 fps A and B both land on frame 1.
    assert moho_dat(mouth_cues(frames_showing("XABBBBBB"), CHANNELS, 50.0)) == (
        "MohoSwitch1\n1 X\n4 X\n"
    )
    # 100 fps, X A: the end (0.02 s) lands on frame 1 too, so it moves to frame 2.
    assert moho_dat(mouth_cues(frames_showing("XA"), CHANNELS, 100.0)) == "MohoSwitch1\n1 X\n2 X\n"
    # 30 fps Moho: 0.10 -> 1 + 3 = 4, 0.25 -> 8.5 -> 8, 0.30 -> 10, 0.40 -> 13, 0.45 -> 14.5 -> 14.
    assert moho_dat(mouth_cues(HI, CHANNELS, 20.0), 30.0) == (
        "MohoSwitch1\n1 X\n4 D\n8 C\n10 B\n13 X\n14 X\n"
    )


def test_no_frames_give_rhubarbs_zero_length_rest_cue() -> None:
    cues = mouth_cues(np.zeros((0, 9), dtype=np.float32), CHANNELS, 60.0)
    assert rhubarb_tsv(cues) == "0.00\tX\n"
    assert '<mouthCue start="0.00" end="0.00">X</mouthCue>' in rhubarb_xml(cues)
    assert '{ "start": 0.00, "end": 0.00, "value": "X" }' in rhubarb_json(cues)


def test_frames_above_100_fps_join_within_a_centisecond() -> None:
    # 200 fps: frame i covers [i/2, (i+1)/2) cs, rounded; A A B B -> A 0-1, B 1-2.
    cues = mouth_cues(frames_showing("AABB"), CHANNELS, 200.0)
    assert cues.cues == (MouthCue(0, 1, "A"), MouthCue(1, 2, "B"))


@pytest.mark.parametrize(
    "channels",
    [("jawOpen",) * 9, ("A", "B", "C", "D", "E", "F", "G", "H"), CHANNELS[:8] + ("viseme_sil",)],
)
def test_anything_but_the_nine_shapes_is_refused(channels: tuple[str, ...]) -> None:
    with pytest.raises(InvalidRequestError, match="nine Preston Blair shapes") as error:
        mouth_cues(np.zeros((2, len(channels)), dtype=np.float32), channels, 60.0)
    assert error.value.code == "invalid_request"


def test_moho_frame_rate_outside_rhubarbs_range_is_refused() -> None:
    with pytest.raises(InvalidRequestError, match=r"\[24, 100\]"):
        moho_dat(mouth_cues(HI, CHANNELS, 20.0), 12.0)
