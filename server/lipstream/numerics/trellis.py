"""HMM trellis kernels in log space: Viterbi, forward-backward, and fixed-lag Viterbi.

Method. Probabilities are carried as logarithms so long sequences never
underflow. The forward and backward recursions shift each message by its
maximum, exponentiate and multiply by the transition matrix (one
matrix-vector product per frame); where a state's sum comes out so small that
its terms may have underflowed (its only predecessors far below the best
state), that state alone is redone as an exact log-sum-exp. Viterbi takes the
max of log δ + log A. The kernels are compiled loops over frames (numba), vectorized
over states; the work per frame is O(N²).

``forward_backward`` also returns the entropy H(S | X) of the posterior over
state sequences, which is a Markov chain: H = H(s₀ | X) + Σ_t H(s_t | s_{t−1}, X),
with P(s_t = j | s_{t−1} = i, X) = ξ_t(i, j) / γ_{t−1}(i). Per frame it is the
entropy rate of the decoded state sequence.

``FixedLagViterbi`` decodes a stream frame by frame. After each frame it
traces every live survivor back to the oldest uncommitted frame; where all of
them pass through one state (the survivors have merged) every frame up to
there is committed, which is exactly the full Viterbi path there. When the
oldest uncommitted frame falls ``lag`` frames behind, it is committed from the
best survivor and every survivor not passing through it is dropped, so later
decisions stay consistent with it. Lag 0 is greedy decoding. The decisions
depend only on the frames seen, never on how the stream was cut. Its max runs
over each state's possible predecessors only (``predecessors``; entropic
training leaves most transitions at zero), in increasing order, so ties and
the result are the dense max's.

hmmlearn's compiled ``_hmmc`` has forward-backward and Viterbi but no fixed-lag
decoder or posterior entropy, and would be a new dependency; numba is already
one, so the three kernels live here together.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

NEG_INF = -np.inf
_NO_LAG = int(np.iinfo(np.int64).max)
_SMALL = 1e-250


@dataclass(frozen=True)
class Posterior:
    """``forward_backward``'s result: log-likelihood, state marginals γ (T, N), expected
    transition counts Σ_t ξ_t (N, N), and the posterior entropy H(S | X) in nats."""

    log_likelihood: float
    gamma: np.ndarray
    transitions: np.ndarray
    entropy: float


@njit(cache=True)
def _log_sum_exp_sum(first: np.ndarray, second: np.ndarray) -> float:
    """log Σ_k exp(first[k] + second[k]), shifted by its own maximum."""
    peak = NEG_INF
    for k in range(first.shape[0]):
        value = first[k] + second[k]
        if value > peak:
            peak = value
    if peak == NEG_INF:
        return NEG_INF
    total = 0.0
    for k in range(first.shape[0]):
        value = first[k] + second[k]
        if value > NEG_INF:
            total += np.exp(value - peak)
    return float(np.log(total) + peak)


@njit(cache=True)
def _step(previous: np.ndarray, weights: np.ndarray, logs: np.ndarray, out: np.ndarray) -> None:
    """out[j] = log Σ_k exp(previous[k]) · weights[j, k], in log space: one shared shift and
    a matrix-vector product, redone per state by its own log-sum-exp where the shared
    shift left a sum so small that terms may have underflowed (``_SMALL``)."""
    peak = previous.max()
    if peak == NEG_INF:
        out[:] = NEG_INF
        return
    scaled = np.exp(previous - peak)
    sums = weights @ scaled
    for j in range(out.shape[0]):
        if sums[j] > _SMALL:
            out[j] = np.log(sums[j]) + peak
        else:
            out[j] = _log_sum_exp_sum(previous, logs[j])


@njit(cache=True)
def _forward_backward(
    log_start: np.ndarray, transition: np.ndarray, log_emission: np.ndarray
) -> tuple[float, np.ndarray, np.ndarray, float]:
    frames, states = log_emission.shape
    log_transition = np.full((states, states), NEG_INF)
    for i in range(states):
        for j in range(states):
            if transition[i, j] > 0.0:
                log_transition[i, j] = np.log(transition[i, j])
    into = np.ascontiguousarray(transition.T)
    log_into = np.ascontiguousarray(log_transition.T)
    log_alpha = np.empty((frames, states))
    log_alpha[0] = log_start + log_emission[0]
    for t in range(1, frames):
        _step(log_alpha[t - 1], into, log_into, log_alpha[t])
        log_alpha[t] += log_emission[t]
    log_likelihood = _log_sum_exp_sum(log_alpha[frames - 1], np.zeros(states))
    log_beta = np.zeros((frames, states))
    ahead = np.empty(states)
    for t in range(frames - 2, -1, -1):
        ahead[:] = log_emission[t + 1] + log_beta[t + 1]
        _step(ahead, transition, log_transition, log_beta[t])
    gamma = np.exp(log_alpha + log_beta - log_likelihood)
    counts = np.zeros((states, states))
    entropy = 0.0
    for j in range(states):
        if gamma[0, j] > 0.0:
            entropy -= gamma[0, j] * np.log(gamma[0, j])
    for t in range(1, frames):
        ahead[:] = log_emission[t] + log_beta[t]
        shift = ahead.max()
        right = np.exp(ahead - shift)
        for i in range(states):
            if gamma[t - 1, i] <= 0.0:
                continue
            base = log_alpha[t - 1, i] - log_likelihood + shift
            left = np.exp(base)
            log_gamma = np.log(gamma[t - 1, i])
            for j in range(states):
                xi = left * transition[i, j] * right[j]
                if xi > 0.0:
                    counts[i, j] += xi
                    entropy -= xi * (base + log_transition[i, j] + ahead[j] - shift - log_gamma)
    return log_likelihood, gamma, counts, entropy


def forward_backward(
    log_start: np.ndarray, transition: np.ndarray, log_emission: np.ndarray
) -> Posterior:
    """Posterior of an HMM with start log-probabilities (N,), transition probabilities
    (N, N) and per-frame emission log-likelihoods (T, N), T ≥ 1."""
    log_likelihood, gamma, counts, entropy = _forward_backward(
        np.ascontiguousarray(log_start, dtype=np.float64),
        np.ascontiguousarray(transition, dtype=np.float64),
        np.ascontiguousarray(log_emission, dtype=np.float64),
    )
    return Posterior(float(log_likelihood), gamma, counts, max(0.0, float(entropy)))


@njit(cache=True)
def _viterbi(
    log_start: np.ndarray, log_transition: np.ndarray, log_emission: np.ndarray
) -> tuple[np.ndarray, float]:
    frames, states = log_emission.shape
    pointers = np.zeros((frames, states), dtype=np.int64)
    delta = log_start + log_emission[0]
    for t in range(1, frames):
        fresh = np.empty(states)
        for j in range(states):
            best = 0
            score = delta[0] + log_transition[0, j]
            for i in range(1, states):
                candidate = delta[i] + log_transition[i, j]
                if candidate > score:
                    score, best = candidate, i
            fresh[j] = score + log_emission[t, j]
            pointers[t, j] = best
        delta = fresh
    path = np.empty(frames, dtype=np.int64)
    path[frames - 1] = np.argmax(delta)
    for t in range(frames - 1, 0, -1):
        path[t - 1] = pointers[t, path[t]]
    return path, delta[path[frames - 1]]


def viterbi(
    log_start: np.ndarray, log_transition: np.ndarray, log_emission: np.ndarray
) -> tuple[np.ndarray, float]:
    """The most likely state path (T,) and its joint log-probability with the observations.
    Ties go to the lowest state index."""
    path, score = _viterbi(
        np.ascontiguousarray(log_start, dtype=np.float64),
        np.ascontiguousarray(log_transition, dtype=np.float64),
        np.ascontiguousarray(log_emission, dtype=np.float64),
    )
    return path, float(score)


@njit(cache=True)
def _trace(ring: np.ndarray, frame: int, state: int, until: int, out: np.ndarray) -> None:
    """Write the survivor of ``state`` at ``frame`` into out[u - until] for u in until..frame."""
    size = ring.shape[0]
    out[frame - until] = state
    for u in range(frame, until, -1):
        state = ring[u % size, state]
        out[u - 1 - until] = state


class ViterbiState(NamedTuple):
    """A ``FixedLagViterbi``'s arrays, which ``advance`` decodes on in place (N states).

    log_start (N,) and log_transition (N, N) are the model's; into_offsets (N + 1,) and
    into_states are ``predecessors(log_transition)``; delta (N,) holds each survivor's
    log-score at the last frame decoded (−inf: dropped); ring (size, N) the back-pointer
    of each state at frame u in row u mod size; position = [frames decoded, oldest
    uncommitted frame]; lag the most frames left uncommitted (no limit: int64 max)."""

    log_start: np.ndarray
    log_transition: np.ndarray
    into_offsets: np.ndarray
    into_states: np.ndarray
    delta: np.ndarray
    ring: np.ndarray
    position: np.ndarray
    lag: int


@njit(cache=True)
def _advance(
    decoder: ViterbiState,
    log_emission: np.ndarray,
    first_frame: int,
    oldest: int,
    committed: np.ndarray,
) -> tuple[int, int]:
    """Decode frames first_frame.. of ``log_emission``; returns (frames committed into
    ``committed``, the new oldest uncommitted frame)."""
    log_start, log_transition = decoder.log_start, decoder.log_transition
    into_offsets, into_states = decoder.into_offsets, decoder.into_states
    delta, ring, lag = decoder.delta, decoder.ring, decoder.lag
    states = delta.shape[0]
    size = ring.shape[0]
    count = 0
    scratch = np.empty(size, dtype=np.int64)
    fresh = np.empty(states)
    cursor = np.empty(states, dtype=np.int64)
    seen = np.full(states, -1, dtype=np.int64)
    stamp = 0
    for offset in range(log_emission.shape[0]):
        t = first_frame + offset
        if t == 0:
            delta[:] = log_start + log_emission[0]
        else:
            for j in range(states):  # the dense max over i, skipping log A[i, j] = −inf
                best = 0
                score = NEG_INF
                for k in range(into_offsets[j], into_offsets[j + 1]):
                    i = into_states[k]
                    candidate = delta[i] + log_transition[i, j]
                    if candidate > score:
                        score, best = candidate, i
                fresh[j] = score + log_emission[offset, j]
                ring[t % size, j] = best
            delta[:] = fresh
        # Merged survivors: the latest frame where every live path passes one state. The
        # distinct states the survivors pass at frame u are traced back one frame at a time.
        live = 0
        for j in range(states):
            if delta[j] > NEG_INF:
                cursor[live] = j
                live += 1
        for u in range(t, oldest - 1, -1):
            if live == 1:
                _trace(ring, u, cursor[0], oldest, scratch)
                for k in range(u - oldest + 1):
                    committed[count + k] = scratch[k]
                count += u - oldest + 1
                oldest = u + 1
                break
            if u > oldest:
                stamp += 1
                distinct = 0
                for k in range(live):
                    ancestor = ring[u % size, cursor[k]]
                    if seen[ancestor] != stamp:
                        seen[ancestor] = stamp
                        cursor[distinct] = ancestor
                        distinct += 1
                live = distinct
        if t - oldest >= lag and oldest <= t:
            _trace(ring, t, int(np.argmax(delta)), oldest, scratch)
            chosen = scratch[0]
            committed[count] = chosen
            count += 1
            for j in range(states):
                ancestor = j
                for u in range(t, oldest, -1):
                    ancestor = ring[u % size, ancestor]
                if ancestor != chosen:
                    delta[j] = NEG_INF
            oldest += 1
    return count, oldest


@njit(cache=True)
def advance(decoder: ViterbiState, log_emission: np.ndarray, committed: np.ndarray, at: int) -> int:
    """``FixedLagViterbi.push_into`` for compiled callers, on the arrays its ``reserve``
    returned: decodes the rows of ``log_emission`` as the frames after the ones decoded
    (``decoder.position`` updated), writes the states they commit into committed[at:] and
    returns how many."""
    position = decoder.position
    count, oldest = _advance(decoder, log_emission, position[0], position[1], committed[at:])
    position[0] += log_emission.shape[0]
    position[1] = oldest
    return count


def predecessors(log_transition: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The states i with log A[i, j] > −inf of each state j, in increasing order:
    into_states[into_offsets[j] : into_offsets[j + 1]]."""
    possible = log_transition.T > NEG_INF
    offsets = np.zeros(len(possible) + 1, dtype=np.int64)
    np.cumsum(possible.sum(axis=1), out=offsets[1:])
    return offsets, np.nonzero(possible)[1].astype(np.int64)


