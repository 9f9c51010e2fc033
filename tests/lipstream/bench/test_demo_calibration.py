"""The demo character's calibration measures on synthetic curves with known answers, and the
command end to end on the shipped GRID set beside a small corpus written to tmp_path."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from lipstream.bench.demo_calibration import (
    OTHER_TALKERS,
    Track,
    closure_timings,
    main,
    peak_speeds,
    phone_apertures,
    resample,
    rounding_half_rises,
    summarize,
    talker_groups,
)
from lipstream.corpus import Corpus, Utterance, write_corpus
from lipstream.timeline import PhonemeSpan

FPS = 25.0


def test_resampling_reads_a_line_on_the_new_grid() -> None:
    values = 2.0 * np.arange(121) / 120.0  # 1 s at 120 fps of 2 t
    resampled = resample(values, 120.0, FPS)
    assert len(resampled) == 26
    np.testing.assert_allclose(resampled, 2.0 * np.arange(26) / FPS)


def test_closure_is_timed_at_its_plateau_centre_from_the_bilabial_onset() -> None:
    # the B runs from frame 10 (0.4 s) to frame 14; lips shut on frames 9..11, centre 10
    aperture = np.full(30, 0.5)
    aperture[9:12] = 0.0
    phones = [
        PhonemeSpan("sil", 0.0, 0.2),
        PhonemeSpan("AA", 0.2, 0.4),
        PhonemeSpan("B", 0.4, 0.56),
        PhonemeSpan("AA", 0.56, 1.2),
    ]
    track = Track(aperture, np.zeros(30), phones)
    ((offset, share),) = closure_timings(track, FPS)
    assert offset == pytest.approx(0.0, abs=1e-9)
    assert share == pytest.approx(0.0, abs=1e-9)
    aperture[9:12], aperture[11:14] = 0.5, 0.0  # shut on frames 11..13: 80 ms in, half the B
    ((offset, share),) = closure_timings(track, FPS)
    assert offset == pytest.approx(0.08)
    assert share == pytest.approx(0.5)


def test_peak_speeds_are_relative_to_the_aperture_range() -> None:
    # speech over every frame; aperture rises by 0.1 a frame to 1, holds, falls by 0.25
    aperture = np.concatenate([np.arange(11) * 0.1, np.ones(10), 1.0 - np.arange(1, 5) * 0.25])
    phones = [PhonemeSpan("AA", 0.0, len(aperture) / FPS)]
    opening, closing = peak_speeds(Track(aperture, np.zeros_like(aperture), phones), FPS) or (0, 0)
    low, high = np.percentile(aperture, [2.0, 98.0])
    assert opening == pytest.approx(0.1 * FPS / (high - low))
    assert closing == pytest.approx(0.25 * FPS / (high - low))
    flat = Track(np.full(20, 0.3), np.zeros(20), [PhonemeSpan("AA", 0.0, 0.8)])
    assert peak_speeds(flat, FPS) is None


def test_phone_aperture_is_its_mean_as_a_share_of_the_speech_range() -> None:
    # 2 s at 25 fps: AA open at 1.0 (frames 0..24), M shut at 0.0 (25..29), IY at 0.5
    # (30..39), then silence at 9.0 (40..49), which is not speech and sets no range
    aperture = np.concatenate([np.ones(25), np.zeros(5), np.full(10, 0.5), np.full(10, 9.0)])
    phones = [
        PhonemeSpan("AA", 0.0, 1.0),
        PhonemeSpan("M", 1.0, 1.2),
        PhonemeSpan("IY", 1.2, 1.6),
        PhonemeSpan("sil", 1.6, 2.0),
    ]
    shares = phone_apertures(Track(aperture, np.zeros(50), phones), FPS)
    low, high = np.percentile(aperture[:40], [2.0, 98.0])
    assert [p for p, _ in shares] == ["AA", "M", "IY"]
    expected = [(value - low) / (high - low) for value in (1.0, 0.0, 0.5)]
    np.testing.assert_allclose([share for _, share in shares], expected)
    assert low == pytest.approx(0.0) and high == pytest.approx(1.0)
    still = Track(np.full(20, 0.3), np.zeros(20), [PhonemeSpan("AA", 0.0, 0.8)])
    assert phone_apertures(still, FPS) == []


def test_rounding_half_rise_is_timed_against_the_vowel_onset() -> None:
    # UW from 0.6 s (frame 15); rounding ramps 0 -> 0.4 over frames 10..14, so it crosses
    # 0.2 at frame 12: 120 ms before the vowel
    rounding = np.zeros(30)
    rounding[10:15] = np.arange(5) * 0.1
    rounding[15:] = 0.4
    phones = [
        PhonemeSpan("sil", 0.0, 0.4),
        PhonemeSpan("T", 0.4, 0.6),
        PhonemeSpan("UW", 0.6, 0.9),
        PhonemeSpan("sil", 0.9, 1.2),
    ]
    (lead,) = rounding_half_rises(Track(np.zeros(30), rounding, phones), FPS)
    assert lead == pytest.approx(-0.12)
    small = Track(np.zeros(30), 0.1 * rounding, phones)  # a rise of 0.04: not timed
    assert rounding_half_rises(small, FPS) == []
    after_silence = [PhonemeSpan("sil", 0.0, 0.6), *phones[2:]]
    assert rounding_half_rises(Track(np.zeros(30), rounding, after_silence), FPS) == []


def test_summary_of_known_values() -> None:
    summary = summarize([1.0, 2.0, 6.0])
    assert summary.mean == 3.0 and summary.count == 3
    assert summary.sd == pytest.approx(np.sqrt(7.0))
    assert summarize([]).mean is None


def _tiny_corpus(path: Path) -> None:
    fps = 100.0
    times = np.arange(101) / fps
    channels = ("jawOpen", "mouthClose", "mouthFunnel", "mouthPucker")
    frames = np.zeros((101, 4), dtype=np.float32)
    frames[:, 0] = 0.4
    frames[:, 1] = np.where((times >= 0.4) & (times < 0.5), 0.4, 0.0)
    frames[:, 3] = np.clip((times - 0.6) * 4.0, 0.0, 0.4)
    phones = [
        PhonemeSpan("sil", 0.0, 0.2),
        PhonemeSpan("AA", 0.2, 0.4),
        PhonemeSpan("M", 0.4, 0.5),
        PhonemeSpan("T", 0.5, 0.7),
        PhonemeSpan("UW", 0.7, 0.9),
        PhonemeSpan("sil", 0.9, 1.0),
    ]
    utterance = Utterance(stem="tiny", frames=frames, phones=phones, fps=fps, text="ma too")
    write_corpus(Corpus(name="tiny", fps=fps, channels=channels, utterances=[utterance]), path)


def test_command_measures_the_real_set_and_a_named_corpus(tmp_path: Path) -> None:
    _tiny_corpus(tmp_path / "tiny")
    out = tmp_path / "calibration.json"
    main(["--corpus", f"tiny={tmp_path / 'tiny'}", "--json", str(out)])
    doc = json.loads(out.read_text())
    assert set(doc["corpora"]) == {"real", "real: s1", "real: other talkers", "tiny"}
    assert doc["corpora"]["real"]["utterances"] == 59
    # the shipped set: 49 clips of GRID's talker s1 and one of each of ten others
    assert doc["corpora"]["real: s1"]["utterances"] == 49
    assert doc["corpora"]["real: other talkers"]["utterances"] == 10
    tiny = doc["corpora"]["tiny"]["measures"]
    # on the 25 fps grid the lips are shut on frames 10..12 (0.40, 0.44, 0.48 s): centre 0.44 s
    assert tiny["closure_from_onset_ms"]["mean"] == pytest.approx(40.0)
    assert tiny["closure_from_onset_ms"]["count"] == 1
    assert tiny["rounding_half_rise_ms"]["count"] == 1


def _talker(stem: str, speaker: str | None) -> Utterance:
    frames = np.zeros((3, 2), dtype=np.float32)
    phones = [PhonemeSpan("sil", 0.0, 0.02)]
    return Utterance(stem=stem, frames=frames, phones=phones, fps=100.0, speaker=speaker)


def test_talkers_with_enough_clips_are_measured_alone_and_the_rest_pooled() -> None:
    utterances = [
        _talker("a1", "ann"),
        _talker("b1", "bob"),
        _talker("a2", "ann"),
        _talker("c1", None),
        _talker("a3", "ann"),
        _talker("b2", "bob"),
        _talker("d1", "dee"),
    ]
    corpus = Corpus("set", 100.0, ("jawOpen", "mouthClose"), utterances)
    groups = talker_groups(corpus, min_clips=2)
    assert [(name, group.stems) for name, group in groups] == [
        ("ann", ("a1", "a2", "a3")),
        ("bob", ("b1", "b2")),
        (OTHER_TALKERS, ("c1", "d1")),
    ]
    assert talker_groups(corpus, min_clips=4) == []  # none has four: one pooled group
    one = Corpus("one", 100.0, ("jawOpen", "mouthClose"), utterances[:1])
    assert talker_groups(one, min_clips=1) == []
