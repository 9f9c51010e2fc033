"""The HMM frame-rate bench: its settings, its averages on hand-made rows, one real
measurement on a small corpus, and its report block."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from lipstream.bench.closure_sources import RealPhones, character_apertures
from lipstream.bench.hmm_rate import measure, rate_means, settings_at
from lipstream.bench.real_faces import real_clips
from lipstream.bench.real_set import REAL_SET
from lipstream.bench.report import BLOCKS, Bench
from lipstream.corpus import Corpus, load_corpus

RUNG_NAMES = ("full", "short", "causal_lead", "causal")


def test_settings_keep_the_seconds_that_frames_count() -> None:
    base = {"hmm_fps": 60.0, "max_training_frames": 12000, "prior_frames": 60.0, "seed": 0}
    assert settings_at(base, 40.0, 3) == {
        "hmm_fps": 40.0,
        "max_training_frames": 8000,
        "prior_frames": 40.0,
        "seed": 3,
    }
    assert settings_at(base, 100.0, 1)["max_training_frames"] == 20000
    assert settings_at(base, 100.0, 1)["prior_frames"] == pytest.approx(100.0)


def _row(rate: float, seed: int, real: float, fit: float, voice_cpu: float) -> dict[str, Any]:
    return {
        "hmm_fps": rate,
        "seed": seed,
        "rungs": {
            name: {"lag_ms": real / 2 + index, "rms": 0.06 + index / 100}
            for index, name in enumerate(RUNG_NAMES)
        },
        "voice_rms_ratio": 0.5 + seed / 10,
        "real_phones_lag_ms": real - 1.0,
        "real": {"mean_ms": real},
        "aperture_r": 0.4 + seed / 10,
        "fit_cpu_s": fit,
        "voice_cpu_per_speech_s": voice_cpu,
    }


def test_rate_means_average_each_rate_over_its_seeds() -> None:
    rows = [
        _row(40.0, 0, 30.0, 4.0, 0.001),
        _row(40.0, 1, 10.0, 6.0, 0.003),
        _row(60.0, 0, 8.0, 9.0, 0.003),
        _row(60.0, 1, 2.0, 11.0, 0.003),
    ]
    means = rate_means(rows)
    assert [row["hmm_fps"] for row in means] == [40.0, 60.0]
    low, high = means
    assert low["seeds"] == 2
    assert low["real_lag_ms"] == pytest.approx(20.0)
    assert (low["real_lag_min_ms"], low["real_lag_max_ms"]) == (10.0, 30.0)
    assert low["real_phones_lag_ms"] == pytest.approx(19.0)
    assert low["rungs"]["causal"]["lag_ms"] == pytest.approx(13.0)
    assert high["voice_rms_ratio"] == pytest.approx(0.55)
    assert high["aperture_r"] == pytest.approx(0.45)
    assert (high["fit_cpu_s"], low["voice_cpu_per_speech_s"]) == (10.0, pytest.approx(0.002))


@pytest.fixture(scope="module")
def few_real_clips() -> RealPhones:
    corpus = load_corpus(REAL_SET)
    clips = real_clips(corpus)[:4]
    return RealPhones(corpus.name, clips, character_apertures(clips, corpus.fps), corpus.fps)


def test_a_measurement_trains_at_the_rate_and_reads_every_figure(
    small_demo_corpus: Corpus, few_real_clips: RealPhones
) -> None:
    base = {"hmm_fps": 40.0, "max_training_frames": 4000, "prior_frames": 40.0}
    settings = settings_at(base | {"n_states": 8, "n_iter": 3}, 80.0, 2)
    row = measure(settings, small_demo_corpus.split(), few_real_clips, reference_rms=0.05)
    assert (row["hmm_fps"], row["seed"]) == (80.0, 2)  # the fitted model's own rate
    assert 1 <= row["states"] <= 8
    assert set(row["rungs"]) == set(RUNG_NAMES)
    assert all(0.0 < rung["rms"] < 1.0 for rung in row["rungs"].values())
    assert row["voice_rms_ratio"] > 0.0 and -1.0 <= row["aperture_r"] <= 1.0
    assert row["real"]["count"] > 0
    assert row["fit_cpu_s"] > 0.0 and row["voice_cpu_per_speech_s"] > 0.0


def test_the_block_renders_each_rate_beside_the_first(tmp_path: Path) -> None:
    doc = {
        "date": "2030-01-02T03:04:05+00:00",
        "corpus": {"name": "demo", "fps": 120.0},
        "real_set": {"name": "grid", "clips": 59, "fps": 25.0},
        "default_hmm_fps": 60.0,
        "seeds": [0, 1],
        "rungs": list(RUNG_NAMES),
        "rates": rate_means([_row(40.0, 0, 26.75, 4.0, 0.001), _row(60.0, 0, 8.25, 10.0, 0.0015)]),
    }
    (tmp_path / "hmm_rate.json").write_text(json.dumps(doc))
    rendered = BLOCKS["hmm-rate"](Bench(tmp_path))
    assert "Source: `bench/hmm_rate.json`" in rendered and "59 clips of `grid`" in rendered
    assert "| 40 | +26.8 (+26.8 .. +26.8) | +25.8 | 0.400 | +13.4 / 0.0600 |" in rendered
    assert "| **60** | +8.2 (+8.2 .. +8.2) | +7.2 |" in rendered
    assert "| 0.500 | ×2.50 | ×1.50 |" in rendered


def test_the_block_says_when_the_bench_was_not_run(tmp_path: Path) -> None:
    assert "no `bench/hmm_rate.json`" in BLOCKS["hmm-rate"](Bench(tmp_path))
