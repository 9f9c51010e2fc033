"""The critically damped filter against its closed-form step response, computed by hand."""

from __future__ import annotations

import math

import numpy as np

from lipstream.engines.damped import HALF_POWER_RATIO, DampedState, filter_raw, omega_for_cutoff


def _expected(x0: float, v0: float, target: float, omega: float, t: float) -> float:
    return target + (x0 - target + (v0 + omega * (x0 - target)) * t) * math.exp(-omega * t)


def test_one_step_is_the_closed_form_step_response() -> None:
    # x0 = 1, v0 = 0, target 0, omega 10, t = 0.1: (1 + 1) e^-1 = 0.7357588823
    state = DampedState(np.array([1.0]), np.array([0.0]), 0.0)
    state.step(np.array([0.0]), np.array([10.0]), 0.1)
    assert math.isclose(state.x[0], 2.0 * math.exp(-1.0), rel_tol=1e-12)
    assert math.isclose(state.x[0], 0.7357588823428847, rel_tol=1e-12)
    # v(t) = (v0 - omega (v0 + omega e0) t) e^-wt = -10 e^-1
    assert math.isclose(state.v[0], -10.0 * math.exp(-1.0), rel_tol=1e-12)


def test_many_small_steps_follow_the_same_curve_with_initial_velocity() -> None:
    x0, v0, target, omega = np.array([0.2, -1.0]), np.array([3.0, 0.5]), np.array([1.0, 2.0]), 7.0
    state = DampedState(x0.copy(), v0.copy(), 0.0)
    dts = np.full(40, 0.01)
    values = state.run(
        np.tile(target, (40, 1)), np.full((40, 2), omega), dts, np.ones(40, dtype=bool)
    )
    for row, t in enumerate(np.arange(1, 41) * 0.01):
        for column in range(2):
            expected = _expected(x0[column], v0[column], target[column], omega, t)
            assert math.isclose(values[row, column], expected, rel_tol=1e-9, abs_tol=1e-12)


def test_recording_keeps_only_the_marked_pieces() -> None:
    state = DampedState.at_rest(np.array([0.0]))
    values = state.run(
        np.ones((3, 1)), np.full((3, 1), 5.0), np.array([0.1, 0.1, 0.1]), np.array([0, 1, 0], bool)
    )
    # from rest at 0 toward 1 for 0.2 s: 1 - (1 + 5 * 0.2) e^-1
    assert values.shape == (1, 1)
    assert math.isclose(values[0, 0], 1.0 - 2.0 * math.exp(-1.0), rel_tol=1e-12)


def test_the_cutoff_is_where_half_the_power_passes() -> None:
    omega = float(omega_for_cutoff(4.0))
    frequency = 2 * math.pi * 4.0
    gain = 1.0 / (1.0 + (frequency / omega) ** 2)
    assert math.isclose(gain**2, 0.5, rel_tol=1e-12)
    assert math.isclose(HALF_POWER_RATIO, 0.6435942529055826, rel_tol=1e-12)


def test_filter_raw_steps_each_frame_toward_its_raw_value_and_carries_its_state() -> None:
    generator = np.random.default_rng(3)
    raw = generator.normal(size=(30, 3))
    omegas = generator.uniform(5.0, 60.0, size=30)
    times = np.arange(30) / 60.0
    # by hand: at rest on raw[0] at frame 0, then one closed-form step per frame
    x, v = raw[0].copy(), np.zeros(3)
    expected = [x.copy()]
    for row in range(1, 30):
        dt = times[row] - times[row - 1]
        for column in range(3):
            error = x[column] - raw[row, column]
            pull = v[column] + omegas[row] * error
            decay = math.exp(-omegas[row] * dt)
            x[column] = raw[row, column] + (error + pull * dt) * decay
            v[column] = (v[column] - omegas[row] * pull * dt) * decay
        expected.append(x.copy())
    state, first = filter_raw(None, raw[:11], omegas[:11], times[:11])
    state, second = filter_raw(state, raw[11:], omegas[11:], times[11:])
    np.testing.assert_allclose(np.concatenate([first, second]), expected, rtol=0, atol=1e-12)
    assert state.t == times[-1]


def test_follow_equals_running_the_pieces_between_the_times() -> None:
    rng = np.random.default_rng(4)
    for _ in range(5):
        x0, v0 = rng.normal(size=4), rng.normal(size=4)
        times = 0.3 + np.cumsum(rng.uniform(0.001, 0.05, size=12))
        targets, omega = rng.normal(size=(12, 4)), rng.uniform(1.0, 60.0, size=4)
        followed = DampedState(x0.copy(), v0.copy(), 0.3)
        values = np.empty((12, 4))
        followed.follow(targets, omega, times, values)
        ran = DampedState(x0.copy(), v0.copy(), 0.3)
        steps = np.diff(np.concatenate(([0.3], times)))
        expected = ran.run(targets, np.tile(omega, (12, 1)), steps, np.ones(12, dtype=bool))
        assert np.array_equal(values, expected)
        assert np.array_equal(followed.x, ran.x) and np.array_equal(followed.v, ran.v)
        assert followed.t == times[-1]
