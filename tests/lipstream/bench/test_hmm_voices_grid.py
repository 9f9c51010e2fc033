"""The real-speech part of ``python -m lipstream.bench.hmm_voices``: each GRID clip's sound
found where the set ships it, and the per-clip figures averaged and rendered."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from lipstream.bench.aligner_real import grid_sound
from lipstream.bench.hmm_voices import mean_figures
from lipstream.bench.report import BLOCKS, Bench

GRID = Path(__file__).resolve().parents[2] / "data" / "grid"


def test_the_mean_leaves_out_undefined_r_and_counts_the_clips() -> None:
    clips: list[dict[str, Any]] = [
        {"hmm_audio_r": 0.5, "viseme_lerp_r": 0.2, "warp": 0.88},
        {"hmm_audio_r": None, "viseme_lerp_r": 0.4, "warp": 1.12},
        {"hmm_audio_r": -0.1, "viseme_lerp_r": 0.6, "warp": 1.0},
    ]
    assert mean_figures(clips) == {
        "clips": 3,
        "hmm_audio_r": pytest.approx(0.2),
        "viseme_lerp_r": pytest.approx(0.4),
    }
    assert mean_figures([{"hmm_audio_r": None}]) == {"clips": 1, "hmm_audio_r": None}


def test_every_shipped_clip_has_its_sound(tmp_path: Path) -> None:
    stems = sorted(path.stem for path in (GRID / "corpus").glob("*.json") if path.stem != "corpus")
    found = {stem: grid_sound(GRID, stem) for stem in stems}
    assert found["swwp2s"] == GRID / "swwp2s.mp4"
    assert all(found[stem] == GRID / "clips" / f"{stem}.ogg" for stem in stems if stem != "swwp2s")
    assert grid_sound(tmp_path, "swwp2s") is None


def _configuration(grid_mean: dict[str, object]) -> dict[str, object]:
    figures = {"audio_ratio": 0.6, "phonemes_ratio": 0.5}
    return {"training_lines": 299, "sets": {"demo": figures}, "grid": {}, "grid_mean": grid_mean}


def test_the_report_gives_each_configurations_mean_over_the_clips(tmp_path: Path) -> None:
    doc = {
        "date": "2030-01-02T03:04:05+00:00",
        "machine": {"python": "3.11.7"},
        "command": "python -m lipstream.bench.hmm_voices",
        "corpus": {"digest": "0123456789abcdef", "lines": 332},
        "second_character": {
            "voice": "en-us+m7",
            "pitch": 30,
            "rate_factor": 1.25,
            "jaw_scale": 1.35,
            "lips_scale": 0.8,
            "rounding_scale": 1.3,
            "stiffness_scale": 1.3,
            "lines": 120,
        },
        "heldout_voice": {"variant": "f5", "pitch_shift": 14},
        "grid": {"clips": 59, "clips_with_sound": ["a"] * 59},
        "configurations": {
            "raw": _configuration(
                {"clips": 59, "hmm_audio_r": -0.05, "hmm_phonemes_r": 0.339, "viseme_lerp_r": 0.514}
            )
        },
    }
    (tmp_path / "hmm_voices.json").write_text(json.dumps(doc))
    rendered = BLOCKS["hmm-voices"](Bench(tmp_path))
    assert "GRID clips with sound: 59 of 59." in rendered
    assert "| raw | 59 | -0.050 | +0.339 | +0.514 |" in rendered
