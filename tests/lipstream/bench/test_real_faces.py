"""``lipstream bench --real``: its measures on synthetic curves with known answers, and the
command end to end on two shipped GRID clips with ``viseme-lerp``."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from lipstream import cli
from lipstream.bench.real_faces import (
    Clip,
    fit_linear_map,
    pearson_r,
    score_apertures,
    speaker_maps,
    speech_mask,
)
from lipstream.corpus import Corpus, read_textgrid_phones
from lipstream.engines.base import Model
from lipstream.evaluation import lip_aperture
from lipstream.timeline import PhonemeSpan

GRID = Path(__file__).resolve().parents[2] / "data" / "grid" / "corpus"
FPS = 25.0


def test_linear_map_recovers_a_known_map() -> None:
    source = np.array([0.1, 0.4, 0.2, 0.9, 0.5, 0.3])
    linear = fit_linear_map(source, 2.5 * source - 0.3)
    assert linear.slope == pytest.approx(2.5)
    assert linear.offset == pytest.approx(-0.3)
    assert fit_linear_map(np.full(4, 0.2), np.array([1.0, 2.0, 3.0, 6.0])).offset == 3.0


def test_pearson_r_of_a_known_mixture() -> None:
    # over whole periods cos and sin are centred and orthogonal with equal norms, so
    # cos + c·sin has r = 1 / sqrt(1 + c²) with cos
    t = np.arange(200) * 2 * np.pi / 200
    assert pearson_r(np.cos(t), np.cos(t) + 0.75 * np.sin(t)) == pytest.approx(1 / 1.25)
    assert pearson_r(np.cos(t), -3 * np.cos(t) + 1) == pytest.approx(-1.0)
    assert pearson_r(np.cos(t), np.ones(200)) is None


def test_speech_is_every_frame_inside_a_phone_but_silence() -> None:
    spans = [PhonemeSpan("sil", 0.0, 0.1), PhonemeSpan("B", 0.1, 0.2), PhonemeSpan("sil", 0.2, 0.4)]
    # frames at 0, 40, 80, 120, 160, 200, ... ms: 120 and 160 lie in [100, 200)
    assert np.flatnonzero(speech_mask(spans, FPS, 10)).tolist() == [3, 4]


def _phones(closure_start_frame: int) -> list[PhonemeSpan]:
    """sil, AA, B (4 frames), AA, sil at 25 fps, the B from ``closure_start_frame``."""
    b = closure_start_frame / FPS
    return [
        PhonemeSpan("sil", 0.0, 0.2),
        PhonemeSpan("AA", 0.2, b),
        PhonemeSpan("B", b, b + 4 / FPS),
        PhonemeSpan("AA", b + 4 / FPS, b + 0.6),
        PhonemeSpan("sil", b + 0.6, b + 0.8),
    ]


def _real_aperture(n: int, shut: range, wobble: float) -> np.ndarray:
    """Open at 0.5 (with a wobble so r is defined), shut at 0 for the frames of ``shut``."""
    aperture: np.ndarray = 0.5 + wobble * np.sin(np.arange(n) * 0.7)
    aperture[list(shut)] = 0.0
    return aperture


def _clip(stem: str, speaker: str, start: int, wobble: float) -> Clip:
    phones = _phones(start)
    n = round(phones[-1].end * FPS)
    aperture = _real_aperture(n, range(start, start + 4), wobble)
    return Clip(stem, speaker, aperture, speech_mask(phones, FPS, n), phones)


def test_a_scaled_copy_shifted_by_two_frames_closes_80_ms_late() -> None:
    clips = [_clip("a", "one", 12, 0.1), _clip("b", "one", 15, 0.05)]
    # the prediction: each real curve in the demo character's units (real = 2·pred - 0.1),
    # delayed by two frames
    shift = 2
    predicted = [np.roll((clip.aperture + 0.1) / 2, shift) for clip in clips]
    row = score_apertures("shifted", clips, predicted, FPS, threshold=0.01)
    assert row.closure_lag_ms == pytest.approx(1000 * shift / FPS)
    assert row.closure_lag_sd_ms == pytest.approx(0.0)
    assert row.closures_timed == 2
    assert row.clips_mapped_on_themselves == 0


def test_the_lags_standard_error_is_their_sd_over_root_n() -> None:
    """Three clips closing 0, 1 and 2 frames late: lags 0, 40 and 80 ms, whose mean is
    40, sample sd 40 and standard error 40 / sqrt(3)."""
    clips = [_clip("a", "one", 12, 0.1), _clip("b", "one", 15, 0.05), _clip("c", "one", 13, 0.08)]
    predicted = [np.roll((clip.aperture + 0.1) / 2, shift) for clip, shift in zip(clips, (0, 1, 2))]
    row = score_apertures("spread", clips, predicted, FPS, threshold=0.01)
    assert row.closures_timed == 3
    assert row.closure_lag_ms == pytest.approx(40.0)
    assert row.closure_lag_sd_ms == pytest.approx(40.0)
    assert row.closure_lag_se_ms == pytest.approx(40.0 / np.sqrt(3))


def test_one_closure_has_no_spread() -> None:
    clips = [_clip("a", "one", 12, 0.1)]
    row = score_apertures("one", clips, [np.roll(clips[0].aperture, 1)], FPS, threshold=0.01)
    assert row.closure_lag_ms == pytest.approx(40.0)
    assert row.closure_lag_sd_ms is None and row.closure_lag_se_ms is None


@pytest.mark.parametrize(("speakers", "on_themselves"), [(("one", "one"), 0), (("one", "two"), 2)])
def test_an_unshifted_copy_has_r_one_no_lag_and_closes(
    speakers: tuple[str, str], on_themselves: int
) -> None:
    clips = [_clip("a", speakers[0], 12, 0.1), _clip("b", speakers[1], 15, 0.05)]
    # the same map for both clips, so the map fitted on the other clip is exact too
    predicted = [0.3 * clip.aperture + 0.2 for clip in clips]
    row = score_apertures("copy", clips, predicted, FPS, threshold=0.01)
    assert row.aperture_r == pytest.approx(1.0)
    assert row.closure_lag_ms == pytest.approx(0.0)
    assert row.clips_mapped_on_themselves == on_themselves
    assert row.closure_rate == 1.0


def test_a_prediction_that_never_closes_closes_none() -> None:
    clips = [_clip("a", "one", 12, 0.1)]
    t = np.arange(len(clips[0].aperture))
    predicted = [0.5 + 0.2 * np.sin(t * 0.7)]  # the wobble without the closure
    row = score_apertures("open", clips, predicted, FPS, threshold=0.01)
    assert row.closure_rate == 0.0


def test_leave_one_clip_out_fits_on_the_other_clips_only() -> None:
    clips = [_clip("a", "one", 12, 0.1), _clip("b", "one", 15, 0.05), _clip("c", "two", 12, 0.1)]
    # clip a's prediction is off by a different map from b's: a's map is b's, and vice versa
    predicted = [3 * clips[0].aperture, (clips[1].aperture - 0.2) / 4, clips[2].aperture + 1]
    maps, own = speaker_maps(clips, predicted)
    assert (maps[0].slope, maps[0].offset) == pytest.approx((4.0, 0.2))
    assert (maps[1].slope, maps[1].offset) == pytest.approx((1 / 3, 0.0))
    assert (maps[2].slope, maps[2].offset) == pytest.approx((1.0, -1.0))
    assert own == 1


@pytest.fixture(scope="module")
def lerp_only(small_demo_corpus: Corpus, tmp_path_factory: pytest.TempPathFactory) -> Path:
    from lipstream.training import train_engine

    train, _ = small_demo_corpus.split()
    directory = tmp_path_factory.mktemp("lerp-only")
    train_engine(train, "viseme-lerp").save(directory / "viseme-lerp")
    return directory


def _aperture_from_csv(path: Path) -> np.ndarray:
    with path.open(newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    return np.array([float(row["jawOpen"]) - float(row["mouthClose"]) for row in rows])


def test_bench_real_on_two_clips(
    lerp_only: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from lipstream.engines import load_model

    corpus = tmp_path / "grid"
    corpus.mkdir()
    shutil.copyfile(GRID / "corpus.json", corpus / "corpus.json")
    stems = ["bbaf2n", "lbbc2a"]  # both say "bin": each has a /b/
    for stem in stems:
        for suffix in (".csv", ".TextGrid", ".json"):
            shutil.copyfile(GRID / f"{stem}{suffix}", corpus / f"{stem}{suffix}")
    monkeypatch.setenv("LIPSTREAM_HOME", str(tmp_path / "home"))
    results = tmp_path / "real.json"
    argv = ["bench", "--real", "--corpus", str(corpus), "--models", str(lerp_only)]
    assert cli.main([*argv, "--results", str(results)]) == 0

    doc = json.loads(results.read_text(encoding="utf-8"))
    assert doc["command"] == " ".join(["lipstream", *argv, "--results", str(results)])
    assert doc["machine"]["python"] and doc["date"]
    assert doc["corpus"]["clips"] == 2
    (row,) = doc["engines"]
    assert row["engine"] == "viseme-lerp"
    assert row["clips_mapped_on_themselves"] == 2
    assert row["closures_timed"] >= 2
    model = load_model(lerp_only / "viseme-lerp")
    for stem in stems:
        phones = read_textgrid_phones(corpus / f"{stem}.TextGrid")
        real = _aperture_from_csv(corpus / f"{stem}.csv")
        frames = model.synthesize(phones, fps=FPS).frames
        jaw, close = model.channels.index("jawOpen"), model.channels.index("mouthClose")
        predicted = (frames[:, jaw] - frames[:, close])[: len(real)]
        times = np.arange(len(real)) / FPS
        speech = np.zeros(len(real), dtype=bool)
        for span in phones:
            if span.phoneme != "sil":
                speech |= (times >= span.start) & (times < span.end)
        expected = np.corrcoef(predicted[speech], real[speech])[0, 1]
        assert row["aperture_r_by_clip"][stem] == pytest.approx(expected, abs=1e-6)


def test_bench_real_wants_a_baseline(
    small_demo_corpus: Corpus,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    from lipstream.training import train_engine

    train, _ = small_demo_corpus.split()
    train_engine(train, "cohen-massaro").save(tmp_path / "models" / "cohen-massaro")
    monkeypatch.setenv("LIPSTREAM_HOME", str(tmp_path / "home"))
    argv = ["bench", "--real", "--corpus", str(GRID), "--models", str(tmp_path / "models")]
    assert cli.main([*argv, "--results", str(tmp_path / "x.json")]) == 2
    error = capsys.readouterr().err
    assert "[invalid_request]" in error and "no viseme-lerp model" in error
    assert not (tmp_path / "x.json").exists()


@pytest.mark.parametrize(
    "extra", [["--real", "--word-timings"], ["--real", "--no-engine-benches"], ["--models", "m"]]
)
def test_options_that_do_not_go_together_are_refused(
    extra: list[str],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.setenv("LIPSTREAM_HOME", str(tmp_path / "home"))
    assert cli.main(["bench", *extra, "--results", str(tmp_path / "x.json")]) == 2
    assert "[invalid_request]" in capsys.readouterr().err
    assert not (tmp_path / "x.json").exists()


HALF_FRAME_S = 0.5 / FPS


def _misfit(coarse: np.ndarray, dense: np.ndarray, fine_fps: float, shift_s: float) -> float:
    """RMS of ``coarse`` (at ``FPS``, ends left out) less ``dense`` (at ``fine_fps``) read by
    np.interp at the coarse frames' times plus ``shift_s``."""
    times = np.arange(len(coarse))[2:-2] / FPS
    read = np.interp(times + shift_s, np.arange(len(dense)) / fine_fps, dense)
    return float(np.sqrt(np.mean((read - coarse[2:-2]) ** 2)))


