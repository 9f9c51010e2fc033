"""Emitting frames in compiled calls: PCA values to channels, and the causal rung's frames.

Sketch: ``channel_frames`` maps PCA values to channel frames (values @ components + mean,
clipped to each channel's recorded range, as float32), with the BLAS product numpy's
``@`` uses, so its frames are numpy's. ``causal_frames`` makes a causal request's frames
in one call: output frame k is at t_k = k / fps; the track is sampled left-continuously
at min(t_k + lead, end of the input) (``track.evaluate_track``), and the critically
damped filter (``damped``) steps from its state to each t_k toward that sample, at each
PCA component's rate; a request's first frame starts the filter at rest on its sample.
It is the arithmetic of ``MotionTrack.evaluate``, ``DampedState.follow`` and
``channel_frames`` in one call instead of a dozen numpy calls, because a causal request
makes it on every streamed message and its few frames cost less than the calls' set-up;
``causal_call`` runs it inside the compiled call that also picks and places the spans.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..damped import follow_rates
from .track import evaluate_track


@njit(cache=True)
def channel_frames(
    values: np.ndarray, components: np.ndarray, mean: np.ndarray, low: np.ndarray,
    high: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """Channel frames (n, n_channels) float32 of PCA ``values`` (n, n_pc), each channel
    held inside [low, high]."""
    frames = np.dot(values, components)
    out = np.empty(frames.shape, dtype=np.float32)
    for row in range(frames.shape[0]):
        for column in range(frames.shape[1]):
            value = frames[row, column] + mean[column]
            out[row, column] = min(max(value, low[column]), high[column])
    return out


@njit(cache=True)
def causal_frames(
    first: int,
    stop: int,
    fps: float,
    lead_s: float,
    covered_until: float,
    x: np.ndarray,
    v: np.ndarray,
    t: float,
    at_rest: bool,
    omegas: np.ndarray,
    components: np.ndarray,
    mean: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    starts: np.ndarray,
    ends: np.ndarray,
    animes: np.ndarray,
    knot_offsets: np.ndarray,
    knot_targets: np.ndarray,
    knot_sources: np.ndarray,
    join_kinds: np.ndarray,
    left_examples: np.ndarray,
    right_examples: np.ndarray,
    anime_start: np.ndarray,
    anime_end: np.ndarray,
    utterance: np.ndarray,
    values: np.ndarray,
    offsets: np.ndarray,
    rate: float,
) -> np.ndarray:
    """Channel frames (``channel_frames``) of output frames first .. stop - 1; the filter's
    ``x`` and ``v`` (at time ``t``) advance to the last frame, or (``at_rest``) start at
    rest on frame ``first``'s sample. The track arguments are ``MotionTrack.arrays()``."""
    times = np.empty(stop - first)
    ahead = np.empty(stop - first)
    for row in range(stop - first):
        times[row] = (first + row) / fps
        ahead[row] = min(times[row] + lead_s, covered_until)
    targets = evaluate_track(
        ahead, starts, ends, animes, knot_offsets, knot_targets, knot_sources, join_kinds,
        left_examples, right_examples, anime_start, anime_end, utterance, values, offsets,
        rate, True,
    )  # fmt: skip
    out = np.empty_like(targets)
    done = 0
    if at_rest:
        x[:] = targets[0]
        v[:] = 0.0
        out[0] = x
        done = 1
    if len(times) > done:
        follow_rates(x, v, t, targets[done:], omegas, times[done:], out[done:])
    return channel_frames(out, components, mean, low, high)
