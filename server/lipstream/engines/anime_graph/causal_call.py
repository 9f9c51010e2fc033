"""A causal request's streamed call in one compiled call: pick, place and emit.

Sketch: ``causal_step`` does what the causal synthesizer's Python did per message, in
the same arithmetic. (1) ``greedy_tiles`` with one-phoneme tiles picks the anime of every
new query position (all in the view of the one before them); if a phoneme has no anime,
nothing is placed and the call returns the count it reached, for the caller to raise.
(2) Each pick is written into the motion track's buffers (``MotionTrack.reserve``): span,
anime, the linear warp onto its whole recording (two knots) and the join from the one
before, seamless when the recording continues, else forward (cut without blending); a
jump is a pick that the searched graph's successor does not continue. (3)
``causal_emit`` finds the frames that became final (t + lead within the decided spans,
every frame once finished) and makes them with ``emission.causal_frames``, the damped
filter's state advancing in place. A streamed call's few frames cost less than the ~40
numpy and interpreter steps this replaces. The kernels take the arrays in named groups:
the request's ``CausalClock`` and filter state, the track's buffers, the view's
``GreedySearch`` and the model's ``CausalEmission``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base import frame_count
from ..damped import FilterState
from .emission import CausalClock, CausalEmission, causal_frames
from .suffix_search import GreedySearch, greedy_tiles
from .track import CUT_CODE, FORWARD_CODE, SEAMLESS_CODE, TrackBuffers

_frame_count = njit(cache=True)(frame_count)  # the same function, callable from the kernels


@njit(cache=True)
def causal_emit(
    first: int,
    finished: bool,
    decided: int,
    total: int,
    bounds: np.ndarray,
    clock: CausalClock,
    state: FilterState,
    track: TrackBuffers,
    count: int,
    knots: int,
    emission: CausalEmission,
) -> tuple[int, np.ndarray]:
    """(stop, channel frames first .. stop - 1 (n, n_channels) float32) of a request whose
    ``total`` spans ((n, 2) ``bounds``, start and end s) are decided up to ``decided``:
    frames whose time plus the lead lies within the decided spans, all of them once
    ``finished`` with every span decided. The filter ``state`` is at rest before frame 0
    and at frame ``first`` - 1 otherwise; ``track`` holds ``count`` placements of
    ``knots`` knots."""
    fps, lead_s = clock.fps, clock.lead_s
    covered_until = bounds[total - 1, 1] if total else 0.0
    frames_total = _frame_count(covered_until, fps) if total else 0
    if finished and decided == total:
        stop = frames_total
    elif decided and bounds[decided - 1, 1] >= lead_s:
        stop = min(frames_total, _frame_count(bounds[decided - 1, 1] - lead_s, fps))
    else:
        stop = first
    if stop <= first:
        return first, np.zeros((0, emission.channels.components.shape[1]), dtype=np.float32)
    frames = causal_frames(first, stop, clock, covered_until, state, emission, track, count, knots)
    return stop, frames


@njit(cache=True)
def causal_step(
    query: np.ndarray,
    bounds: np.ndarray,
    placed: int,
    total: int,
    first: int,
    finished: bool,
    clock: CausalClock,
    state: FilterState,
    track: TrackBuffers,
    knots: int,
    search: GreedySearch,
    emission: CausalEmission,
) -> tuple[np.ndarray, int, int, np.ndarray]:
    """(anime picked per new position (k,), jumps among them, emission stop, frames) for
    query positions ``placed`` .. ``total`` - 1 (``query`` labels, ``bounds`` (n, 2)
    spans), after the anime of the track's last placement, the track holding ``placed``
    placements and ``knots`` knots. When k < ``total`` - ``placed`` (a phoneme with no
    anime) nothing is placed or emitted: stop is ``first``, frames empty."""
    previous = track.animes[placed - 1] if placed else -1
    chosen, _, _ = greedy_tiles(query[placed:total], 1, previous, previous, False, search)
    if len(chosen) < total - placed:
        empty = np.zeros((0, emission.channels.components.shape[1]), dtype=np.float32)
        return chosen, 0, first, empty
    successor = search.tables.successor
    pose_successor = search.ranking.poses.successor
    anime_start, anime_end = emission.motion.start, emission.motion.end
    count = placed
    jumps = 0
    for anime in chosen:
        if count:
            jumps += successor[previous] != anime
            if pose_successor[previous] == anime:
                kind = SEAMLESS_CODE
            else:
                kind = FORWARD_CODE if clock.blend else CUT_CODE
            track.join_kinds[count - 1] = kind
            track.left_examples[count - 1] = -1
            track.right_examples[count - 1] = -1
        track.starts[count] = bounds[count, 0]
        track.ends[count] = bounds[count, 1]
        track.animes[count] = anime
        track.knot_targets[knots] = bounds[count, 0]
        track.knot_targets[knots + 1] = bounds[count, 1]
        track.knot_sources[knots] = anime_start[anime]
        track.knot_sources[knots + 1] = anime_end[anime]
        knots += 2
        count += 1
        track.knot_offsets[count] = knots
        previous = anime
    stop, frames = causal_emit(
        first, finished, total, total, bounds, clock, state, track, count, knots, emission
    )
    return chosen, jumps, stop, frames
