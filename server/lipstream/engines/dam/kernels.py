"""Compiled synthesis of a DAM (numba): the windowed mode searches and the sum of Eq. 2.

Sketch: interpreting ``selection`` and ``model.render`` phoneme by phoneme
cost about 0.4 ms per phoneme, nearly all of it Python and small-array
overhead. Everything that does not depend on a request is tabulated when the
model loads (``SearchTables``): for each phoneme (after its stand-in) and
emotion, the candidate modes in one flat array, and for each candidate and
each previous phoneme, next phoneme and emotion, the log share of
``selection._log_share``, computed by the same numpy expression, so the
context costs E_c are the reference's to the bit. A request then reduces to a
few integer arrays per span, and two kernels do the rest:

- ``choose_modes``: for each span k of a range, the min-plus programme over
  its window k - search_behind .. k + ahead exactly as
  ``selection.cheapest_path`` runs it (E_c with the next phoneme unknown on
  the window's last layer, E_s per join, first minimum on ties), with the
  joins' E_s computed once per pair of neighbouring spans;
- ``dam_sum``: for each frame, Eq. 2 over the spans owner - tail .. owner +
  ahead whose dominance reaches it, each term D·A with A on the clamped local
  time, in the order ``model.render`` adds them.

A streamed call of a search rung is one call of ``render_run``: each frame's
owner span found by stepping on from the last call's, ``choose_modes`` for
the spans whose mode no earlier call chose (a span's mode depends only on the
spans of its window), ``dam_sum``, and ``channels`` (the motion basis back to
float32 channels), so the modes are chosen once per span however the input
is cut.

The causal rungs (``causal``) use ``commit_mode``, a span's mode as it arrives
(E_c with its next phoneme unknown plus E_s of the join to the mode committed
before it; ``commit_modes`` runs it over the spans not yet committed), and
``causal_sum``, Eq. 2 at each time over the latest span begun and the ``tail``
before it; both sums share ``_dam_frame``. A streamed call is one call of
``causal_run``: the new modes, the raw curve, the damped filter
(``damped.follow_frame_rates``) and ``channels``.

Sums of squares and polynomial products run in plain loops, so E_s and the
frames may differ from numpy's (pairwise, BLAS) summation in the last bits;
the tests hold the modes equal and the frames within 1e-12 of the
straightforward implementation. ``channels`` adds each channel's components
in order, as a plain loop too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ...phonemes import PHONEMES
from ...timeline import EMOTIONS
from ..damped import follow_frame_rates


@dataclass(frozen=True)
class SearchTables:
    """Candidates and context costs of every (phoneme, emotion), flat.

    ``set_start``/``set_stop`` (phonemes, emotions) bound the candidates of a span of that
    canonical phoneme (its stand-in's modes, those said with the emotion if any) in
    ``modes``; ``log_previous`` / ``log_following`` (positions, phonemes) and
    ``log_emotion`` (positions, emotions) hold each candidate's log share."""

    set_start: np.ndarray
    set_stop: np.ndarray
    modes: np.ndarray
    log_previous: np.ndarray
    log_following: np.ndarray
    log_emotion: np.ndarray


def _log_shares(table: np.ndarray, candidates: np.ndarray, alpha: float) -> np.ndarray:
    """log(share) of each candidate (rows) for every context (columns), each column as
    ``selection._log_share`` computes it."""
    counts = np.ascontiguousarray(table[candidates].astype(np.float64).T) + alpha
    return np.asarray(np.log(counts / counts.sum(axis=1)[:, None]).T)


def search_tables(
    offsets: np.ndarray,
    stand_in: np.ndarray,
    count_previous: np.ndarray,
    count_following: np.ndarray,
    count_emotion: np.ndarray,
    alpha: float,
) -> SearchTables:
    """The tables of a model's modes (see ``SearchTables``)."""
    n_phonemes, n_emotions = len(PHONEMES), len(EMOTIONS)
    set_start = np.zeros((n_phonemes, n_emotions), dtype=np.int64)
    set_stop = np.zeros((n_phonemes, n_emotions), dtype=np.int64)
    chunks: list[np.ndarray] = []
    shares: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    placed: dict[tuple[int, int], tuple[int, int]] = {}
    size = 0
    for phoneme in range(n_phonemes):
        own = int(stand_in[phoneme])
        for emotion in range(n_emotions):
            candidates = np.arange(offsets[own], offsets[own + 1])
            said = candidates[count_emotion[candidates, emotion] > 0]
            if len(said):
                candidates = said
            key = (own, emotion)
            if key not in placed:
                placed[key] = (size, size + len(candidates))
                size += len(candidates)
                chunks.append(candidates)
                shares.append(
                    (
                        _log_shares(count_previous, candidates, alpha),
                        _log_shares(count_following, candidates, alpha),
                        _log_shares(count_emotion, candidates, alpha),
                    )
                )
            set_start[phoneme, emotion], set_stop[phoneme, emotion] = placed[key]
    return SearchTables(
        set_start,
        set_stop,
        np.concatenate(chunks).astype(np.int64),
        np.concatenate([share[0] for share in shares]),
        np.concatenate([share[1] for share in shares]),
        np.concatenate([share[2] for share in shares]),
    )


@njit(cache=True)
def _node(
    start: int,
    stop: int,
    previous: int,
    following: int,
    emotion: int,
    log_previous: np.ndarray,
    log_following: np.ndarray,
    log_emotion: np.ndarray,
    out: np.ndarray,
) -> None:
    """E_c of one layer's candidates into ``out``, term by term as
    ``selection.context_cost``."""
    for position in range(start, stop):
        value = 0.0
        if previous >= 0:
            value -= log_previous[position, previous]
        if following >= 0:
            value -= log_following[position, following]
        if emotion >= 0:
            value -= log_emotion[position, emotion]
        out[position - start] = value


@njit(cache=True)
def _joins(
    left: np.ndarray,
    right: np.ndarray,
    left_duration: float,
    right_duration: float,
    ends: np.ndarray,
    starts: np.ndarray,
    reference_duration: float,
    out: np.ndarray,
) -> None:
    """E_s of each (left, right) candidate pair into ``out``, as ``selection.smooth_cost``."""
    scale = np.array([1.0, reference_duration, reference_duration**2])
    left_factor = np.empty(3)
    right_factor = np.empty(3)
    for order in range(3):
        left_factor[order] = scale[order] / left_duration**order
        right_factor[order] = scale[order] / right_duration**order
    channels = ends.shape[2]
    for a in range(len(left)):
        for b in range(len(right)):
            total = 0.0
            for order in range(3):
                for channel in range(channels):
                    jump = (
                        ends[left[a], order, channel] * left_factor[order]
                        - starts[right[b], order, channel] * right_factor[order]
                    )
                    total += jump * jump
            out[a, b] = total


@njit(cache=True)
def choose_modes(
    span_set: np.ndarray,
    previous: np.ndarray,
    following: np.ndarray,
    emotion: np.ndarray,
    durations: np.ndarray,
    chosen_first: int,
    chosen_last: int,
    search_behind: int,
    ahead: int,
    set_start: np.ndarray,
    set_stop: np.ndarray,
    modes: np.ndarray,
    log_previous: np.ndarray,
    log_following: np.ndarray,
    log_emotion: np.ndarray,
    ends: np.ndarray,
    starts: np.ndarray,
    reference_duration: float,
    w_context: float,
    w_smooth: float,
) -> np.ndarray:
    """The mode of each span chosen_first .. chosen_last (indices into the per-span arrays,
    which hold every span a window reaches; ``following`` is the next span's phoneme,
    silence after the utterance's last); ``span_set`` indexes ``set_start``/``set_stop``
    flattened as phoneme * emotions + emotion."""
    n = len(span_set)
    flat_start = set_start.ravel()
    flat_stop = set_stop.ravel()
    size = np.empty(n, dtype=np.int64)
    for j in range(n):
        size[j] = flat_stop[span_set[j]] - flat_start[span_set[j]]
    width = size.max()
    open_nodes = np.zeros((n, width))
    cut_nodes = np.zeros((n, width))
    for j in range(n):
        start, stop = flat_start[span_set[j]], flat_stop[span_set[j]]
        shares = (log_previous, log_following, log_emotion)
        _node(start, stop, previous[j], following[j], emotion[j], *shares, open_nodes[j])
        _node(start, stop, previous[j], -1, emotion[j], *shares, cut_nodes[j])
    joins = np.zeros((max(n - 1, 0), width, width))
    for j in range(n - 1):
        left = modes[flat_start[span_set[j]] : flat_stop[span_set[j]]]
        right = modes[flat_start[span_set[j + 1]] : flat_stop[span_set[j + 1]]]
        _joins(
            left, right, durations[j], durations[j + 1], ends, starts, reference_duration, joins[j]
        )
    chosen = np.empty(chosen_last - chosen_first + 1, dtype=np.int64)
    total = np.empty(width)
    following_total = np.empty(width)
    backs = np.zeros((n, width), dtype=np.int64)
    for k in range(chosen_first, chosen_last + 1):
        first = max(0, k - search_behind)
        last = k + ahead
        stop = min(last, n - 1)
        node = cut_nodes[first] if first == last else open_nodes[first]
        for a in range(size[first]):
            total[a] = w_context * node[a]
        for j in range(first + 1, stop + 1):
            node = cut_nodes[j] if j == last else open_nodes[j]
            join = joins[j - 1]
            for b in range(size[j]):
                best = 0
                best_step = total[0] + w_smooth * join[0, b]
                for a in range(1, size[j - 1]):
                    step = total[a] + w_smooth * join[a, b]
                    if step < best_step:
                        best, best_step = a, step
                backs[j, b] = best
                following_total[b] = best_step + w_context * node[b]
            total[: size[j]] = following_total[: size[j]]
        position = 0
        for a in range(1, size[stop]):
            if total[a] < total[position]:
                position = a
        for j in range(stop, k, -1):
            position = backs[j, position]
        chosen[k - chosen_first] = modes[flat_start[span_set[k]] + position]
    return chosen


@njit(cache=True)
def _dam_frame(
    time: float,
    low: int,
    high: int,
    span_start: np.ndarray,
    span_end: np.ndarray,
    span_mode: np.ndarray,
    sigma: np.ndarray,
    reach: np.ndarray,
    eps: float,
    coefficients: np.ndarray,
    animeme: np.ndarray,
    out: np.ndarray,
) -> None:
    """Add to ``out`` (components) Eq. 2 at ``time`` over spans ``low`` .. ``high``: D·A of each
    span's mode wherever its local time lies within the mode's reach (``animeme`` is
    scratch)."""
    n_terms, n_components = coefficients.shape[1], coefficients.shape[2]
    for k in range(low, high + 1):
        mode = span_mode[k]
        local = (time - span_start[k]) / (span_end[k] - span_start[k])
        if local < -reach[mode] or local > 1.0 + reach[mode]:
            continue
        gap = local if local < 0.0 else (local - 1.0 if local > 1.0 else 0.0)
        weight = 1.0  # exp(-0 / w), exactly
        if gap != 0.0:
            weight = np.exp(-(gap * gap) / (2.0 * sigma[mode] * sigma[mode] + eps))
        clamped = min(max(local, 0.0), 1.0)
        # A = sum_m clamped^m a_m, in increasing m as ``powers(u) @ coefficients`` adds
        animeme[:] = coefficients[mode, 0]
        power = 1.0
        for m in range(1, n_terms):
            power *= clamped
            for c in range(n_components):
                animeme[c] += power * coefficients[mode, m, c]
        for c in range(n_components):
            out[c] += weight * animeme[c]


@njit(cache=True)
def dam_sum(
    times: np.ndarray,
    owner: np.ndarray,
    span_start: np.ndarray,
    span_end: np.ndarray,
    span_mode: np.ndarray,
    tail: int,
    ahead: int,
    sigma: np.ndarray,
    reach: np.ndarray,
    eps: float,
    coefficients: np.ndarray,
) -> np.ndarray:
    """Eq. 2 at ``times`` (components): frame i sums, over spans k (indices into the per-span
    arrays) from owner[i] - tail to owner[i] + ahead, D·A of span k's mode wherever its local
    time lies within the mode's reach."""
    n_spans = len(span_mode)
    frames = np.zeros((len(times), coefficients.shape[2]))
    animeme = np.empty(coefficients.shape[2])
    for i in range(len(times)):
        low, high = max(0, owner[i] - tail), min(n_spans - 1, owner[i] + ahead)
        _dam_frame(times[i], low, high, span_start, span_end, span_mode, sigma, reach, eps,
                   coefficients, animeme, frames[i])  # fmt: skip
    return frames


@njit(cache=True)
def channels(values: np.ndarray, components: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """``MotionBasis.reconstruct`` of ``values`` (frames, components) as float32 frames: each
    channel the sum over components, added in component order, plus the mean."""
    n_channels = components.shape[1]
    out = np.empty((values.shape[0], n_channels), dtype=np.float32)
    total = np.empty(n_channels)
    for i in range(values.shape[0]):
        total[:] = 0.0
        for component in range(components.shape[0]):
            weight = values[i, component]
            for channel in range(n_channels):
                total[channel] += weight * components[component, channel]
        for channel in range(n_channels):
            out[i, channel] = np.float32(total[channel] + mean[channel])
    return out


@njit(cache=True)
def render_run(
    times: np.ndarray,
    owner: int,
    n_spans: int,
    span_start: np.ndarray,
    span_end: np.ndarray,
    span_phoneme: np.ndarray,
    span_emotion: np.ndarray,
    span_mode: np.ndarray,
    silence: int,
    search_behind: int,
    search: int,
    tail: int,
    ahead: int,
    sigma: np.ndarray,
    reach: np.ndarray,
    eps: float,
    coefficients: np.ndarray,
    components: np.ndarray,
    mean: np.ndarray,
    set_start: np.ndarray,
    set_stop: np.ndarray,
    modes: np.ndarray,
    log_previous: np.ndarray,
    log_following: np.ndarray,
    log_emotion: np.ndarray,
    ends: np.ndarray,
    starts: np.ndarray,
    reference_duration: float,
    w_context: float,
    w_smooth: float,
) -> tuple[np.ndarray, int]:
    """A search rung's float32 frames at ascending ``times``, over the first ``n_spans``
    spans (rows of the per-span arrays, which may hold more): each frame's owner (the first
    span ending after it, the last span after the end) found by stepping from ``owner``,
    the modes of the spans the frames reach that ``span_mode`` does not hold yet (-1)
    chosen by ``choose_modes`` and stored there, then ``dam_sum`` and ``channels``.
    Returns the frames and the owner of the last time."""
    n = n_spans
    span_start, span_end, span_mode = span_start[:n], span_end[:n], span_mode[:n]
    if len(times) == 0:
        return np.zeros((0, components.shape[1]), dtype=np.float32), owner
    owners = np.empty(len(times), dtype=np.int64)
    owner = min(max(owner, 0), n - 1)
    for i in range(len(times)):
        while owner > 0 and span_end[owner - 1] > times[i]:
            owner -= 1
        while owner < n - 1 and span_end[owner] <= times[i]:
            owner += 1
        owners[i] = owner
    first = max(0, owners[0] - tail)
    last = min(n - 1, owners[-1] + ahead)
    missing = first
    while missing <= last and span_mode[missing] >= 0:
        missing += 1
    if missing <= last:
        low = max(0, missing - search_behind)
        high = min(n - 1, last + search)
        previous = np.empty(high - low + 1, dtype=np.int64)
        following = np.empty(high - low + 1, dtype=np.int64)
        for k in range(low, high + 1):
            previous[k - low] = span_phoneme[k - 1] if k > 0 else silence
            following[k - low] = span_phoneme[k + 1] if k + 1 < n else silence
        sets = span_phoneme[low : high + 1] * set_start.shape[1] + span_emotion[low : high + 1]
        span_mode[missing : last + 1] = choose_modes(
            sets, previous, following, span_emotion[low : high + 1],
            span_end[low : high + 1] - span_start[low : high + 1], missing - low, last - low,
            search_behind, search, set_start, set_stop, modes, log_previous, log_following,
            log_emotion, ends, starts, reference_duration, w_context, w_smooth,
        )  # fmt: skip
    values = dam_sum(times, owners, span_start, span_end, span_mode, tail, ahead, sigma, reach,
                     eps, coefficients)  # fmt: skip
    return channels(values, components, mean), owner


@njit(cache=True)
def commit_mode(
    span_set: int,
    previous: int,
    emotion: int,
    duration: float,
    before_mode: int,
    before_duration: float,
    set_start: np.ndarray,
    set_stop: np.ndarray,
    modes: np.ndarray,
    log_previous: np.ndarray,
    log_following: np.ndarray,
    log_emotion: np.ndarray,
    ends: np.ndarray,
    starts: np.ndarray,
    reference_duration: float,
    w_context: float,
    w_smooth: float,
) -> int:
    """The causal rungs' mode of a span as it arrives (``span_set``, ``previous``, ``emotion``
    as in ``choose_modes``): the least w_c·E_c, its next phoneme unknown, plus w_s·E_s of its
    join to ``before_mode``, the mode committed at the span before (of ``before_duration``
    s; no join when negative); the first minimum on ties."""
    start, stop = set_start.ravel()[span_set], set_stop.ravel()[span_set]
    cost = np.empty(stop - start)
    _node(start, stop, previous, -1, emotion, log_previous, log_following, log_emotion, cost)
    for a in range(stop - start):
        cost[a] = w_context * cost[a]
    if before_mode >= 0:
        join = np.empty((1, stop - start))
        left = np.full(1, before_mode, dtype=np.int64)
        _joins(left, modes[start:stop], before_duration, duration, ends, starts,
               reference_duration, join)  # fmt: skip
        for a in range(stop - start):
            cost[a] = cost[a] + w_smooth * join[0, a]
    position = 0
    for a in range(1, stop - start):
        if cost[a] < cost[position]:
            position = a
    return int(modes[start + position])


@njit(cache=True)
def causal_sum(
    times: np.ndarray,
    span_start: np.ndarray,
    span_end: np.ndarray,
    span_mode: np.ndarray,
    span_rate: np.ndarray,
    tail: int,
    sigma: np.ndarray,
    reach: np.ndarray,
    eps: float,
    coefficients: np.ndarray,
    started: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The causal rungs' raw curve: Eq. 2 at each of ``times`` over the latest span begun by
    then (the last whose start lies more than ``started`` before it; span 0 at the first
    times) and the ``tail`` spans before it, and that span's ``span_rate``."""
    frames = np.zeros((len(times), coefficients.shape[2]))
    rates = np.empty(len(times))
    animeme = np.empty(coefficients.shape[2])
    for i in range(len(times)):
        begun = max(np.searchsorted(span_start, times[i] - started) - 1, 0)
        _dam_frame(times[i], max(0, begun - tail), begun, span_start, span_end, span_mode,
                   sigma, reach, eps, coefficients, animeme, frames[i])  # fmt: skip
        rates[i] = span_rate[begun]
    return frames, rates


@njit(cache=True)
def commit_modes(
    first: int,
    span_start: np.ndarray,
    span_end: np.ndarray,
    span_phoneme: np.ndarray,
    span_emotion: np.ndarray,
    span_mode: np.ndarray,
    silence: int,
    set_start: np.ndarray,
    set_stop: np.ndarray,
    modes: np.ndarray,
    log_previous: np.ndarray,
    log_following: np.ndarray,
    log_emotion: np.ndarray,
    ends: np.ndarray,
    starts: np.ndarray,
    reference_duration: float,
    w_context: float,
    w_smooth: float,
) -> None:
    """``commit_mode`` of spans ``first`` .. the last, in order, into ``span_mode`` (each
    joined to the mode committed before it; the first span after silence)."""
    n_emotions = set_start.shape[1]
    for k in range(first, len(span_mode)):
        previous, before_mode, before_duration = silence, -1, 1.0
        if k > 0:
            previous, before_mode = span_phoneme[k - 1], span_mode[k - 1]
            before_duration = span_end[k - 1] - span_start[k - 1]
        span_mode[k] = commit_mode(
            span_phoneme[k] * n_emotions + span_emotion[k], previous, span_emotion[k],
            span_end[k] - span_start[k], before_mode, before_duration, set_start, set_stop,
            modes, log_previous, log_following, log_emotion, ends, starts, reference_duration,
            w_context, w_smooth,
        )  # fmt: skip


@njit(cache=True)
def causal_run(
    first_frame: int,
    stop_frame: int,
    fps: float,
    shift: float,
    started: float,
    kappa: float,
    x: np.ndarray,
    v: np.ndarray,
    t: float,
    fresh: bool,
    committed: int,
    n_spans: int,
    span_start: np.ndarray,
    span_end: np.ndarray,
    span_phoneme: np.ndarray,
    span_emotion: np.ndarray,
    span_mode: np.ndarray,
    span_rate: np.ndarray,
    silence: int,
    tail: int,
    sigma: np.ndarray,
    reach: np.ndarray,
    eps: float,
    coefficients: np.ndarray,
    components: np.ndarray,
    mean: np.ndarray,
    set_start: np.ndarray,
    set_stop: np.ndarray,
    modes: np.ndarray,
    log_previous: np.ndarray,
    log_following: np.ndarray,
    log_emotion: np.ndarray,
    ends: np.ndarray,
    starts: np.ndarray,
    reference_duration: float,
    w_context: float,
    w_smooth: float,
) -> tuple[np.ndarray, float]:
    """A causal rung's float32 frames ``first_frame`` .. ``stop_frame`` - 1 at ``fps``, over
    the first ``n_spans`` spans (rows of the per-span arrays, which may hold more): the
    modes of the spans from ``committed`` on committed (``commit_modes``), the raw curve at
    each frame's time + ``shift`` (``causal_sum``), the filter (value ``x``, velocity
    ``v``, at time ``t``; ``fresh``: none yet, it starts at rest on the first raw value)
    stepped toward it at ω = ``kappa`` times the rates (``damped.follow_frame_rates``), and
    the basis (``channels``). ``x`` and ``v`` are updated in place; returns the frames and
    the filter's time."""
    n = n_spans
    span_start, span_end, span_mode = span_start[:n], span_end[:n], span_mode[:n]
    span_phoneme, span_emotion, span_rate = span_phoneme[:n], span_emotion[:n], span_rate[:n]
    commit_modes(committed, span_start, span_end, span_phoneme, span_emotion, span_mode,
                 silence, set_start, set_stop, modes, log_previous, log_following, log_emotion,
                 ends, starts, reference_duration, w_context, w_smooth)  # fmt: skip
    times = np.arange(first_frame, stop_frame) / fps
    raw, rates = causal_sum(times + shift, span_start, span_end, span_mode, span_rate, tail,
                            sigma, reach, eps, coefficients, started)  # fmt: skip
    values = np.empty((len(times), coefficients.shape[2]))
    first = 0
    if fresh:
        x[:] = raw[0]
        v[:] = 0.0
        t = times[0]
        values[0] = x
        first = 1
    if len(times) > first:
        omegas = kappa * rates
        follow_frame_rates(x, v, t, raw[first:], omegas[first:], times[first:], values[first:])
    return channels(values, components, mean), times[-1]
