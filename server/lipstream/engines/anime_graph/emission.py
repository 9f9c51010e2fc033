"""Emitting frames in compiled calls: PCA values to channels, and the causal rung's frames.

Sketch: ``channel_frames`` maps PCA values to channel frames (values @ components + mean,
clipped to each channel's recorded range, as float32: ``numerics.basis.basis_frames``),
with the BLAS product numpy's ``@`` uses, so its frames are numpy's. ``causal_frames``
makes a causal request's frames in one call: output frame k is at t_k = k / fps; the track
is sampled left-continuously at min(t_k + lead, end of the input)
(``track.evaluate_track``), and the critically damped filter (``damped``) steps from its
state to each t_k toward that sample, at each PCA component's rate; a request's first frame
starts the filter at rest on its sample. It is the arithmetic of ``MotionTrack.evaluate``,
``DampedState.follow`` and ``channel_frames`` in one call instead of a dozen numpy calls,
because a causal request makes it on every streamed message and its few frames cost less
than the calls' set-up; ``causal_call`` runs it inside the compiled call that also picks
and places the spans.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ...numerics.basis import BLAS, basis_frames
from ..damped import FilterState, follow_rates
from .track import AnimeMotion, TrackBuffers, evaluate_track


class ChannelMap(NamedTuple):
    """PCA values to channels: ``components`` (n_pc, n_channels), ``mean`` (n_channels,),
    each channel held inside [``low``, ``high``] (n_channels,), the range the recordings
    span; all float64, C-contiguous."""

    components: np.ndarray
    mean: np.ndarray
    low: np.ndarray
    high: np.ndarray


class CausalEmission(NamedTuple):
    """What a causal request's frames are made with, per model: the filter's rate per PCA
    component ``omegas`` (n_pc,) float64, the ``channels`` map and the animes' ``motion``."""

    omegas: np.ndarray
    channels: ChannelMap
    motion: AnimeMotion


class CausalClock(NamedTuple):
    """A causal request's output rate ``fps``, its lead ``lead_s`` (s) and whether its joins
    blend (``blend``; else they cut)."""

    fps: float
    lead_s: float
    blend: bool


@njit(cache=True)
def channel_frames(values: np.ndarray, channels: ChannelMap) -> np.ndarray:
    """Channel frames (n, n_channels) float32 of PCA ``values`` (n, n_pc), each channel
    held inside [low, high] (``numerics.basis.basis_frames``, numpy's BLAS product)."""
    return basis_frames(
        values, channels.components, channels.mean, channels.low, channels.high, BLAS
    )


@njit(cache=True)
def causal_frames(
    first: int,
    stop: int,
    clock: CausalClock,
    covered_until: float,
    state: FilterState,
    emission: CausalEmission,
    track: TrackBuffers,
    count: int,
    knots: int,
) -> np.ndarray:
    """Channel frames (``channel_frames``) of output frames first .. stop - 1 on the first
    ``count`` placements (``knots`` knots) of ``track``; the filter ``state``, at frame
    ``first`` - 1, advances to the last frame, or at frame 0 starts at rest on its sample."""
    fps, lead_s = clock.fps, clock.lead_s
    times = np.empty(stop - first)
    ahead = np.empty(stop - first)
    for row in range(stop - first):
        times[row] = (first + row) / fps
        ahead[row] = min(times[row] + lead_s, covered_until)
    targets = evaluate_track(ahead, track, count, knots, emission.motion, True)
    x, v = state.x, state.v
    out = np.empty_like(targets)
    done = 0
    if first == 0:
        x[:] = targets[0]
        v[:] = 0.0
        out[0] = x
        done = 1
    if len(times) > done:
        t = 0.0 if first == 0 else (first - 1) / fps
        follow_rates(x, v, t, targets[done:], emission.omegas, times[done:], out[done:])
    return channel_frames(out, emission.channels)
