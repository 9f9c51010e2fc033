"""Compiled per-call steps of ``synthesizer`` (numba): emissions, state lookups, recursion.

Sketch: a streamed call decodes a few HMM frames and solves a few trajectory
frames; done as numpy expressions, each step costs more in array set-up than
in arithmetic, and rebuilding arrays from the request's growing lists costs
O(length so far) per call. The synthesizer therefore keeps its spans, states
and trajectory in growing buffers (``engines.growable``) and these kernels
read and write them in place:

- ``decode``: the emission log-likelihoods of HMM frames ``first .. stop − 1``
  (``emissions``: the phoneme and emotion log-probabilities, each frame finding
  its span by bisection over the span starts, the span with start < j / R ≤ end,
  plus the weighted vocal log-densities computed by the caller), decoded by the
  request's ``FixedLagViterbi`` in the same compiled call;
- ``solve_block``: a block of the trajectory (``trajectory.solve``) written into
  the trajectory buffer, the states of its frames (``frame_states``: HMM frame
  ⌊k R / f⌋, the last committed one past the end) looked up in the same call;
- ``recurse``: the frame-at-a-time solve y_t = G_cur⁻¹ (r_cur − G_cross y_{t−1})
  written into the trajectory buffer;
- ``output_frames``: output frames ``first .. stop − 1`` (trajectory frame
  ⌊i f / fps⌋ back in channel space by ``numerics.basis.basis_frames``, the BLAS
  product of ``MotionBasis.reconstruct``), up to the first not yet solved.

Every value is computed by the same floating-point operations as the numpy
expressions they replace (the same sums in the same order, the same BLAS
products, the same compiled block solve), so the frames are the same to the bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ...numerics.banded import SOLVED, solve_block_tridiagonal_into
from ...numerics.basis import BLAS, basis_frames
from ...numerics.trellis import ViterbiState, advance
from .trajectory import Blocks, assemble

EPS = 1e-9
"""Tolerance of the frame-time comparisons (``synthesizer``)."""


@njit(cache=True)
def _span_of(spans: np.ndarray, count: int, time: float) -> int:
    """The span with start < time ≤ end among the first ``count`` (clipped to 0 .. count − 1):
    one less than the number of starts below time − EPS."""
    key = time - EPS
    low, high = 0, count
    while low < high:
        middle = (low + high) >> 1
        if spans[middle, 0] < key:
            low = middle + 1
        else:
            high = middle
    return min(max(low - 1, 0), count - 1)


@njit(cache=True)
def emissions(
    spans: np.ndarray,
    count: int,
    first: int,
    hmm_fps: float,
    categories: np.ndarray,
    mood: int,
    audio_terms: np.ndarray,
    heard_from: int,
    out: np.ndarray,
) -> None:
    """out[j − first] = the log-probability of HMM frame j's phoneme plus its emotion's (rows
    of ``categories``: phonemes, then emotions; ``spans`` rows: start, phoneme row, emotion
    row), or with no spans (``count`` 0) of the emotion row ``mood`` alone; plus
    audio_terms[j − heard_from] for the frames it covers."""
    states = out.shape[1]
    for offset in range(out.shape[0]):
        row = out[offset]
        if count == 0:
            emotion = categories[mood]
            for state in range(states):
                row[state] = 0.0 + emotion[state]
        else:
            span = _span_of(spans, count, (first + offset) / hmm_fps)
            phoneme, emotion = categories[int(spans[span, 1])], categories[int(spans[span, 2])]
            for state in range(states):
                row[state] = (0.0 + phoneme[state]) + emotion[state]
        heard = first + offset - heard_from
        if 0 <= heard < audio_terms.shape[0]:
            for state in range(states):
                row[state] += audio_terms[heard, state]


@njit(cache=True)
def decode(
    spans: np.ndarray,
    count: int,
    first: int,
    stop: int,
    hmm_fps: float,
    categories: np.ndarray,
    mood: int,
    audio_terms: np.ndarray,
    heard_from: int,
    decoder: ViterbiState,
    committed: np.ndarray,
    at: int,
) -> int:
    """``emissions`` of HMM frames first .. stop − 1 pushed through a
    ``numerics.trellis.FixedLagViterbi`` (``decoder``: what its ``reserve`` returned); the
    states committed go to committed[at:], and their count is returned."""
    log_emission = np.empty((stop - first, decoder.log_start.shape[0]))
    emissions(spans, count, first, hmm_fps, categories, mood, audio_terms, heard_from, log_emission)
    return advance(decoder, log_emission, committed, at)


@njit(cache=True)
def _hmm_frame(frame: int, ratio: float, committed: int) -> int:
    return min(int(math.floor(float(frame) * ratio + EPS)), committed - 1)


@njit(cache=True)
def frame_states(
    states: np.ndarray, committed: int, ratio: float, first: int, stop: int
) -> np.ndarray:
    """The state of each trajectory frame first .. stop − 1 (``ratio`` = R / f) among the
    ``committed`` states."""
    out = np.empty(stop - first, dtype=np.int64)
    for frame in range(first, stop):
        out[frame - first] = states[_hmm_frame(frame, ratio, committed)]
    return out


@njit(cache=True)
def solve_block(
    states: np.ndarray,
    committed: int,
    ratio: float,
    curve: np.ndarray,
    first: int,
    start: int,
    stop: int,
    end: int,
    blocks: Blocks,
) -> int:
    """curve[start .. stop − 1] from Eq. 6 over frames first .. end − 1 with frames
    first .. start − 1 pinned to the curve, as ``trajectory.solve``; returns the solve's
    code (``numerics.banded.solve_block_tridiagonal_into``)."""
    solved_states = frame_states(states, committed, ratio, first, end)
    diagonal, below, rhs = assemble(solved_states, curve[first:start], blocks)
    solution = np.empty(rhs.shape)
    code = solve_block_tridiagonal_into(diagonal, below, rhs, solution)
    if code == SOLVED:
        curve[start:stop] = solution[start - first : stop - first]
    return code


@njit(cache=True)
def recurse(
    states: np.ndarray,
    committed: int,
    ratio: float,
    curve: np.ndarray,
    start: int,
    stop: int,
    inverse: np.ndarray,
    cross: np.ndarray,
    rhs: np.ndarray,
    mean: np.ndarray,
) -> None:
    """curve[start .. stop − 1] a frame at a time from curve[start − 1] (frame 0: its
    state's pose mean), as ``trajectory.recurse``."""
    for t in range(start, stop):
        state = states[_hmm_frame(t, ratio, committed)]
        if t == 0:
            curve[0] = mean[state]
        else:
            curve[t] = inverse[state] @ (rhs[state] - cross[state] @ curve[t - 1])


@njit(cache=True)
def output_frames(
    curve: np.ndarray,
    solved: int,
    first: int,
    stop: int,
    step: float,
    components: np.ndarray,
    mean: np.ndarray,
) -> np.ndarray:
    """Output frames first .. stop − 1 as float32 channel frames (``MotionBasis.reconstruct``
    of trajectory row ⌊i · step + EPS⌋, ``step`` = f / fps), ending before the first whose row
    is past the ``solved`` ones."""
    count = 0
    for frame in range(first, stop):
        if int(math.floor(float(frame) * step + EPS)) >= solved:
            break
        count += 1
    if count == 0:
        return np.zeros((0, components.shape[1]), dtype=np.float32)
    rows = np.empty((count, curve.shape[1]))
    for offset in range(count):
        rows[offset] = curve[int(math.floor(float(first + offset) * step + EPS))]
    unbounded = np.empty(0)
    return basis_frames(rows, components, mean, unbounded, unbounded, BLAS)
