"""Mode selection (Lin et al., Eq. 10): the layered mode graph and what its costs read.

Layers are the phonemes of a window, nodes the candidate modes of each phoneme.
The cost of a path is E = w_c·E_c + w_s·E_s:

- E_c (node cost): the negative log-likelihood of the mode given its previous and
  next phoneme and the span's emotion, each from the training context counts with
  additive (Laplace) smoothing ``alpha`` over the phoneme's candidate modes, so a
  context never seen costs the same for every mode instead of infinity. A
  neighbour outside the window (not yet known) contributes nothing.
- E_s (edge cost): the C2 discontinuity at the join of consecutive animemes: the
  squared jumps of value, slope and curvature between A_a at local time 1 and A_b
  at 0, derivatives converted to real time and scaled by a reference phoneme
  duration so the three terms share units.

A dynamic programme over the layers (Viterbi in min-plus form) finds the same
optimum as A* on this graph; ties go to the lower mode index. Synthesis runs it
compiled (``kernels.choose_modes`` over ``numerics.layered``); this module keeps the
layer and cost records and the animemes' end derivatives. The same search written
plainly in numpy, E_c and E_s term by term, is the tests' oracle
(``tests/lipstream/engines/dam/reference.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .dominance import derivative_powers


@dataclass(frozen=True)
class Layer:
    """One phoneme of the window: candidate mode indices, duration (s), neighbour phonemes
    (-1: unknown) and emotion index (-1: none)."""

    candidates: np.ndarray
    duration: float
    previous: int
    following: int
    emotion: int


@dataclass(frozen=True)
class Costs:
    """Context counts and the animemes' end derivatives, read by the search."""

    previous: np.ndarray
    following: np.ndarray
    emotion: np.ndarray
    starts: np.ndarray  # (modes, 3, channels): A, A', A'' at local time 0
    ends: np.ndarray  # (modes, 3, channels): at local time 1
    reference_duration: float
    alpha: float
    w_context: float
    w_smooth: float


def end_derivatives(coefficients: np.ndarray, at: float) -> np.ndarray:
    """(modes, 3, channels): the value, first and second local-time derivative at ``at``."""
    degree = coefficients.shape[1] - 1
    rows = np.stack([derivative_powers(at, degree, order) for order in range(3)])
    return np.asarray(np.einsum("om,kmc->koc", rows, coefficients))
