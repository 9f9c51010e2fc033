"""The kernels every streamed call of an anime-graph request runs, shared by a model's
requests through one ``DirectCall`` each (``StreamCalls``).

Sketch: the causal rungs' whole call (``causal_call``), GreedyMatching's tiles
(``suffix_search``), the track sampled on the model's frame grid, and smoothed samples
interpolated onto the output frame times and mapped to channels; the argument types at
each call site are fixed by the model's arrays and the requests' buffers.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...numerics.direct_call import DirectCall
from ...numerics.resample import blend_into, bracket
from .causal_call import causal_emit, causal_step
from .emission import ChannelMap, channel_frames
from .suffix_search import greedy_tiles
from .track import AnimeMotion, TrackBuffers, evaluate_track

SNAP = 1e-9
"""A position within this of a model-grid sample is taken as that sample."""


@njit(cache=True)
def _grid_samples(
    first: int,
    stop: int,
    fps_model: float,
    until: float,
    track: TrackBuffers,
    count: int,
    knots: int,
    motion: AnimeMotion,
) -> np.ndarray:
    """The first ``count`` placements (``knots`` knots) of ``track`` at model-grid samples
    ``first`` .. ``stop`` - 1, sample k at k / ``fps_model`` s but no later than ``until``:
    (stop - first, n_pc)."""
    times = np.empty(stop - first)
    for row in range(stop - first):
        times[row] = min((first + row) / fps_model, until)
    return evaluate_track(times, track, count, knots, motion, False)


@njit(cache=True)
def _interpolate(
    first: int, stop: int, ratio: float, curve: np.ndarray, offset: int, count: int
) -> np.ndarray:
    """Output frames first .. stop - 1 interpolated linearly between the smoothed samples
    (``curve`` holds samples offset .. offset + len - 1 of ``count``) at frame * ``ratio``,
    a position within ``SNAP`` of a sample taken as that sample."""
    values = np.empty((stop - first, curve.shape[1]))
    for row in range(stop - first):
        position = (first + row) * ratio
        snapped = np.round(position)
        if abs(position - snapped) < SNAP:
            position = snapped
        low, high, fraction = bracket(position, count - 1)
        blend_into(values[row], curve, low - offset, high - offset, fraction)
    return values


@njit(cache=True)
def _interpolated_frames(
    first: int,
    stop: int,
    ratio: float,
    curve: np.ndarray,
    offset: int,
    count: int,
    channels: ChannelMap,
) -> np.ndarray:
    """``_interpolate``'s values as channel frames (``emission.channel_frames``), in one
    call."""
    values = _interpolate(first, stop, ratio, curve, offset, count)
    return channel_frames(values, channels)


class StreamCalls:
    """The kernels a model's synthesizers call on every streamed message, each through one
    ``DirectCall`` that they share: the argument types at each call site are fixed by the
    model's arrays and the requests' buffers, so the first request binds them and the
    others skip the binding (a few hundred µs of typing named groups in Python)."""

    def __init__(self) -> None:
        self.causal_step = DirectCall(causal_step)
        self.causal_emit = DirectCall(causal_emit)
        self.greedy_tiles = DirectCall(greedy_tiles)
        self.grid_samples = DirectCall(_grid_samples)
        self.interpolated_frames = DirectCall(_interpolated_frames)
