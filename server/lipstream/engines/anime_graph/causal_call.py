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
numpy and interpreter steps this replaces.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base import frame_count
from .emission import causal_frames
from .suffix_search import greedy_tiles
from .track import CUT_CODE, FORWARD_CODE, SEAMLESS_CODE

_frame_count = njit(cache=True)(frame_count)  # the same function, callable from the kernels


@njit(cache=True)
def causal_emit(
    first: int,
    finished: bool,
    decided: int,
    total: int,
    bounds: np.ndarray,
    fps: float,
    lead_s: float,
    x: np.ndarray,
    v: np.ndarray,
    count: int,
    knots: int,
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
) -> tuple[int, np.ndarray]:
    """(stop, channel frames first .. stop - 1 (n, n_channels) float32) of a request whose
    ``total`` spans ((n, 2) ``bounds``, start and end s) are decided up to ``decided``:
    frames whose time plus ``lead_s`` lies within the decided spans, all of them once
    ``finished`` with every span decided. The filter (``x``, ``v``) is at rest before
    frame 0 and at frame ``first`` - 1 otherwise; the track is ``count`` placements of
    ``knots`` knots in ``MotionTrack.reserve``'s buffers."""
    covered_until = bounds[total - 1, 1] if total else 0.0
    frames_total = _frame_count(covered_until, fps) if total else 0
    if finished and decided == total:
        stop = frames_total
    elif decided and bounds[decided - 1, 1] >= lead_s:
        stop = min(frames_total, _frame_count(bounds[decided - 1, 1] - lead_s, fps))
    else:
        stop = first
    if stop <= first:
        return first, np.zeros((0, components.shape[1]), dtype=np.float32)
    joins = max(count - 1, 0)
    frames = causal_frames(
        first, stop, fps, lead_s, covered_until, x, v, 0.0 if first == 0 else (first - 1) / fps,
        first == 0, omegas, components, mean, low, high, starts[:count], ends[:count],
        animes[:count], knot_offsets[: count + 1], knot_targets[:knots], knot_sources[:knots],
        join_kinds[:joins], left_examples[:joins], right_examples[:joins], anime_start,
        anime_end, utterance, values, offsets, rate,
    )  # fmt: skip
    return stop, frames


@njit(cache=True)
def causal_step(
    query: np.ndarray,
    placed: int,
    total: int,
    bounds: np.ndarray,
    previous: int,
    blend: bool,
    first: int,
    finished: bool,
    fps: float,
    lead_s: float,
    x: np.ndarray,
    v: np.ndarray,
    count: int,
    knots: int,
    starts: np.ndarray,
    ends: np.ndarray,
    animes: np.ndarray,
    knot_offsets: np.ndarray,
    knot_targets: np.ndarray,
    knot_sources: np.ndarray,
    join_kinds: np.ndarray,
    left_examples: np.ndarray,
    right_examples: np.ndarray,
    limit: int,
    transitions: np.ndarray,
    index_low: np.ndarray,
    index_high: np.ndarray,
    index_ends: np.ndarray,
    text_anime: np.ndarray,
    single_offsets: np.ndarray,
    single_starts: np.ndarray,
    labels: np.ndarray,
    successor: np.ndarray,
    use_audio: bool,
    query_summaries: np.ndarray,
    summaries: np.ndarray,
    last: np.ndarray,
    pose_first: np.ndarray,
    pose_successor: np.ndarray,
    omegas: np.ndarray,
    components: np.ndarray,
    mean: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    anime_start: np.ndarray,
    anime_end: np.ndarray,
    utterance: np.ndarray,
    values: np.ndarray,
    offsets: np.ndarray,
    rate: float,
) -> tuple[np.ndarray, int, int, np.ndarray]:
    """(anime picked per new position (k,), jumps among them, emission stop, frames) for
    query positions ``placed`` .. ``total`` - 1 (``query`` labels, ``bounds`` (n, 2)
    spans), after anime ``previous`` (-1: none), the track holding ``count`` == ``placed``
    placements and ``knots`` knots. The
    arguments after ``right_examples`` are ``SuffixMatcher.kernel_arguments`` then the
    model's emission arrays (``causal_emit``). When k < ``total`` - ``placed`` (a phoneme
    with no anime) nothing is placed or emitted: stop is ``first``, frames empty."""
    chosen, _, _ = greedy_tiles(
        query[placed:total], 1, previous, previous, False, limit, transitions, index_low,
        index_high, index_ends, text_anime, single_offsets, single_starts, labels, successor,
        use_audio, query_summaries, summaries, last, pose_first, pose_successor,
    )  # fmt: skip
    if len(chosen) < total - placed:
        return chosen, 0, first, np.zeros((0, components.shape[1]), dtype=np.float32)
    jumps = 0
    for anime in chosen:
        if count:
            jumps += successor[previous] != anime
            if pose_successor[previous] == anime:
                kind = SEAMLESS_CODE
            else:
                kind = FORWARD_CODE if blend else CUT_CODE
            join_kinds[count - 1] = kind
            left_examples[count - 1] = -1
            right_examples[count - 1] = -1
        starts[count] = bounds[count, 0]
        ends[count] = bounds[count, 1]
        animes[count] = anime
        knot_targets[knots] = bounds[count, 0]
        knot_targets[knots + 1] = bounds[count, 1]
        knot_sources[knots] = anime_start[anime]
        knot_sources[knots + 1] = anime_end[anime]
        knots += 2
        count += 1
        knot_offsets[count] = knots
        previous = anime
    stop, frames = causal_emit(
        first, finished, total, total, bounds, fps, lead_s, x, v, count, knots, omegas,
        components, mean, low, high, starts, ends, animes, knot_offsets, knot_targets,
        knot_sources, join_kinds, left_examples, right_examples, anime_start, anime_end,
        utterance, values, offsets, rate,
    )  # fmt: skip
    return chosen, jumps, stop, frames
