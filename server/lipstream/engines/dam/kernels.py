"""Compiled synthesis of a DAM (numba): the windowed mode searches and the sum of Eq. 2.

Sketch: interpreting the mode search (the tests' numpy reference,
``tests/lipstream/engines/dam/reference.py``) and ``model.render`` phoneme by phoneme
cost about 0.4 ms per phoneme, nearly all of it Python and small-array
overhead. Everything that does not depend on a request is tabulated when the
model loads (``SearchTables``): for each phoneme (after its stand-in) and
emotion, the candidate modes in one flat array, and for each candidate and
each previous phoneme, next phoneme and emotion, the log share of the
reference's ``_log_share``, computed by the same numpy expression, so the
context costs E_c are the reference's to the bit. A request then reduces to a
few integer arrays per span, and two kernels do the rest:

- ``choose_modes``: for each span k of a range, the min-plus programme over
  its window k - search_behind .. k + ahead exactly as the reference's
  ``cheapest_path`` runs it (E_c with the next phoneme unknown on the
  window's last layer, E_s per join, first minimum on ties): the shared
  layered search (``numerics.layered.sliding_positions``, every window in one
  call) over a trellis built once per call, E_c and the joins' E_s computed once per span
  and per pair of neighbouring spans and weighed by w_c and w_s there (the
  products the reference adds);
- ``dam_sum``: for each frame, Eq. 2 over the spans owner - tail .. owner +
  ahead whose dominance reaches it, each term D·A with A on the clamped local
  time, in the order ``model.render`` adds them.

The kernels take the model's arrays in named groups, built once when it loads:
``SearchTables`` (candidates, log shares, end derivatives, weights), ``Animemes``
(dominance and coefficients) and ``DamTables`` (those two, the basis and the
model's integers); a request's spans come as ``SpanArrays``.

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

from typing import NamedTuple

import numpy as np
from numba import njit

from ...numerics.basis import IN_ORDER, basis_frames
from ...numerics.layered import Survivors, Trellis, sliding_positions
from ...phonemes import PHONEMES
from ...timeline import EMOTIONS
from ..damped import FilterState, follow_frame_rates
from .modes import SILENCE_INDEX
from .selection import Costs

STARTED = 1e-9
"""A span starting within this of τ has not begun at τ (causal rungs): the frame at a span's
end is final with that span's input."""


class SearchTables(NamedTuple):
    """Everything a mode search reads, flat, built once per model by ``search_tables``.

    ``set_start``/``set_stop`` (phonemes, emotions) bound the candidates of a span of that
    canonical phoneme (its stand-in's modes, those said with the emotion if any) in
    ``modes``; ``log_previous`` / ``log_following`` (positions, phonemes) and
    ``log_emotion`` (positions, emotions) hold each candidate's log share; ``ends`` and
    ``starts`` (modes, 3, components) each mode's value and local-time derivatives at its
    ends (``selection.end_derivatives``), E_s's terms scaled by ``reference_duration``
    (s); ``w_context`` and ``w_smooth`` weigh E_c and E_s."""

    set_start: np.ndarray
    set_stop: np.ndarray
    modes: np.ndarray
    log_previous: np.ndarray
    log_following: np.ndarray
    log_emotion: np.ndarray
    ends: np.ndarray
    starts: np.ndarray
    reference_duration: float
    w_context: float
    w_smooth: float


class Animemes(NamedTuple):
    """What Eq. 2 sums, per mode: dominance width ``sigma`` and ``reach`` (modes,), the
    dominance's ``eps``, and the animeme ``coefficients`` (modes, M + 1, components)."""

    sigma: np.ndarray
    reach: np.ndarray
    eps: float
    coefficients: np.ndarray


class DamTables(NamedTuple):
    """A model's arrays as its kernels read them (``DamModel.tables``): the mode
    ``search``, the ``animemes``, the motion basis (``components`` (components,
    channels), ``mean`` (channels,)), the spans summed on each side (``tail``) and searched
    behind (``search_behind``), and the causal filter's ``kappa``."""

    search: SearchTables
    animemes: Animemes
    components: np.ndarray
    mean: np.ndarray
    tail: int
    search_behind: int
    kappa: float


