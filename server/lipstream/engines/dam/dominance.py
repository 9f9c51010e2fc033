"""The dominance function of a DAM (Lin et al., Eq. 1) and the animeme polynomial.

A phoneme j spoken from s_j for d_j seconds has local time t_j = (t - s_j) / d_j.
Its dominance is 1 inside the phoneme and decays as a Gaussian outside:

    D(t) = exp(-g(t)^2 / (2 sigma^2 + eps)),   g(t) = t for t < 0, t - 1 for t > 1, else 0.

The animeme is a degree-M polynomial A(t) = sum_m a_m t^m. Outside [0, 1] it is
evaluated at the nearest end (t clamped to [0, 1]): the tail carries the mouth
shape the phoneme starts or ends with. Evaluating the polynomial at the raw t, as
Eq. 6 literally reads, lets t^4 grow in the tails, and the fit then relies on
neighbours cancelling each other's large tails (docs/explanation/engines/dam.md has the
measurement). ``reach`` is how far outside [0, 1]
(in local time) the dominance stays above a cut-off ``tol``.
"""

from __future__ import annotations

import numpy as np


def outside(u: np.ndarray) -> np.ndarray:
    """g(t): the distance of local time ``u`` outside [0, 1] (signed, 0 inside)."""
    return np.where(u < 0.0, u, np.where(u > 1.0, u - 1.0, 0.0))


def dominance(u: np.ndarray, sigma: np.ndarray, eps: float) -> np.ndarray:
    """D(u; sigma) of Eq. 1, elementwise (``sigma`` broadcasts against ``u``)."""
    gap = outside(u)
    return np.asarray(np.exp(-(gap * gap) / (2.0 * sigma * sigma + eps)))


def dominance_dsigma(u: np.ndarray, sigma: np.ndarray, eps: float) -> np.ndarray:
    """dD/dsigma = D * g^2 * 4 sigma / (2 sigma^2 + eps)^2 (the Jacobian of Eq. 8-9)."""
    gap2 = outside(u) ** 2
    width = 2.0 * sigma * sigma + eps
    return np.asarray(np.exp(-gap2 / width) * gap2 * 4.0 * sigma / (width * width))


def reach(sigma: np.ndarray, eps: float, tol: float) -> np.ndarray:
    """Local time outside [0, 1] within which D >= ``tol``."""
    return np.asarray(np.sqrt((2.0 * sigma * sigma + eps) * np.log(1.0 / tol)))


def powers(u: np.ndarray, degree: int) -> np.ndarray:
    """clamp(u, 0, 1)^m for m = 0..degree, shape (len(u), degree + 1)."""
    return np.asarray(np.vander(np.clip(u, 0.0, 1.0), degree + 1, increasing=True))


def derivative_powers(u: float, degree: int, order: int) -> np.ndarray:
    """d^order/du^order of u^m for m = 0..degree at one ``u``, shape (degree + 1,)."""
    row = np.zeros(degree + 1)
    for m in range(order, degree + 1):
        factor = 1.0
        for k in range(order):
            factor *= m - k
        row[m] = factor * u ** (m - order)
    return row
