"""Training the facial HMM: EM in log space, entropic (MAP) or conventional (Baum-Welch).

Sketch, in the style of hmmlearn's ``fit``: initialize a large fully connected
model (k-means means and covariances, every transition allowed), then alternate
the E-step (``trellis.forward_backward`` per sequence: γ, expected transition
counts, log-likelihood) and the M-step, recording the objective in a
``ConvergenceMonitor`` until its relative gain falls below ``tol``.

Objective: log P(X | θ) + log P(θ). Both estimators share a normalized
inverse-Wishart prior on each covariance, IW(K; Ψ, df) with df = d +
``PRIOR_FRAMES`` and Ψ = (df + d + 1) c diag(var), whose mode is c·var (c the
covariance floor, a share of each dimension's variance over all frames), so no
state collapses onto a point, a state seen for few frames keeps a broad
density, and models with different numbers of states compare fairly. The entropic
estimator adds Brand's prior −Z·H(θ): the transition rows and the start
distribution by ``entropic.entropic_map``, the covariances
K = (S + Ψ) / (n + Z + df + d + 1). Baum-Welch is Z = 0: normalized counts. Every M-step
maximizes the expected complete-data log-posterior exactly, so the objective
never decreases.

Extinction (entropic only): after the M-step, transitions meeting Brand's
criterion (``entropic.extinct``) are trimmed and their rows renormalized, then
states whose expected occupancy falls below ``min_occupancy`` frames (by default
d + 1, the fewest that support a full covariance), or that no transition or
start enters any more, are removed. The criterion is first
order, so a trim is kept only if the next E-step's log-posterior is no lower
than before it; otherwise the untrimmed M-step stands (it cannot be lower).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.special import multigammaln
from sklearn.cluster import KMeans

from ...numerics.trellis import forward_backward
from .entropic import entropic_map, extinct, objective
from .gaussian import Gaussians

ENTROPIC = "entropic"
BAUM_WELCH = "baum-welch"
ESTIMATORS = (ENTROPIC, BAUM_WELCH)
PRIOR_FRAMES = 10.0
KMEANS_FRAMES = 4000
_TINY = 1e-300


@dataclass(frozen=True)
class HmmParameters:
    """Start (N,) and transition (N, N) probabilities, and the Gaussian states."""

    start: np.ndarray
    transition: np.ndarray
    means: np.ndarray
    covariances: np.ndarray

    @property
    def n_states(self) -> int:
        return len(self.start)

    def gaussians(self) -> Gaussians:
        return Gaussians(self.means, self.covariances)

    def log_start(self) -> np.ndarray:
        return _log(self.start)

    def log_transition(self) -> np.ndarray:
        return _log(self.transition)


def _log(values: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return np.asarray(np.log(values))


@dataclass(frozen=True)
class Settings:
    """``estimator`` (entropic or baum-welch), prior scale ``z``, ``covariance_floor`` c
    (a share of each dimension's variance), ``min_occupancy`` (frames; None: d + 1) for a
    state to survive, iteration limit and tolerance."""

    n_states: int
    estimator: str = ENTROPIC
    z: float = 1.0
    covariance_floor: float = 0.05
    min_occupancy: float | None = None
    n_iter: int = 25
    tol: float = 1e-4
    seed: int = 0


@dataclass
class Statistics:
    """Expected sufficient statistics of one E-step."""

    log_likelihood: float
    entropy: float
    frames: int
    start: np.ndarray
    transitions: np.ndarray
    occupancy: np.ndarray
    sums: np.ndarray
    outer: np.ndarray
    gammas: list[np.ndarray]


@dataclass
class ConvergenceMonitor:
    """The objective after each iteration (hmmlearn's monitor); stops when the relative gain
    falls below ``tol`` or after ``n_iter`` iterations."""

    tol: float
    n_iter: int
    history: list[float] = field(default_factory=list)

    def report(self, value: float) -> None:
        self.history.append(value)

    @property
    def converged(self) -> bool:
        if len(self.history) > self.n_iter:
            return True
        if len(self.history) < 2:
            return False
        gain = self.history[-1] - self.history[-2]
        return gain <= self.tol * max(1.0, abs(self.history[-1]))


@dataclass
class FitResult:
    """The trained parameters, the objective per iteration, the last E-step's statistics."""

    parameters: HmmParameters
    history: list[float]
    statistics: Statistics
    trims_kept: int = 0
    trims_undone: int = 0


def initialize(
    sequences: Sequence[np.ndarray], n_states: int, floor: float, seed: int
) -> HmmParameters:
    """k-means means and covariances, a fully connected transition matrix, uniform start."""
    data = np.concatenate(sequences)
    rng = np.random.default_rng(seed)
    sample = data if len(data) <= KMEANS_FRAMES else data[rng.choice(len(data), KMEANS_FRAMES)]
    n_states = max(1, min(n_states, len(np.unique(sample, axis=0))))
    kmeans = KMeans(n_clusters=n_states, n_init=1, random_state=seed).fit(sample)
    labels = kmeans.labels_
    dim = data.shape[1]
    overall = np.cov(sample.T).reshape(dim, dim) + np.diag(floor * sample.var(axis=0) + 1e-12)
    covariances = np.empty((n_states, dim, dim))
    for state in range(n_states):
        members = sample[labels == state]
        if len(members) > dim:
            covariances[state] = np.cov(members.T) + np.diag(floor * sample.var(axis=0) + 1e-12)
        else:
            covariances[state] = overall
    stay = 0.5 if n_states > 1 else 1.0
    transition = np.full((n_states, n_states), (1.0 - stay) / max(1, n_states - 1))
    np.fill_diagonal(transition, stay)
    return HmmParameters(
        np.full(n_states, 1.0 / n_states), transition, kmeans.cluster_centers_, covariances
    )


def e_step(parameters: HmmParameters, sequences: Sequence[np.ndarray]) -> Statistics:
    """Posterior statistics of every sequence under ``parameters``."""
    n = parameters.n_states
    data = np.concatenate(sequences)
    log_density = parameters.gaussians().log_density(data)
    log_start = parameters.log_start()
    stats = Statistics(
        0.0,
        0.0,
        len(data),
        np.zeros(n),
        np.zeros((n, n)),
        np.zeros(n),
        np.zeros(0),
        np.zeros(0),
        [],
    )
    offset = 0
    for sequence in sequences:
        rows = log_density[offset : offset + len(sequence)]
        offset += len(sequence)
        posterior = forward_backward(log_start, parameters.transition, rows)
        stats.log_likelihood += posterior.log_likelihood
        stats.entropy += posterior.entropy
        stats.start += posterior.gamma[0]
        stats.transitions += posterior.transitions
        stats.gammas.append(posterior.gamma)
    gamma = np.concatenate(stats.gammas)
    stats.occupancy = gamma.sum(axis=0)
    stats.sums = gamma.T @ data
    stats.outer = np.stack([(data * gamma[:, state, None]).T @ data for state in range(n)])
    return stats


def log_prior(parameters: HmmParameters, settings: Settings, prior_scatter: np.ndarray) -> float:
    """log P(θ) up to a constant: the covariance prior, and −Z·H(θ) when entropic."""
    gaussians = parameters.gaussians()
    log_dets = gaussians.log_determinants()
    inverses = np.einsum("nki,nkj->nij", gaussians.whitening, gaussians.whitening)
    traces = np.einsum("nii,i->n", inverses, prior_scatter)
    dim = parameters.means.shape[1]
    df = dim + PRIOR_FRAMES
    normalizer = (
        0.5 * df * float(np.log(prior_scatter).sum())
        - 0.5 * df * dim * math.log(2.0)
        - float(multigammaln(0.5 * df, dim))
    )
    per_state = normalizer - 0.5 * (df + dim + 1.0) * log_dets - 0.5 * traces
    value = float(per_state.sum())
    if settings.estimator == ENTROPIC:
        z, dim = settings.z, parameters.means.shape[1]
        value += z * _neg_entropy(parameters.start) + z * _neg_entropy(parameters.transition)
        value -= z * float(np.sum(0.5 * (dim * math.log(2.0 * math.pi * math.e) + log_dets)))
    return value


def _neg_entropy(probabilities: np.ndarray) -> float:
    positive = probabilities[probabilities > 0.0]
    return float(np.sum(positive * np.log(positive)))


def m_step(
    parameters: HmmParameters, stats: Statistics, settings: Settings, prior_scatter: np.ndarray
) -> HmmParameters:
    """The parameters maximizing the expected complete-data log-posterior."""
    z = settings.z if settings.estimator == ENTROPIC else 0.0
    start = _multinomial(stats.start, parameters.start, z)
    transition = np.stack(
        [_multinomial(row, old, z) for row, old in zip(stats.transitions, parameters.transition)]
    )
    means = parameters.means.copy()
    covariances = parameters.covariances.copy()
    floor = np.diag(prior_scatter)
    for state, weight in enumerate(stats.occupancy):
        if weight > 1e-10:
            means[state] = stats.sums[state] / weight
        scatter = stats.outer[state] - weight * np.outer(means[state], means[state])
        scatter = 0.5 * (scatter + scatter.T)
        covariances[state] = (scatter + floor) / (weight + z + _prior_power(len(floor)))
    return HmmParameters(start, transition, means, covariances)


def _multinomial(counts: np.ndarray, old: np.ndarray, z: float) -> np.ndarray:
    """The row's MAP (z ≠ 0) or normalized counts; the old row where nothing was seen, and
    where the (exact) solve would lower the row's objective through round-off."""
    counts = np.where(old > 0.0, counts, 0.0)
    if not counts.sum() > 1e-12:
        return old
    fresh = entropic_map(counts, z) if z != 0.0 else counts / counts.sum()
    if objective(fresh, counts, z) < objective(old, counts, z):
        return old
    return fresh


def trim_transitions(parameters: HmmParameters, stats: Statistics, z: float) -> HmmParameters:
    """Brand's extinction of transitions; each trimmed row renormalized."""
    transition = parameters.transition.copy()
    for row in range(len(transition)):
        mask = extinct(transition[row], stats.transitions[row], z)
        if mask.any() and not mask.all():
            transition[row, mask] = 0.0
            transition[row] /= transition[row].sum()
    return replace(parameters, transition=transition)


def trim_states(
    parameters: HmmParameters, occupancy: np.ndarray, min_occupancy: float
) -> HmmParameters:
    """Remove the states occupied less than ``min_occupancy`` frames, and those no transition
    from another state (nor the start) enters."""
    transition = parameters.transition
    entered = (transition - np.diag(np.diag(transition))).sum(axis=0) > 0.0
    keep = (occupancy >= min_occupancy) & (entered | (parameters.start > 0.0))
    if not keep.any():
        keep[int(np.argmax(occupancy))] = True
    return parameters if keep.all() else _restrict(parameters, keep)


def _restrict(parameters: HmmParameters, keep: np.ndarray) -> HmmParameters:
    transition = parameters.transition[np.ix_(keep, keep)].copy()
    for row in range(len(transition)):
        total = transition[row].sum()
        if total > 0.0:
            transition[row] /= total
        else:
            transition[row, row] = 1.0
    start = parameters.start[keep]
    start = start / start.sum() if start.sum() > 0.0 else np.full(len(start), 1.0 / len(start))
    return HmmParameters(start, transition, parameters.means[keep], parameters.covariances[keep])


def min_occupancy(settings: Settings, parameters: HmmParameters) -> float:
    """Frames a state must explain to survive: ``settings.min_occupancy``, else d + 1 (enough
    to support its full covariance)."""
    if settings.min_occupancy is not None:
        return settings.min_occupancy
    return float(parameters.means.shape[1] + 1)


def objective_of(
    stats: Statistics, parameters: HmmParameters, settings: Settings, prior_scatter: np.ndarray
) -> float:
    return stats.log_likelihood + log_prior(parameters, settings, prior_scatter)


def prior_scatter_of(sequences: Sequence[np.ndarray], settings: Settings) -> np.ndarray:
    """diag Ψ = ν c var_d over all frames (d,)."""
    variance = np.concatenate(sequences).var(axis=0)
    power = _prior_power(len(variance))
    return np.asarray(power * settings.covariance_floor * np.maximum(variance, 1e-12))


def _prior_power(dim: int) -> float:
    """df + d + 1 of the inverse-Wishart prior (df = d + ``PRIOR_FRAMES``): the power of
    |K|^(−1/2) in its density, and the pseudo-frames the MAP covariance adds."""
    return 2.0 * dim + PRIOR_FRAMES + 1.0


def fit(
    sequences: Sequence[np.ndarray],
    settings: Settings,
    initial: HmmParameters | None = None,
) -> FitResult:
    """Train on ``sequences`` (each (T_k, d)) from ``initial`` (default: ``initialize``)."""
    parameters = initial or initialize(
        sequences, settings.n_states, settings.covariance_floor, settings.seed
    )
    psi = prior_scatter_of(sequences, settings)
    stats = e_step(parameters, sequences)
    monitor = ConvergenceMonitor(settings.tol, settings.n_iter)
    monitor.report(objective_of(stats, parameters, settings, psi))
    result = FitResult(parameters, monitor.history, stats)
    while not monitor.converged:
        updated = m_step(parameters, stats, settings, psi)
        candidate, fresh = updated, None
        if settings.estimator == ENTROPIC:
            thinned = trim_transitions(updated, stats, settings.z)
            trials = [trim_states(thinned, stats.occupancy, min_occupancy(settings, updated))]
            if trials[0] is not thinned:
                trials.append(thinned)
            for trial in trials:
                if trial is thinned and np.array_equal(trial.transition, updated.transition):
                    continue
                trial_stats = e_step(trial, sequences)
                value = objective_of(trial_stats, trial, settings, psi)
                if math.isfinite(value) and value >= monitor.history[-1]:
                    candidate, fresh = trial, trial_stats
                    result.trims_kept += 1
                    break
                result.trims_undone += 1
        if fresh is None:
            fresh = e_step(updated, sequences)
        value = objective_of(fresh, candidate, settings, psi)
        parameters, stats = candidate, fresh
        monitor.report(value)
    result.parameters, result.statistics = parameters, stats
    return result


def perplexity(parameters: HmmParameters, occupancy: np.ndarray) -> float:
    """Average branching factor 2^H of the state machine: the transition rows' entropy
    (bits) weighted by each state's share of the occupancy."""
    weights = occupancy / max(float(occupancy.sum()), _TINY)
    rows = parameters.transition
    with np.errstate(divide="ignore", invalid="ignore"):
        entropies = -np.where(rows > 0.0, rows * np.log2(rows), 0.0).sum(axis=1)
    return float(2.0 ** float(weights @ entropies))
