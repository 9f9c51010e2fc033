"""The Anime Graph and the Anime Array, unclustered and clustered (§5.2-5.3).

Sketch: in the unclustered graph the nodes are the animes; each recording is
a linked list (edge A_i -> A_i+1) and the Anime Array lists the animes of each
phoneme. In the clustered graph a node is a K-means cluster of animes: it
shows its representative's motion, carries every member's label and audio
features, and keeps every member's edges, so its degree is usually above
one. Both expose the same queries to the searches (``SearchGraph``); all
arrays are CSR so they memory-map straight from the model store.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


def csr_offsets(keys: np.ndarray, n_keys: int) -> np.ndarray:
    """Offsets (n_keys + 1,) of rows sorted by ``keys``."""
    offsets = np.zeros(n_keys + 1, dtype=np.int64)
    np.cumsum(np.bincount(keys, minlength=n_keys), out=offsets[1:])
    return offsets


def _ranges(offsets: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For CSR ``offsets`` and chosen ``rows``: (row position of each item, item index)."""
    first = offsets[rows]
    counts = (offsets[rows + 1] - first).astype(np.int64)
    owner = np.repeat(np.arange(len(rows)), counts)
    starts = np.repeat(first - np.concatenate(([0], np.cumsum(counts)[:-1])), counts)
    return owner, starts + np.arange(int(counts.sum()))


