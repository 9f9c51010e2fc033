"""Entropic MAP estimation (Brand 1999, §4.2 and "Structure learning in conditional
probability models via an entropic prior and parameter extinction").

Prior P_e(θ) ∝ exp(−Z·H(θ)); Z = 1 is the paper's entropic prior, Z < 0 would
favour high entropy. For a multinomial with evidence ω (expected counts) the
log-posterior is

    F(θ) = Σ_i ω_i log θ_i + Z Σ_i θ_i log θ_i,     Σ_i θ_i = 1.

Setting the Lagrangian's gradient to zero gives, for each i with ω_i > 0,
θ_i = ω_i / (Z v_i) where v_i solves v − log v = −log(ω_i / Z) − 1 − λ / Z,
that is v_i = −W(−e^{−c_i}) with Lambert's W: branch −1 (v > 1) or branch 0
(v < 1) for Z > 0, and for Z < 0 θ_i = ω_i / (|Z| q_i) with q_i = W₀(e^{c'_i})
(unique, the posterior is concave). The multiplier λ is found by a bracketed
root search on Σθ(λ) = 1, which stays stable when the evidence is small
(Brand's alternating fixed point on λ can oscillate there). For Z > 0 the
maximum puts every θ on branch −1 except possibly the one with the largest
evidence; both families are solved and the better F kept. Entries with ω_i = 0
get θ_i = 0 (Z > 0: the prior alone pushes them out). Large arguments use
the asymptotic solution of v − log v = c refined by Newton steps, since
e^{−c} underflows.

Gaussian terms: with the entropy ½ log((2πe)^d |K|) in the prior, the MAP
covariance from a weighted scatter S of total weight n is K = S / (n + Z).

Extinction: a transition θ_ij is trimmed when the prior gains more than the
likelihood loses by zeroing it, to first order ω_ij / θ_ij < −Z log θ_ij
(Brand's criterion, ``extinct``); the row is renormalized.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq
from scipy.special import lambertw

_ASYMPTOTIC = 600.0
_NEAR_BRANCH = 1e-8
_NO_EVIDENCE = 1e-200  # evidence below this counts as none (its logarithm would underflow)


def _v_above_one(c: np.ndarray) -> np.ndarray:
    """v > 1 with v − log v = c (c ≥ 1): −W₋₁(−e^{−c})."""
    c = np.maximum(c, 1.0)
    v = 1.0 + np.sqrt(2.0 * (c - 1.0))  # the series at the branch point, where W is NaN
    regular = (c - 1.0 > _NEAR_BRANCH) & (c < _ASYMPTOTIC)
    v[regular] = -np.real(lambertw(-np.exp(-c[regular]), -1))
    big = c >= _ASYMPTOTIC
    if big.any():
        guess = c[big] + np.log(c[big])
        for _ in range(4):
            guess -= (guess - np.log(guess) - c[big]) / (1.0 - 1.0 / guess)
        v[big] = guess
    return np.maximum(v, 1.0)


def _v_below_one(c: float) -> float:
    """v in (0, 1] with v − log v = c (c ≥ 1): −W₀(−e^{−c})."""
    c = max(c, 1.0)
    if c - 1.0 <= _NEAR_BRANCH:
        return max(1.0 - math.sqrt(2.0 * (c - 1.0)), 1e-300)
    if c >= _ASYMPTOTIC:
        return math.exp(-c)
    return float(max(-np.real(lambertw(-math.exp(-c), 0)), 1e-300))


def objective(theta: np.ndarray, omega: np.ndarray, z: float) -> float:
    """F(θ) above (0 log 0 = 0; −inf where θ_i = 0 < ω_i)."""
    theta = np.asarray(theta, dtype=np.float64)
    omega = np.asarray(omega, dtype=np.float64)
    if np.any((theta <= 0.0) & (omega > 0.0)):
        return -math.inf
    positive = theta > 0.0
    logs = np.log(theta[positive])
    return float(omega[positive] @ logs + z * (theta[positive] @ logs))


def entropic_map(omega: np.ndarray, z: float = 1.0) -> np.ndarray:
    """The multinomial maximizing F for evidence ``omega`` (≥ 0, not all 0) and scale z."""
    omega = np.asarray(omega, dtype=np.float64)
    if np.any(omega < 0.0) or not np.any(omega > _NO_EVIDENCE):
        raise ValueError("evidence must be non-negative with a positive entry")
    if z == 0.0:
        return np.asarray(omega / omega.sum())
    theta = np.zeros_like(omega)
    support = np.flatnonzero(omega > _NO_EVIDENCE)
    if len(support) == 1:
        theta[support] = 1.0
        return theta
    w = omega[support]
    if z < 0.0:
        theta[support] = _concave(w, -z)
    else:
        theta[support] = _entropic(w, z)
    return np.asarray(theta / theta.sum())


def _concave(w: np.ndarray, scale: float) -> np.ndarray:
    """Z = −scale < 0: θ_i = w_i / (scale q_i), q + log q = log(w_i/scale) + 1 − λ/scale."""
    base = np.log(w / scale) + 1.0

    def theta(mu: float) -> np.ndarray:
        arg = base - mu
        q = np.where(
            arg < _ASYMPTOTIC,
            np.real(lambertw(np.exp(np.minimum(arg, _ASYMPTOTIC)), 0)),
            arg - np.log(np.maximum(arg, 1.0)),
        )
        return np.asarray(w / (scale * np.maximum(q, 1e-300)))

    def gap(mu: float) -> float:
        return float(theta(mu).sum() - 1.0)

    low, high = -1.0, 1.0
    while gap(low) > 0.0:
        low *= 2.0
    while gap(high) < 0.0:
        high *= 2.0
    return theta(brentq(gap, low, high, xtol=1e-13, maxiter=200))


def _entropic(w: np.ndarray, z: float) -> np.ndarray:
    """Z > 0: the better of the stationary families (all on branch −1; the largest on 0)."""
    a = -np.log(w / z) - 1.0  # c_i = a_i − λ/z, need c_i ≥ 1
    mu_max = float(a.min() - 1.0)  # μ = λ/z
    top = int(np.argmax(w))

    def family(mu: float, flip: bool) -> np.ndarray:
        v = _v_above_one(a - mu)
        if flip:
            v[top] = _v_below_one(float(a[top] - mu))
        return np.asarray(w / (z * v))

    candidates = []
    for flip in (False, True):

        def gap(mu: float, flip: bool = flip) -> float:
            return float(family(mu, flip).sum() - 1.0)

        at_max = gap(mu_max)
        if abs(at_max) < 1e-15:
            candidates.append(family(mu_max, flip))
            continue
        if (at_max > 0.0) == flip:
            continue  # this family's sum never crosses 1 below μ_max
        low = mu_max - 1.0
        while (gap(low) > 0.0) != flip:
            low = mu_max - 2.0 * (mu_max - low)
            if mu_max - low > 1e6:
                break
        else:
            root = brentq(gap, low, mu_max, xtol=1e-13, maxiter=200)
            candidates.append(family(root, flip))
    if not candidates:
        return np.asarray(w / w.sum())
    return max(candidates, key=lambda theta: objective(theta / theta.sum(), w, z))


def extinct(theta: np.ndarray, omega: np.ndarray, z: float) -> np.ndarray:
    """Mask of the entries Brand's criterion trims: 0 < θ_i with ω_i / θ_i < −Z log θ_i."""
    theta = np.asarray(theta, dtype=np.float64)
    mask = np.zeros(theta.shape, dtype=bool)
    if z <= 0.0:
        return mask
    positive = theta > 0.0
    mask[positive] = omega[positive] / theta[positive] < -z * np.log(theta[positive])
    return mask


def map_covariance(scatter: np.ndarray, weight: float, z: float) -> np.ndarray:
    """The MAP covariance under the entropic prior: scatter / (weight + Z)."""
    return np.asarray(scatter / max(weight + z, 1e-12))
