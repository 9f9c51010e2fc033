import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lipstream.bench.hmm_closure_lag import CONVENTIONS, aperture_of, frame_states
from lipstream.bench.report import BLOCKS, Bench
from lipstream.engines.hmm import trajectory
from lipstream.errors import LipstreamError
from lipstream.evaluation import closure_centre


def test_each_convention_maps_trajectory_frames_to_hmm_frames() -> None:
    states = np.array([10, 11, 12])
    # f = 3 R: frame k sits at k / 3 HMM frames
    assert frame_states(states, 9, 1 / 3, "floor").tolist() == [10, 10, 10, 11, 11, 11, 12, 12, 12]
    assert frame_states(states, 9, 1 / 3, "nearest").tolist() == [
        10,
        10,
        11,
        11,
        11,
        12,
        12,
        12,
        12,
    ]
    assert frame_states(states, 9, 1 / 3, "ceil").tolist() == [10, 11, 11, 11, 12, 12, 12, 12, 12]
    # f = 50 Hz, R = 40 Hz: positions 0, 0.8, 1.6, 2.4, 3.2
    many = np.arange(6)
    assert frame_states(many, 5, 0.8, "floor").tolist() == [0, 0, 1, 2, 3]
    assert frame_states(many, 5, 0.8, "nearest").tolist() == [0, 1, 2, 2, 3]
    assert frame_states(many, 5, 0.8, "ceil").tolist() == [0, 1, 2, 3, 4]
    with pytest.raises(ValueError, match="unknown convention"):
        frame_states(states, 3, 1.0, "middle")


def test_holding_a_state_after_its_instant_delays_a_one_frame_closure() -> None:
    """Two 1-D states, open (pose 1) and shut (pose 0), pose variance tiny and velocity
    variance huge, so the trajectory follows the held state means. HMM frame 5 (at 125 ms,
    R = 40 Hz) is shut; solved at f = 120 Hz the closure is timed at its plateau's centre:
    held after the instant (floor) it is 8.3 ms late, at the nearest instant on time."""
    means = np.array([[1.0, 0.0], [0.0, 0.0]])
    covariances = np.array([np.diag([1e-6, 1e6])] * 2)
    terms = trajectory.dynamics(means, covariances, ratio=1 / 3)
    states = np.zeros(12, dtype=np.int64)
    states[5] = 1
    centres = {}
    for convention in CONVENTIONS:
        curve = trajectory.solve(terms, frame_states(states, 34, 1 / 3, convention))[:, 0]
        centres[convention] = closure_centre(curve) / 120.0
    assert centres["nearest"] == pytest.approx(0.125)
    assert centres["floor"] == pytest.approx(0.125 + 1 / 120)
    assert centres["ceil"] == pytest.approx(0.125 - 1 / 120)


def _lag(mean: float, count: int = 9) -> dict[str, Any]:
    return {"mean_ms": mean, "se_ms": 1.5, "count": count}


def _measured(offset: float, lag: float) -> dict[str, Any]:
    """One model's lags as ``hmm_closure_lag.measured`` stores them, its own (``floor``)
    closures ``lag`` ms late on the demo lines and 10 ms later on the real clips."""
    contexts = {
        "all": _lag(lag + 10.0),
        "after_silence": _lag(30.0, 3),
        "after_speech": _lag(15.0, 6),
    }
    return {
        "sample_offset": offset,
        "demo": {
            "lines": 3,
            "floor_max_abs_diff": 2e-8,
            "conventions": {
                name: {
                    "lag": _lag(lag - 7.0 * i),
                    "shift_from_floor": _lag(0.0 - 7.0 * i),
                    "rms": 0.06,
                    "by_context": {
                        "all": _lag(lag - 7.0 * i),
                        "after_silence": _lag(-4.0, 4),
                        "after_speech": _lag(1.0, 5),
                    },
                }
                for i, name in enumerate(CONVENTIONS)
            },
            "rungs": {"full": {"lag": _lag(lag), "rms": 0.0645}},
        },
        "real": {
            "clips": 2,
            "fps": 25.0,
            "conventions": {
                name: {"behind_character": contexts, "behind_real": contexts}
                for name in CONVENTIONS
            },
        },
    }


def test_the_block_renders_both_samplings_each_convention_rung_and_seed(tmp_path: Path) -> None:
    shift = {"offline": _lag(-12.0), "full": _lag(-11.0), "real_behind_character": _lag(-9.0)}
    centre = _measured(0.5, -4.0) | {"shift_from_instant": shift}
    doc = {
        "date": "2030-01-02T03:04:05+00:00",
        "corpus": {"name": "demo", "fps": 120.0},
        "model": "trained on the train split",
        "hmm_fps": 40.0,
        "seed": 0,
        "samplings": {"instant": _measured(0.0, 8.0), "centre": centre},
        "seeds": [
            {
                "seed": 1,
                "instant": {"rms": 0.061},
                "centre": {"rms": 0.062},
                "shift": {name: _lag(-2.0) for name in shift},
            }
        ],
        "seed_mean_shift": {name: _lag(-7.0, 2) for name in shift},
    }
    (tmp_path / "hmm_closure_lag.json").write_text(json.dumps(doc))
    rendered = BLOCKS["hmm-closure-lag"](Bench(tmp_path))
    assert "3 held-out lines at 120 fps and 2 real clips at 25 fps" in rendered
    assert (
        "| at j / R (the engine's default): `sample_offset` 0 | `nearest`: ⌊k R / f + ½⌋, the nearest instant "
        "| +1.0 ± 1.5 (n 9) | -7.0 ± 1.5 (n 9)" in rendered
    )
    assert (
        "| at (j + ½) / R: `sample_offset` 0.5 | `floor`: ⌊k R / f⌋, held over "
        "[j / R, (j + 1) / R) (the engine's) | -4.0 ± 1.5 (n 9) | +0.0 ± 1.5 (n 9) | 0.06000 "
        "| +6.0 ± 1.5 (n 9) |" in rendered
    )
    assert (
        "| at (j + ½) / R | real clips | +6.0 ± 1.5 (n 9) | +30.0 ± 1.5 (n 3) "
        "| +15.0 ± 1.5 (n 6) |" in rendered
    )
    assert (
        "| `full` | +8.0 ± 1.5 (n 9) | 0.06450 | -4.0 ± 1.5 (n 9) | 0.06450 | -11.0 ± 1.5 (n 9) |"
        in rendered
    )
    assert (
        "| demo held-out, `full` | -11.0 ± 1.5 (n 9) | -2.0 ± 1.5 (n 9) | -7.0 ± 1.5 (n 2) |"
        in rendered
    )
    assert (
        "| real clips, behind the character (offline) | -9.0 ± 1.5 (n 9) | -2.0 ± 1.5 (n 9) "
        "| -7.0 ± 1.5 (n 2) |" in rendered
    )
    assert "| seed 0 | 0.06000 | 0.06000 |" in rendered
    assert "| seed 1 | 0.06100 | 0.06200 |" in rendered
    assert "Not measured yet" in BLOCKS["hmm-closure-lag"](Bench(tmp_path / "empty"))


def test_a_rig_without_the_lip_aperture_is_a_coded_error() -> None:
    frames = np.array([[0.5, 0.25], [0.75, 0.5]])
    assert aperture_of(frames, ["jawOpen", "mouthClose"]).tolist() == [0.25, 0.25]
    with pytest.raises(LipstreamError, match="no lip aperture") as raised:
        aperture_of(frames, ["jawOpen", "mouthSmile"])
    assert raised.value.code == "invalid_model"
