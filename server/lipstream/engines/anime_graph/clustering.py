"""Anime clustering (§5.3): K-means on duration-normalized motion fragments.

Sketch: every anime's fragment is resampled to a fixed number of poses and
flattened (``AnimeTable.shapes``); K-means with k clusters groups them, and
each cluster's representative is the member nearest its centroid (ties to
the lowest anime id). Clusters are numbered by their representative's anime
id, so the result does not depend on K-means' internal numbering.
"""

from __future__ import annotations

import warnings

import numpy as np
from sklearn.cluster import KMeans
from sklearn.exceptions import ConvergenceWarning


def cluster_animes(
    shapes: np.ndarray, k: int, seed: int, max_iter: int = 100
) -> tuple[np.ndarray, np.ndarray]:
    """Cluster ``shapes`` (n_animes, dim): (assignment (n_animes,), representative
    (n_clusters,)). Fewer than ``k`` clusters come back when there are fewer distinct
    fragments."""
    n_clusters = max(1, min(int(k), len(shapes)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        kmeans = KMeans(n_clusters=n_clusters, n_init=1, max_iter=max_iter, random_state=seed).fit(
            shapes
        )
    raw = kmeans.labels_.astype(np.int64)
    distance = np.linalg.norm(shapes - kmeans.cluster_centers_[raw], axis=1)
    order = np.lexsort((np.arange(len(raw)), distance, raw))
    used, first = np.unique(raw[order], return_index=True)
    representative = order[first]
    ranking = np.argsort(representative, kind="stable")
    renumber = np.full(n_clusters, -1, dtype=np.int64)
    renumber[used[ranking]] = np.arange(len(used))
    return renumber[raw].astype(np.int32), representative[ranking].astype(np.int32)