def _distances(points: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Euclidean distance of each row of ``points`` (n, D) to its row of ``targets`` (n, D)
    or to one target (D,); einsum, not ``norm``, as it is several times faster here."""
    differences = points - targets
    return np.asarray(np.sqrt(np.einsum("ij,ij->i", differences, differences)))


class SearchGraph(Protocol):
    """What GreedyMatching and PQ-Matching need from a graph."""

    @property
    def n_nodes(self) -> int: ...

    def nodes_with_label(self, label: int) -> np.ndarray:
        """The Anime Array row of ``label``: node ids, ascending."""

    def successors_of(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every edge leaving ``nodes``: (position in ``nodes``, target node)."""

    def has_label(self, nodes: np.ndarray, label: int) -> np.ndarray:
        """(len(nodes),) bool: the node carries ``label``."""

    def edge_list(self) -> tuple[np.ndarray, np.ndarray]:
        """Every edge among the graph's nodes: (sources, targets)."""

    def label_pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every node's (label, member anime) pairs, by node then label then anime: offsets
        (n_nodes + 1,) over labels (P,) and members (P,)."""

    def is_edge(self, sources: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """Elementwise: is there an edge sources[i] -> targets[i]?"""

    def motion_of(self, nodes: np.ndarray) -> np.ndarray:
        """The anime whose motion each node shows."""

    def audio_costs(
        self, nodes: np.ndarray, label: int, summary: np.ndarray, summaries: np.ndarray
    ) -> np.ndarray:
        """Distance from a query phoneme's audio ``summary`` (D,) to each node's audio for
        ``label``, given the per-anime ``summaries`` (n_animes, D)."""

    def audio_costs_at(
        self, nodes: np.ndarray, labels: np.ndarray, targets: np.ndarray, summaries: np.ndarray
    ) -> np.ndarray:
        """Elementwise ``audio_costs``: node i's audio for labels[i] against targets[i]
        ((len(nodes), D), or one (D,) summary for all)."""


@dataclass(frozen=True)
class AnimeGraph:
    """Unclustered: node = anime. ``labels`` (n,), ``successor`` (n,) (-1 at the end of a
    recording), Anime Array ``label_offsets`` (n_labels + 1,) over ``label_nodes`` (n,)."""

    labels: np.ndarray
    successor: np.ndarray
    label_offsets: np.ndarray
    label_nodes: np.ndarray

    @classmethod
    def build(
        cls,
        labels: np.ndarray,
        successor: np.ndarray,
        n_labels: int,
        members: np.ndarray | None = None,
    ) -> AnimeGraph:
        """The graph over ``members`` (anime ids, ascending; default all). Recordings lie
        wholly inside or outside the members, so edges need no filtering."""
        chosen = np.arange(len(labels)) if members is None else np.asarray(members)
        keys = np.asarray(labels, dtype=np.int64)[chosen]
        order = chosen[np.argsort(keys, kind="stable")].astype(np.int32)
        return cls(
            np.asarray(labels),
            np.asarray(successor, dtype=np.int32),
            csr_offsets(keys, n_labels),
            order,
        )

    @property
    def n_nodes(self) -> int:
        return len(self.labels)

    def nodes_with_label(self, label: int) -> np.ndarray:
        return self.label_nodes[self.label_offsets[label] : self.label_offsets[label + 1]]

    def successors_of(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        following = self.successor[nodes]
        present = np.flatnonzero(following >= 0)
        return present, following[present]

    def has_label(self, nodes: np.ndarray, label: int) -> np.ndarray:
        return np.asarray(self.labels[nodes] == label)

    def edge_list(self) -> tuple[np.ndarray, np.ndarray]:
        sources = np.sort(self.label_nodes)
        sources = sources[self.successor[sources] >= 0]
        return sources, self.successor[sources]

    def label_pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        members = np.sort(self.label_nodes).astype(np.int64)
        return csr_offsets(members, self.n_nodes), np.asarray(self.labels)[members], members

    def is_edge(self, sources: np.ndarray, targets: np.ndarray) -> np.ndarray:
        return np.asarray(self.successor[sources] == targets)

    def motion_of(self, nodes: np.ndarray) -> np.ndarray:
        return np.asarray(nodes)

    def audio_costs(
        self, nodes: np.ndarray, label: int, summary: np.ndarray, summaries: np.ndarray
    ) -> np.ndarray:
        return self.audio_costs_at(nodes, np.full(len(nodes), label), summary, summaries)

    def audio_costs_at(
        self, nodes: np.ndarray, labels: np.ndarray, targets: np.ndarray, summaries: np.ndarray
    ) -> np.ndarray:
        return _distances(summaries[nodes], np.asarray(targets))


@dataclass(frozen=True)
class ClusterGraph:
    """Clustered: node = cluster of animes (n_clusters = k).

    ``representative`` (k,) anime whose motion the node shows; ``entry_offsets``
    (k * n_labels + 1,) over ``entry_members`` (n_members,): the members of node c with
    label a are entry (c * n_labels + a); ``edge_offsets`` (k + 1,) over ``edge_targets``
    (E,), sorted, and ``edge_keys`` (E,) = source * k + target, ascending;
    ``label_offsets`` (n_labels + 1,) over ``label_nodes``: the Anime Array.
    """

    representative: np.ndarray
    entry_offsets: np.ndarray
    entry_members: np.ndarray
    edge_offsets: np.ndarray
    edge_targets: np.ndarray
    edge_keys: np.ndarray
    label_offsets: np.ndarray
    label_nodes: np.ndarray

    @classmethod
    def build(
        cls,
        assignment: np.ndarray,
        representative: np.ndarray,
        labels: np.ndarray,
        successor: np.ndarray,
        n_labels: int,
    ) -> ClusterGraph:
        """Merge animes by ``assignment`` (n_animes,) into clusters 0..k-1; animes assigned
        -1 stay out of the graph."""
        k = len(representative)
        inside = np.flatnonzero(assignment >= 0)
        entry = assignment[inside].astype(np.int64) * n_labels + labels[inside].astype(np.int64)
        members = inside[np.lexsort((inside, entry))].astype(np.int32)
        linked = inside[successor[inside] >= 0]
        linked = linked[assignment[successor[linked]] >= 0]
        edges = np.unique(assignment[linked].astype(np.int64) * k + assignment[successor[linked]])
        pairs = np.unique(entry)
        return cls(
            representative=np.asarray(representative, dtype=np.int32),
            entry_offsets=csr_offsets(entry, k * n_labels),
            entry_members=members,
            edge_offsets=csr_offsets(edges // k, k),
            edge_targets=(edges % k).astype(np.int32),
            edge_keys=edges,
            label_offsets=csr_offsets(pairs % n_labels, n_labels),
            label_nodes=(pairs[np.argsort(pairs % n_labels, kind="stable")] // n_labels).astype(
                np.int32
            ),
        )

    @property
    def n_nodes(self) -> int:
        return len(self.representative)

    @property
    def n_labels(self) -> int:
        return (len(self.entry_offsets) - 1) // self.n_nodes

    def members(self, node: int, label: int) -> np.ndarray:
        entry = node * self.n_labels + label
        return self.entry_members[self.entry_offsets[entry] : self.entry_offsets[entry + 1]]

    def degree(self) -> np.ndarray:
        """Out-degree of every node, (k,)."""
        return np.diff(self.edge_offsets)

    def nodes_with_label(self, label: int) -> np.ndarray:
        return self.label_nodes[self.label_offsets[label] : self.label_offsets[label + 1]]

    def successors_of(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        owner, items = _ranges(self.edge_offsets, np.asarray(nodes, dtype=np.int64))
        return owner, self.edge_targets[items]

    def has_label(self, nodes: np.ndarray, label: int) -> np.ndarray:
        entry = np.asarray(nodes, dtype=np.int64) * self.n_labels + label
        return np.asarray(self.entry_offsets[entry + 1] > self.entry_offsets[entry])

    def edge_list(self) -> tuple[np.ndarray, np.ndarray]:
        return self.edge_keys // self.n_nodes, self.edge_keys % self.n_nodes

    def label_pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        counts = np.diff(self.entry_offsets)
        labels = np.repeat(np.tile(np.arange(self.n_labels), self.n_nodes), counts)
        offsets = np.ascontiguousarray(self.entry_offsets[:: self.n_labels])
        return offsets, labels, self.entry_members

    def is_edge(self, sources: np.ndarray, targets: np.ndarray) -> np.ndarray:
        keys = np.asarray(sources, dtype=np.int64) * self.n_nodes + np.asarray(targets)
        spots = np.minimum(np.searchsorted(self.edge_keys, keys), len(self.edge_keys) - 1)
        return (
            np.asarray(self.edge_keys[spots] == keys)
            if len(self.edge_keys)
            else np.zeros(np.shape(keys), dtype=bool)
        )

    def motion_of(self, nodes: np.ndarray) -> np.ndarray:
        return np.asarray(self.representative[nodes])

    def audio_costs(
        self, nodes: np.ndarray, label: int, summary: np.ndarray, summaries: np.ndarray
    ) -> np.ndarray:
        return self.audio_costs_at(nodes, np.full(len(nodes), label), summary, summaries)

    def audio_costs_at(
        self, nodes: np.ndarray, labels: np.ndarray, targets: np.ndarray, summaries: np.ndarray
    ) -> np.ndarray:
        entries = np.asarray(nodes, dtype=np.int64) * self.n_labels + labels
        owner, items = _ranges(self.entry_offsets, entries)
        targets = np.asarray(targets)
        rows = targets if targets.ndim == 1 else np.take(targets, owner, axis=0)
        distances = _distances(np.take(summaries, self.entry_members[items], axis=0), rows)
        counts = self.entry_offsets[entries + 1] - self.entry_offsets[entries]
        present = counts > 0
        costs = np.full(len(entries), np.inf)
        if len(distances):
            heads = (np.cumsum(counts) - counts)[present]
            costs[present] = np.minimum.reduceat(distances, heads)
        return costs