class SpanArrays(NamedTuple):
    """A request's spans, one row each (buffers that may hold more rows than spans): start
    and end (s, float64), phoneme and emotion (int64 indices), and mode (int64; -1: not
    chosen yet)."""

    starts: np.ndarray
    ends: np.ndarray
    phonemes: np.ndarray
    emotions: np.ndarray
    modes: np.ndarray


def _log_shares(table: np.ndarray, candidates: np.ndarray, alpha: float) -> np.ndarray:
    """log(share) of each candidate (rows) for every context (columns), each column as
    the reference's ``_log_share`` computes it."""
    counts = np.ascontiguousarray(table[candidates].astype(np.float64).T) + alpha
    return np.asarray(np.log(counts / counts.sum(axis=1)[:, None]).T)


def search_tables(offsets: np.ndarray, stand_in: np.ndarray, costs: Costs) -> SearchTables:
    """The tables of a model's modes (``offsets`` by phoneme, ``stand_in`` for phonemes
    without any) and its search ``costs`` (see ``SearchTables``)."""
    count_previous, count_following = costs.previous, costs.following
    count_emotion, alpha = costs.emotion, costs.alpha
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
        np.ascontiguousarray(costs.ends, dtype=np.float64),
        np.ascontiguousarray(costs.starts, dtype=np.float64),
        float(costs.reference_duration),
        float(costs.w_context),
        float(costs.w_smooth),
    )


@njit(cache=True)
def _node(
    start: int,
    stop: int,
    previous: int,
    following: int,
    emotion: int,
    search: SearchTables,
    out: np.ndarray,
) -> None:
    """E_c of one layer's candidates into ``out``, term by term as
    the reference's ``context_cost``."""
    log_previous, log_following = search.log_previous, search.log_following
    log_emotion = search.log_emotion
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
    search: SearchTables,
    out: np.ndarray,
) -> None:
    """E_s of each (left, right) candidate pair into ``out``, as the reference's ``smooth_cost``."""
    ends, starts, reference_duration = search.ends, search.starts, search.reference_duration
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
    search: SearchTables,
) -> np.ndarray:
    """The mode of each span chosen_first .. chosen_last (indices into the per-span arrays,
    which hold every span a window reaches; ``following`` is the next span's phoneme,
    silence after the utterance's last); ``span_set`` indexes ``set_start``/``set_stop``
    flattened as phoneme * emotions + emotion."""
    n = len(span_set)
    flat_start = search.set_start.ravel()
    flat_stop = search.set_stop.ravel()
    modes, w_context, w_smooth = search.modes, search.w_context, search.w_smooth
    size = np.empty(n, dtype=np.int64)
    for j in range(n):
        size[j] = flat_stop[span_set[j]] - flat_start[span_set[j]]
    width = size.max()
    open_nodes = np.zeros((n, width))
    cut_nodes = np.zeros((n, width))
    for j in range(n):
        start, stop = flat_start[span_set[j]], flat_stop[span_set[j]]
        _node(start, stop, previous[j], following[j], emotion[j], search, open_nodes[j])
        _node(start, stop, previous[j], -1, emotion[j], search, cut_nodes[j])
        for a in range(size[j]):  # weighed once here, the products the reference adds
            open_nodes[j, a] = w_context * open_nodes[j, a]
            cut_nodes[j, a] = w_context * cut_nodes[j, a]
    joins = np.zeros((max(n - 1, 0), width, width))
    for j in range(n - 1):
        left = modes[flat_start[span_set[j]] : flat_stop[span_set[j]]]
        right = modes[flat_start[span_set[j + 1]] : flat_stop[span_set[j + 1]]]
        _joins(left, right, durations[j], durations[j + 1], search, joins[j])
        for a in range(size[j]):
            for b in range(size[j + 1]):
                joins[j, a, b] = w_smooth * joins[j, a, b]
    work = Survivors(np.empty(width), np.empty(width), np.zeros((n, width), dtype=np.int64))
    trellis = Trellis(open_nodes, size, joins)
    positions = sliding_positions(
        trellis, cut_nodes, chosen_first, chosen_last, search_behind, ahead, work
    )
    chosen = np.empty(chosen_last - chosen_first + 1, dtype=np.int64)
    for k in range(chosen_first, chosen_last + 1):
        chosen[k - chosen_first] = modes[flat_start[span_set[k]] + positions[k - chosen_first]]
    return chosen