class FixedLagViterbi:
    """Streaming Viterbi decoding: ``push`` emission rows, get the states committed so far;
    ``finish`` commits the rest along the best survivor. ``lag`` None never forces a
    commit (states commit only where survivors merge, and at the end). Compiled callers
    decode on the arrays ``reserve`` returns, with ``advance``."""

    def __init__(
        self,
        log_start: np.ndarray,
        log_transition: np.ndarray,
        lag: int | None,
        into: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        """``into``: ``predecessors(log_transition)``, if the caller keeps it."""
        self.lag = lag
        log_start = np.ascontiguousarray(log_start, dtype=np.float64)
        log_transition = np.ascontiguousarray(log_transition, dtype=np.float64)
        into_offsets, into_states = into or predecessors(log_transition)
        states = len(log_start)
        self._state = ViterbiState(
            log_start=log_start,
            log_transition=log_transition,
            into_offsets=into_offsets,
            into_states=into_states,
            delta=np.full(states, NEG_INF),
            ring=np.zeros((2 if lag is None else lag + 2, states), np.int64),
            position=np.zeros(2, dtype=np.int64),
            lag=_NO_LAG if lag is None else lag,
        )

    @property
    def frames(self) -> int:
        """Frames decoded so far."""
        return int(self._state.position[0])

    @property
    def oldest(self) -> int:
        """The oldest frame not yet committed."""
        return int(self._state.position[1])

    def reserve(self, extra: int) -> ViterbiState:
        """Make room for ``extra`` more frames and return the arrays that ``advance``
        decodes them on in place (with no lag limit the ring grows, so the uncommitted
        frames never wrap); valid until the next ``reserve``."""
        if self.lag is None:
            frames, oldest, ring = self.frames, self.oldest, self._state.ring
            needed = frames + extra - oldest + 2
            if needed > len(ring):
                size = max(needed, 2 * len(ring))
                grown = np.zeros((size, ring.shape[1]), np.int64)
                for u in range(oldest, frames):
                    grown[u % size] = ring[u % len(ring)]
                self._state = self._state._replace(ring=grown)
        return self._state

    def push(self, log_emission: np.ndarray) -> np.ndarray:
        """Decode the next frames (m, N); the states committed by them, in frame order."""
        rows = np.ascontiguousarray(log_emission, dtype=np.float64)
        committed = np.empty(self.most_committed(len(rows)), dtype=np.int64)
        return committed[: self.push_into(rows, committed)].copy()

    def most_committed(self, frames: int) -> int:
        """The most states that pushing ``frames`` more frames can commit."""
        position = self._state.position
        return frames + int(position[0] - position[1]) + 1

    def push_into(self, log_emission: np.ndarray, out: np.ndarray) -> int:
        """``push`` for C-contiguous float64 rows (m, N), writing the committed states into
        ``out`` (room for ``most_committed(m)``); returns how many."""
        if len(log_emission) == 0:
            return 0
        return int(advance(self.reserve(len(log_emission)), log_emission, out, 0))

    def finish(self) -> np.ndarray:
        """Commit every remaining frame along the best survivor."""
        frames, oldest = self.frames, self.oldest
        if oldest >= frames:
            return np.zeros(0, dtype=np.int64)
        out = np.empty(frames - oldest, dtype=np.int64)
        state = self._state
        _trace(state.ring, frames - 1, int(np.argmax(state.delta)), oldest, out)
        state.position[1] = frames
        return out