def test_every_engine_times_its_25_fps_frames_as_its_fine_frames_with_no_half_frame_offset(
    trained_models: dict[str, Model],
) -> None:
    """bench --real synthesizes each prediction on the real clip's 25 fps frames, frame i at
    i / 25 s. Each engine's 25 fps aperture must be its 200 fps aperture read at those
    times: of the 200 fps aperture read at every shift from half a frame (20 ms) earlier
    to half a frame later, in 1 ms steps, the one nearest the 25 fps aperture is within a
    quarter of a frame of no shift, so neither frame rate is timed at frame centres and
    the other at frame starts. (An engine may smooth differently at 25 fps, ``hmm``'s
    trajectory is solved at the request's rate, so the misfit itself need not vanish.)"""
    phones = read_textgrid_phones(GRID / "bbaf2n.TextGrid")
    fine = 200.0
    shifts = np.linspace(-HALF_FRAME_S, HALF_FRAME_S, 41)
    for engine, model in trained_models.items():
        coarse = lip_aperture(model.synthesize(phones, fps=FPS, audio=None).frames, model.channels)
        dense = lip_aperture(model.synthesize(phones, fps=fine, audio=None).frames, model.channels)
        assert coarse is not None and dense is not None
        misfits = [_misfit(coarse, dense, fine, shift) for shift in shifts]
        best = float(shifts[int(np.argmin(misfits))])
        assert abs(best) <= 0.5 * HALF_FRAME_S, (engine, best)
        assert min(misfits) < 0.5 * max(misfits[0], misfits[-1]), engine