@njit(cache=True)
def _dam_frame(
    time: float,
    low: int,
    high: int,
    spans: SpanArrays,
    animemes: Animemes,
    animeme: np.ndarray,
    out: np.ndarray,
) -> None:
    """Add to ``out`` (components) Eq. 2 at ``time`` over spans ``low`` .. ``high``: D·A of each
    span's mode wherever its local time lies within the mode's reach (``animeme`` is
    scratch)."""
    span_start, span_end, span_mode = spans.starts, spans.ends, spans.modes
    sigma, reach, eps = animemes.sigma, animemes.reach, animemes.eps
    coefficients = animemes.coefficients
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
    spans: SpanArrays,
    n_spans: int,
    tail: int,
    ahead: int,
    animemes: Animemes,
) -> np.ndarray:
    """Eq. 2 at ``times`` (components): frame i sums, over spans k (rows of ``spans``, the
    first ``n_spans``) from owner[i] - tail to owner[i] + ahead, D·A of span k's mode wherever
    its local time lies within the mode's reach."""
    n_components = animemes.coefficients.shape[2]
    frames = np.zeros((len(times), n_components))
    animeme = np.empty(n_components)
    for i in range(len(times)):
        low, high = max(0, owner[i] - tail), min(n_spans - 1, owner[i] + ahead)
        _dam_frame(times[i], low, high, spans, animemes, animeme, frames[i])
    return frames


@njit(cache=True)
def channels(values: np.ndarray, tables: DamTables) -> np.ndarray:
    """The basis of ``tables`` back to float32 channel frames, each channel's components
    added in order (``IN_ORDER``: the DAM's frames have always been summed so, and BLAS's
    product differs in the last bits)."""
    unbounded = np.empty(0)
    return basis_frames(values, tables.components, tables.mean, unbounded, unbounded, IN_ORDER)


@njit(cache=True)
def render_run(
    times: np.ndarray,
    owner: int,
    spans: SpanArrays,
    n_spans: int,
    search: int,
    ahead: int,
    tables: DamTables,
) -> tuple[np.ndarray, int]:
    """A search rung's float32 frames at ascending ``times``, over the first ``n_spans``
    rows of ``spans`` (which may hold more), searching ``search`` spans ahead and summing
    ``ahead`` spans ahead: each frame's owner (the first span ending after it, the last
    span after the end) found by stepping from ``owner``, the modes of the spans the frames
    reach that ``spans.modes`` does not hold yet (-1) chosen by ``choose_modes`` and stored
    there, then ``dam_sum`` and ``channels``. Returns the frames and the owner of the last
    time."""
    n, tail, search_behind = n_spans, tables.tail, tables.search_behind
    span_start, span_end, span_mode = spans.starts[:n], spans.ends[:n], spans.modes[:n]
    span_phoneme, span_emotion = spans.phonemes, spans.emotions
    if len(times) == 0:
        return np.zeros((0, tables.components.shape[1]), dtype=np.float32), owner
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
            previous[k - low] = span_phoneme[k - 1] if k > 0 else SILENCE_INDEX
            following[k - low] = span_phoneme[k + 1] if k + 1 < n else SILENCE_INDEX
        emotions = span_emotion[low : high + 1]
        sets = span_phoneme[low : high + 1] * tables.search.set_start.shape[1] + emotions
        durations = span_end[low : high + 1] - span_start[low : high + 1]
        span_mode[missing : last + 1] = choose_modes(
            sets,
            previous,
            following,
            emotions,
            durations,
            missing - low,
            last - low,
            search_behind,
            search,
            tables.search,
        )
    values = dam_sum(times, owners, spans, n, tail, ahead, tables.animemes)
    return channels(values, tables), owner


