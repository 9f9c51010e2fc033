"""Remapping the facial HMM to vocal outputs through its occupancy γ (Brand 1999, §4.3).

γ_{i,t} = P(state i | facial frame t) from the facial HMM's forward-backward on
the training curves weights every training frame's other signals:

- audio: each state gets a full-covariance Gaussian over the speech features
  (``lipstream.features.speech_features``: MFCC and log energy with deltas, one
  feature frame per HMM frame), mean Σγx/Σγ and covariance from the weighted
  scatter plus ``floor``·I (so a state seldom heard still has a proper density);
- phonemes: each state gets a categorical over the phoneme set, the γ-weighted
  counts of the aligned phoneme at each frame plus ``smoothing`` per phoneme;
- emotion: likewise a categorical over the emotions, from each line's label, so a
  request's emotion steers the face's expression as its phonemes steer the mouth.

The facial dynamics (start, transitions) are kept as they are: the vocal HMM has
the face's state machine, driven by voice, phonemes or both.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def vocal_gaussians(
    gammas: Sequence[np.ndarray], features: Sequence[np.ndarray], floor: float
) -> tuple[np.ndarray, np.ndarray]:
    """Means (N, F) and covariances (N, F, F) of each state's features."""
    gamma = np.concatenate(gammas)
    data = np.concatenate(features).astype(np.float64)
    weight = gamma.sum(axis=0)
    overall = data.mean(axis=0)
    means = np.where(
        weight[:, None] > 1e-8, (gamma.T @ data) / np.maximum(weight, 1e-300)[:, None], overall
    )
    dim = data.shape[1]
    covariances = np.empty((len(weight), dim, dim))
    global_cov = np.cov(data.T).reshape(dim, dim)
    for state in range(len(weight)):
        centred = data - means[state]
        scatter = (centred * gamma[:, state : state + 1]).T @ centred
        # A state heard for few frames leans on the pooled covariance (one frame's worth).
        covariances[state] = (scatter + global_cov) / (weight[state] + 1.0) + floor * np.eye(dim)
    return means, covariances


def phoneme_log_probabilities(
    gammas: Sequence[np.ndarray], labels: Sequence[np.ndarray], n_phonemes: int, smoothing: float
) -> np.ndarray:
    """log P(label | state), (N, n_labels), for per-frame labels (phonemes or emotions)."""
    gamma = np.concatenate(gammas)
    label = np.concatenate(labels)
    counts = np.zeros((gamma.shape[1], n_phonemes))
    np.add.at(counts.T, label, gamma)
    counts += smoothing
    return np.asarray(np.log(counts / counts.sum(axis=1, keepdims=True)))
