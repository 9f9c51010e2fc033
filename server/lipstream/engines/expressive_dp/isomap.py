"""The phoneme-Isomap (§IV–V): 2D maps of phoneme clusters, picking, highlights.

Method. At training, each phoneme's cluster (the frames of all its nodes, in the
motion basis) is embedded in 2D by Isomap (scikit-learn, 12 neighbours). The
geodesic eigenproblem is dense in the number of points, so Isomap is fitted on
at most ``LANDMARKS`` frames taken evenly through the cluster, and every frame
is then placed by Isomap's own out-of-sample ``transform`` (its geodesic
distances through the landmarks' graph). Clusters too small for a neighbour
graph (< 4 frames) lie on their first two basis coefficients. The 2D points are
stored, one per frame, beside the node frames.

At serving time a phoneme's map is Delaunay-triangulated (scipy.spatial) on
first use, under a lock. Picking a point returns the barycentric blend of the
three frames of its triangle (the exact frame at a vertex, a convex blend
inside); a point outside the map takes the nearest frame. Nodes are the
trajectories of their frames through the map. For a constrained phoneme with
relative time t_c and triphone context, the *time-correct* frames are each
node's frame interpolated at t_c (placed on the map the same way), and the
*context-correct* nodes those of the same triphone.
"""

from __future__ import annotations

import threading
import warnings
from dataclasses import dataclass

import numpy as np
from scipy.spatial import Delaunay, QhullError
from sklearn.manifold import Isomap

from ...phonemes import PHONEMES
from .nodes import NodeDatabase, warp_node

NEIGHBOURS = 12
LANDMARKS = 200
MIN_EMBEDDED = 4


def fit_maps(nodes: NodeDatabase) -> np.ndarray:
    """The 2D point of every frame of ``nodes``, (F, 2)."""
    points = np.zeros((len(nodes.frames), 2))
    frame_phoneme = np.repeat(nodes.phoneme, np.diff(nodes.offsets))
    for phoneme in np.unique(nodes.phoneme):
        rows = np.flatnonzero(frame_phoneme == phoneme)
        points[rows] = embed(nodes.frames[rows])
    return points


def embed(frames: np.ndarray) -> np.ndarray:
    """One cluster's frames (m, K) in 2D."""
    m = len(frames)
    flat = np.zeros((m, 2))
    flat[:, : min(2, frames.shape[1])] = frames[:, :2]
    if m < MIN_EMBEDDED:
        return flat
    landmarks = frames[np.unique(np.linspace(0, m - 1, min(m, LANDMARKS)).round().astype(int))]
    isomap = Isomap(n_neighbors=min(NEIGHBOURS, len(landmarks) - 1), n_components=2)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            isomap.fit(landmarks)
            placed = np.asarray(isomap.transform(frames))
    except (ValueError, np.linalg.LinAlgError):
        return flat
    return placed if np.isfinite(placed).all() else flat


@dataclass(frozen=True)
class Pick:
    """A picked point: the blended ``frame`` (K,), the ``vertices`` (global frame indices)
    and barycentric ``weights`` it blends, and whether the point was ``inside`` the map."""

    frame: np.ndarray
    vertices: np.ndarray
    weights: np.ndarray
    inside: bool


class PhonemeMaps:
    """The maps of one model: per phoneme, its frames' points and their triangulation."""

    def __init__(self, nodes: NodeDatabase, points: np.ndarray) -> None:
        self.nodes = nodes
        self.points = points
        self.frame_node = nodes.frame_nodes()
        frame_phoneme = np.repeat(nodes.phoneme, np.diff(nodes.offsets))
        self.rows = {int(p): np.flatnonzero(frame_phoneme == p) for p in np.unique(nodes.phoneme)}
        self._triangulations: dict[int, Delaunay | None] = {}
        self._lock = threading.Lock()

    def phoneme_rows(self, phoneme: int) -> np.ndarray:
        """The global frame indices of ``phoneme``'s cluster (empty when it has no node)."""
        return self.rows.get(phoneme, np.zeros(0, dtype=np.int64))

    def triangulation(self, phoneme: int) -> Delaunay | None:
        with self._lock:
            if phoneme not in self._triangulations:
                rows = self.phoneme_rows(phoneme)
                try:
                    found = Delaunay(self.points[rows]) if len(rows) >= 3 else None
                except QhullError:
                    found = None
                self._triangulations[phoneme] = found
            return self._triangulations[phoneme]

    def pick(self, phoneme: int, x: float, y: float) -> Pick:
        rows = self.phoneme_rows(phoneme)
        point = np.array([x, y])
        triangulation = self.triangulation(phoneme)
        if triangulation is not None:
            simplex = int(triangulation.find_simplex(point))
            if simplex >= 0:
                transform = triangulation.transform[simplex]
                partial = transform[:2] @ (point - transform[2])
                weights = np.clip(np.append(partial, 1.0 - partial.sum()), 0.0, 1.0)
                weights /= weights.sum()
                vertices = rows[triangulation.simplices[simplex]]
                frame = weights @ self.nodes.frames[vertices]
                return Pick(frame, vertices, weights, True)
        nearest = rows[int(np.argmin(np.linalg.norm(self.points[rows] - point, axis=1)))]
        return Pick(self.nodes.frames[nearest].copy(), np.array([nearest]), np.ones(1), False)

    def phoneme_nodes(self, phoneme: int) -> np.ndarray:
        return np.flatnonzero(self.nodes.phoneme == phoneme)

    def trajectory(self, node: int) -> np.ndarray:
        """The map points of ``node``'s frames, in order, (n, 2)."""
        return np.asarray(self.points[self.nodes.offsets[node] : self.nodes.offsets[node + 1]])

    def time_correct(self, phoneme: int, relative: float) -> tuple[np.ndarray, np.ndarray]:
        """Each node of ``phoneme`` and its point interpolated at relative time ``relative``."""
        members = self.phoneme_nodes(phoneme)
        placed = np.array(
            [warp_node(self.trajectory(int(node)), np.array([relative]))[0] for node in members]
        ).reshape(-1, 2)
        return members, placed

    def context_correct(self, phoneme: int, previous: int, following: int) -> np.ndarray:
        """The nodes of ``phoneme`` with the triphone context (previous, phoneme, following)."""
        nodes = self.nodes
        return np.flatnonzero(
            (nodes.phoneme == phoneme) & (nodes.previous == previous) & (nodes.next == following)
        )


def phoneme_label(index: int) -> str:
    return PHONEMES[index]