@njit(cache=True)
def commit_mode(
    span_set: int,
    previous: int,
    emotion: int,
    duration: float,
    before_mode: int,
    before_duration: float,
    search: SearchTables,
) -> int:
    """The causal rungs' mode of a span as it arrives (``span_set``, ``previous``, ``emotion``
    as in ``choose_modes``): the least w_c·E_c, its next phoneme unknown, plus w_s·E_s of its
    join to ``before_mode``, the mode committed at the span before (of ``before_duration``
    s; no join when negative); the first minimum on ties."""
    start, stop = search.set_start.ravel()[span_set], search.set_stop.ravel()[span_set]
    modes, w_context, w_smooth = search.modes, search.w_context, search.w_smooth
    cost = np.empty(stop - start)
    _node(start, stop, previous, -1, emotion, search, cost)
    for a in range(stop - start):
        cost[a] = w_context * cost[a]
    if before_mode >= 0:
        join = np.empty((1, stop - start))
        left = np.full(1, before_mode, dtype=np.int64)
        _joins(left, modes[start:stop], before_duration, duration, search, join)
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
    spans: SpanArrays,
    n_spans: int,
    rates: np.ndarray,
    tail: int,
    animemes: Animemes,
) -> tuple[np.ndarray, np.ndarray]:
    """The causal rungs' raw curve over the first ``n_spans`` rows of ``spans``: Eq. 2 at
    each of ``times`` over the latest span begun by then (the last whose start lies more
    than ``STARTED`` before it; span 0 at the first times) and the ``tail`` spans before
    it, and that span's rate (``rates``, one per span)."""
    span_start = spans.starts[:n_spans]
    n_components = animemes.coefficients.shape[2]
    frames = np.zeros((len(times), n_components))
    out_rates = np.empty(len(times))
    animeme = np.empty(n_components)
    for i in range(len(times)):
        begun = max(np.searchsorted(span_start, times[i] - STARTED) - 1, 0)
        _dam_frame(times[i], max(0, begun - tail), begun, spans, animemes, animeme, frames[i])
        out_rates[i] = rates[begun]
    return frames, out_rates


@njit(cache=True)
def commit_modes(first: int, spans: SpanArrays, n_spans: int, search: SearchTables) -> None:
    """``commit_mode`` of spans ``first`` .. ``n_spans`` - 1, in order, into ``spans.modes``
    (each joined to the mode committed before it; the first span after silence)."""
    span_start, span_end, span_mode = spans.starts, spans.ends, spans.modes
    span_phoneme, span_emotion = spans.phonemes, spans.emotions
    n_emotions = search.set_start.shape[1]
    for k in range(first, n_spans):
        previous, before_mode, before_duration = SILENCE_INDEX, -1, 1.0
        if k > 0:
            previous, before_mode = span_phoneme[k - 1], span_mode[k - 1]
            before_duration = span_end[k - 1] - span_start[k - 1]
        span_mode[k] = commit_mode(
            span_phoneme[k] * n_emotions + span_emotion[k],
            previous,
            span_emotion[k],
            span_end[k] - span_start[k],
            before_mode,
            before_duration,
            search,
        )


@njit(cache=True)
def causal_run(
    first_frame: int,
    stop_frame: int,
    fps: float,
    shift: float,
    state: FilterState,
    committed: int,
    spans: SpanArrays,
    n_spans: int,
    rates: np.ndarray,
    tables: DamTables,
) -> np.ndarray:
    """A causal rung's float32 frames ``first_frame`` .. ``stop_frame`` - 1 at ``fps``, over
    the first ``n_spans`` rows of ``spans`` (which may hold more) and their ``rates``: the
    modes of the spans from ``committed`` on committed (``commit_modes``), the raw curve at
    each frame's time + ``shift`` (``causal_sum``), the filter ``state`` (at frame
    ``first_frame`` - 1; at frame 0 it starts at rest on the first raw value) stepped
    toward it at ω = kappa times the rates (``damped.follow_frame_rates``), and the basis
    (``channels``). The state is updated in place."""
    commit_modes(committed, spans, n_spans, tables.search)
    times = np.arange(first_frame, stop_frame) / fps
    raw, frame_rates = causal_sum(
        times + shift, spans, n_spans, rates[:n_spans], tables.tail, tables.animemes
    )
    x, v = state.x, state.v
    values = np.empty((len(times), tables.animemes.coefficients.shape[2]))
    first = 0
    t = (first_frame - 1) / fps
    if first_frame == 0:
        x[:] = raw[0]
        v[:] = 0.0
        t = times[0]
        values[0] = x
        first = 1
    if len(times) > first:
        omegas = tables.kappa * frame_rates
        follow_frame_rates(x, v, t, raw[first:], omegas[first:], times[first:], values[first:])
    return channels(values, tables)
