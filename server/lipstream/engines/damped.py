"""A critically damped second-order filter, stepped in closed form: the causal rungs' smoother.

Method: a value x with velocity v is pulled toward a target u by
x'' = -2 ω x' - ω² (x - u). Over a step of length dt with u held constant,
the exact solution is, with e0 = x0 - u and c = v0 + ω e0,

    x(dt) = u + (e0 + c dt) e^{-ω dt},    v(dt) = (v0 - ω c dt) e^{-ω dt},

so stepping is stable for any dt and ω (no overshoot, no growth), and the
result does not depend on how a stretch of time is cut into steps with the
same targets. ω sets the speed: a step in u is 1 - (1 + ω t) e^{-ω t}
complete after t, and the filter's gain is 1 / (1 + (f / f0)²) with
f0 = ω / 2π, so its -3 dB frequency is ``HALF_POWER_RATIO`` f0.

The compiled steps are public for the kernels that inline them: ``pull_toward``
(one value), ``step_toward`` (every column, one target), ``follow_frame_rates``
(a raw curve, one rate per frame) and ``follow_rates`` (one rate per column).
``run`` steps a sequence of (target, ω, dt) pieces and records the value
after the pieces marked as frames; both causal engines build those pieces
from what the input has made final. ``filter_raw`` runs the filter over a raw curve
sampled at frame times, carrying its state from call to call.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

HALF_POWER_RATIO = math.sqrt(math.sqrt(2.0) - 1.0)
"""The -3 dB frequency of the filter over ω / 2π."""


def omega_for_cutoff(cutoff_hz: np.ndarray | float) -> np.ndarray:
    """The ω (rad/s) whose filter passes half the power at ``cutoff_hz``."""
    return np.asarray(2.0 * math.pi * np.asarray(cutoff_hz, dtype=np.float64) / HALF_POWER_RATIO)


@njit(cache=True)
def pull_toward(x: float, v: float, target: float, w: float, dt: float) -> tuple[float, float]:
    """x and v after ``dt`` s toward ``target`` at rate ``w``."""
    error = x - target
    pull = v + w * error
    decay = math.exp(-w * dt)
    return target + (error + pull * dt) * decay, (v - w * pull * dt) * decay


@njit(cache=True)
def step_toward(
    x: np.ndarray, v: np.ndarray, target: np.ndarray, omega: np.ndarray, dt: float
) -> None:
    """Every column of ``x`` and ``v`` (n,) in place after ``dt`` s toward ``target`` (n,)
    at rates ``omega`` (n,)."""
    for column in range(len(x)):
        x[column], v[column] = pull_toward(x[column], v[column], target[column], omega[column], dt)


@njit(cache=True)
def follow_frame_rates(
    x: np.ndarray,
    v: np.ndarray,
    t: float,
    raw: np.ndarray,
    omegas: np.ndarray,
    times: np.ndarray,
    out: np.ndarray,
) -> None:
    """Step from time ``t`` to each of ``times`` toward that frame's ``raw`` row at its rate
    ``omegas`` (every column), recording the value in ``out``."""
    for row in range(len(times)):
        dt = times[row] - (t if row == 0 else times[row - 1])
        for column in range(len(x)):
            x[column], v[column] = pull_toward(
                x[column], v[column], raw[row, column], omegas[row], dt
            )
        out[row] = x


@njit(cache=True)
def _run(
    x: np.ndarray,
    v: np.ndarray,
    targets: np.ndarray,
    omegas: np.ndarray,
    dts: np.ndarray,
    record: np.ndarray,
    out: np.ndarray,
) -> None:
    row = 0
    for piece in range(len(dts)):
        step_toward(x, v, targets[piece], omegas[piece], dts[piece])
        if record[piece]:
            out[row] = x
            row += 1


@njit(cache=True)
def follow_rates(
    x: np.ndarray,
    v: np.ndarray,
    t: float,
    targets: np.ndarray,
    omega: np.ndarray,
    times: np.ndarray,
    out: np.ndarray,
) -> None:
    """Step from time ``t`` to each of ``times`` (m,) toward that time's row of ``targets``
    (m, n) at rates ``omega`` (n,), recording the value in ``out`` (m, n)."""
    previous = t
    for row in range(len(times)):
        step_toward(x, v, targets[row], omega, times[row] - previous)
        previous = times[row]
        out[row] = x


class FilterState(NamedTuple):
    """A compiled caller's filter: value ``x`` and velocity ``v`` (n,) float64, which its
    kernels step in place; the caller keeps the time they are at."""

    x: np.ndarray
    v: np.ndarray


@dataclass
class DampedState:
    """The filter's value ``x`` and velocity ``v`` (each (n,)) at time ``t`` (s)."""

    x: np.ndarray
    v: np.ndarray
    t: float

    @classmethod
    def at_rest(cls, value: np.ndarray, t: float = 0.0) -> DampedState:
        start = np.array(value, dtype=np.float64)
        return cls(start, np.zeros_like(start), t)

    def step(self, target: np.ndarray, omega: np.ndarray, dt: float) -> None:
        """Advance by ``dt`` seconds toward ``target`` held constant, at rates ``omega``."""
        step_toward(
            self.x,
            self.v,
            np.asarray(target, dtype=np.float64),
            np.asarray(omega, dtype=np.float64),
            float(dt),
        )
        self.t += dt

    def run(
        self, targets: np.ndarray, omegas: np.ndarray, dts: np.ndarray, record: np.ndarray
    ) -> np.ndarray:
        """Step through pieces (targets (m, n), omegas (m, n), dts (m,)); the values after the
        pieces where ``record`` is true, (count, n) float64. The caller sets ``t`` to the
        end of the last piece (exactly, not as a sum of steps)."""
        out = np.empty((int(np.count_nonzero(record)), len(self.x)))
        _run(
            self.x,
            self.v,
            np.ascontiguousarray(targets, dtype=np.float64),
            np.ascontiguousarray(omegas, dtype=np.float64),
            np.ascontiguousarray(dts, dtype=np.float64),
            np.asarray(record, dtype=np.bool_),
            out,
        )
        return out

    def follow(
        self, targets: np.ndarray, omega: np.ndarray, times: np.ndarray, out: np.ndarray
    ) -> None:
        """Step from ``t`` to each of ``times`` (m,) (ascending, after ``t``) toward that
        time's row of ``targets`` (m, n) at rates ``omega`` (n,), writing the value there
        into ``out`` (m, n); ``t`` becomes the last time. All float64 and contiguous: the
        per-frame loop of a causal rung, one compiled call."""
        follow_rates(self.x, self.v, self.t, targets, omega, times, out)
        self.t = float(times[-1])


def filter_raw(
    state: DampedState | None, raw: np.ndarray, omegas: np.ndarray, times: np.ndarray
) -> tuple[DampedState, np.ndarray]:
    """The filter following ``raw`` (m, components) at rates ``omegas`` (m,) over frame
    ``times`` (m,); ``state`` is the filter at the frame before (None: ``times`` starts at
    frame 0, where the filter rests on raw[0]). The state after and the values."""
    values = np.empty((len(times), raw.shape[1]))
    first = 0
    if state is None:
        state = DampedState.at_rest(raw[0], float(times[0]))
        values[0], first = state.x, 1
    if len(times) > first:
        follow_frame_rates(
            state.x,
            state.v,
            state.t,
            np.ascontiguousarray(raw[first:], dtype=np.float64),
            np.ascontiguousarray(omegas[first:], dtype=np.float64),
            np.ascontiguousarray(times[first:], dtype=np.float64),
            values[first:],
        )
        state.t = float(times[-1])
    return state, values
