"""Truncated evaluation of Eq. 2 and the lookahead that bounds its error.

Eq. 2 sums every phoneme's D·A over the whole utterance. Streaming cannot wait
for the whole utterance, so the sum a frame sees is cut twice:

- by dominance: a phoneme contributes only where D >= ``tol`` (its reach);
- by phoneme count: a frame inside span i takes the phonemes i - behind .. i + ahead.

The sums run over motion-basis components; errors are measured in channels.

Both cuts are part of the model, so streaming and offline synthesis compute the
same truncated sum. ``truncation_errors`` measures, on the training utterances
with their fitted modes, the largest error of the cut sum against the sum cut
by dominance alone, per channel and relative to the channel's range;
``choose_tail`` takes the fewest phonemes for which that error stays below the
bound (1 % by default), and that count is the lookahead.
"""

from __future__ import annotations

import numpy as np

from ...numerics.basis import MotionBasis
from .dominance import dominance, powers
from .em import Settings, pairs
from .modes import Occurrences

MAX_TAIL = 12


def owners(occurrences: Occurrences, n_rows: int) -> np.ndarray:
    """For each stacked frame row, the index of the occurrence (span) containing it: the
    first span of its utterance that ends after the frame's time (the last one at the end)."""
    owner = np.empty(n_rows, dtype=np.int64)
    for first in np.unique(occurrences.first_row):
        members = np.flatnonzero(occurrences.first_row == first)
        rows = int(occurrences.rows[members[0]])
        ends = occurrences.start[members] + occurrences.duration[members]
        times = np.arange(rows) / occurrences.fps
        inside = np.minimum(np.searchsorted(ends, times, side="right"), len(members) - 1)
        owner[first : first + rows] = members[inside]
    return owner


def truncated_sum(
    occurrences: Occurrences,
    mode: np.ndarray,
    sigma: np.ndarray,
    coefficients: np.ndarray,
    n_rows: int,
    s: Settings,
    window: tuple[int, int] | None,
) -> np.ndarray:
    """Eq. 2 on the stacked frames, cut by dominance and, when ``window`` = (behind, ahead)
    is given, by phoneme count."""
    found = pairs(occurrences, sigma, mode, s)
    keep = np.ones(len(found.row), dtype=bool)
    if window is not None:
        offset = found.occurrence - owners(occurrences, n_rows)[found.row]
        keep = (offset >= -window[0]) & (offset <= window[1])
    modes_of_pairs = mode[found.occurrence[keep]]
    local = found.local[keep]
    weight = dominance(local, sigma[modes_of_pairs], s.eps)
    animeme = np.einsum("pm,pmc->pc", powers(local, s.degree), coefficients[modes_of_pairs])
    total = np.zeros((n_rows, coefficients.shape[2]))
    np.add.at(total, found.row[keep], weight[:, None] * animeme)
    return total


def truncation_errors(
    occurrences: Occurrences,
    mode: np.ndarray,
    sigma: np.ndarray,
    coefficients: np.ndarray,
    basis: MotionBasis,
    frames: np.ndarray,
    s: Settings,
    window: tuple[int, int],
) -> np.ndarray:
    """Per channel, the largest |cut - uncut| over the training ``frames`` (channels; the
    model sums in ``basis`` components) over the channel's range in those frames."""
    args = (occurrences, mode, sigma, coefficients, len(frames), s)
    difference = truncated_sum(*args, window) - truncated_sum(*args, None)
    error = np.abs(difference @ basis.components).max(axis=0)
    span = np.maximum(frames.max(axis=0) - frames.min(axis=0), 1e-9)
    return np.asarray(error / span)


def choose_tail(
    occurrences: Occurrences,
    mode: np.ndarray,
    sigma: np.ndarray,
    coefficients: np.ndarray,
    basis: MotionBasis,
    frames: np.ndarray,
    s: Settings,
    bound: float,
) -> tuple[int, float]:
    """The fewest phonemes each side whose cut keeps every channel's error below ``bound``
    (capped at MAX_TAIL), and that error."""
    error = 0.0
    for tail in range(MAX_TAIL + 1):
        error = float(
            truncation_errors(
                occurrences, mode, sigma, coefficients, basis, frames, s, (tail, tail)
            ).max()
        )
        if error < bound:
            return tail, error
    return MAX_TAIL, error
