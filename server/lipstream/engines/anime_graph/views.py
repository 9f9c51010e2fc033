"""Graph views: the whole corpus, and each emotion's recordings on their own.

Sketch: in an expressive corpus each recording has one emotion, and much of
the face (brows, smile, squint) follows the emotion, not the phonemes. A span
spoken with an emotion (its own, else the request's) is searched in the view
holding only that emotion's recordings: the emotion joins the phoneme label
in the match criterion, so Theorem 1 still holds inside the view (the
paper's §8 leaves emotion to future work). A span without an emotion, or
with one the corpus never recorded, uses the whole corpus. Every view has
its own Anime Array, suffix automaton, clustered graph (k shared out in
proportion to the view's size), recorded neighbour pairs and stand-ins for
missing phonemes.

Node ids: an unclustered node is an anime, whose id is the same in every
view; a clustered node is a cluster of one view only. ``node_of`` maps an
anime to the node holding it in a view, so a search can continue across a
change of view (per-phoneme emotions).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ...errors import ModelStoreError
from ...phonemes import PHONEME_INDEX, PHONEMES, SILENCE
from ...visemes import get_scheme
from .blending import PairIndex
from .clustering import cluster_animes
from .graph import AnimeGraph, ClusterGraph, SearchGraph
from .index import SuffixIndex

WHOLE = "all"
VIEW_ARRAYS = (
    "members",
    "substitution",
    "index_transitions",
    "index_low",
    "index_high",
    "index_ends",
    "index_text_anime",
    "cluster_assignment",
    "cluster_representative",
)


@dataclass(frozen=True)
class GraphView:
    """The search structures over the animes ``members`` (ascending ids); ``cluster_of``
    (n_animes,) is each anime's node in ``cluster_graph``, -1 outside the view or without
    clusters."""

    name: str
    members: np.ndarray
    substitution: np.ndarray
    anime_graph: AnimeGraph
    index: SuffixIndex
    pairs: PairIndex
    cluster_graph: ClusterGraph | None
    cluster_of: np.ndarray

    @cached_property
    def label_of(self) -> dict[str, int]:
        """The label searched for each phoneme (``substitution``), by its name."""
        return {phoneme: int(self.substitution[index]) for phoneme, index in PHONEME_INDEX.items()}

    def holds(self, anime: int) -> bool:
        """Is ``anime`` one of the view's members?"""
        spot = int(np.searchsorted(self.members, anime))
        return spot < len(self.members) and int(self.members[spot]) == anime

    def node_of(self, anime: int, graph: SearchGraph) -> int | None:
        """The node of ``graph`` (this view's anime or cluster graph) that holds ``anime``;
        None when the anime is outside the view."""
        if graph is self.cluster_graph:
            node = int(self.cluster_of[anime])
            return node if node >= 0 else None
        return anime if self.holds(anime) else None


def view_members(
    emotion_of_utterance: Sequence[str], utterance: np.ndarray
) -> dict[str, np.ndarray]:
    """The whole corpus, plus one view per emotion when the corpus has more than one."""
    emotions = np.asarray(emotion_of_utterance)[utterance]
    views = {WHOLE: np.arange(len(utterance), dtype=np.int32)}
    names = sorted(set(emotion_of_utterance))
    if len(names) > 1:
        views |= {name: np.flatnonzero(emotions == name).astype(np.int32) for name in names}
    return views


def substitution_table(labels: np.ndarray) -> np.ndarray:
    """(n_phonemes,) the phoneme to search for each phoneme: itself when ``labels`` hold it,
    else the most frequent held phoneme of its (oculus15) viseme class, else silence, else the
    most frequent held phoneme."""
    counts = Counter(int(label) for label in labels)
    scheme = get_scheme("oculus15")
    table = np.arange(len(PHONEMES), dtype=np.int16)
    for phoneme, index in PHONEME_INDEX.items():
        if index in counts:
            continue
        kin = [PHONEME_INDEX[p] for p in scheme.members(scheme.viseme_of(phoneme))]
        present = [k for k in kin if k in counts]
        if present:
            table[index] = max(present, key=lambda k: (counts[k], -k))
        elif PHONEME_INDEX[SILENCE] in counts:
            table[index] = PHONEME_INDEX[SILENCE]
        else:
            table[index] = max(counts, key=lambda k: (counts[k], -k))
    return table


def fit_view(
    name: str,
    members: np.ndarray,
    labels: np.ndarray,
    utterance: np.ndarray,
    shapes: np.ndarray,
    clusters: int,
    seed: int,
) -> dict[str, np.ndarray]:
    """The stored arrays of one view, keys ``<name>_<array>``."""
    index = SuffixIndex.build(labels, utterance, len(PHONEMES), members)
    if clusters > 0:
        assignment, representative = cluster_animes(shapes[members], clusters, seed)
        representative = members[representative]
    else:
        assignment = representative = np.zeros(0, dtype=np.int32)
    arrays = {
        "members": members,
        "substitution": substitution_table(labels[members]),
        "index_transitions": index.transitions,
        "index_low": index.low,
        "index_high": index.high,
        "index_ends": index.ends,
        "index_text_anime": index.text_anime,
        "cluster_assignment": assignment,
        "cluster_representative": representative,
    }
    return {f"{name}_{key}": value for key, value in arrays.items()}


def load_view(
    name: str, arrays: Mapping[str, np.ndarray], labels: np.ndarray, successor: np.ndarray
) -> GraphView:
    """Rebuild a view from its stored arrays."""
    missing = [key for key in VIEW_ARRAYS if f"{name}_{key}" not in arrays]
    if missing:
        raise ModelStoreError(f"view {name!r} lacks arrays {missing}", where="arrays.npz")
    part = {key: np.asarray(arrays[f"{name}_{key}"]) for key in VIEW_ARRAYS}
    members = part["members"]
    cluster_graph = None
    assignment = np.full(len(labels), -1, dtype=np.int64)
    if len(part["cluster_representative"]):
        assignment[members] = part["cluster_assignment"]
        cluster_graph = ClusterGraph.build(
            assignment, part["cluster_representative"], labels, successor, len(PHONEMES)
        )
    return GraphView(
        name=name,
        members=members,
        substitution=part["substitution"],
        anime_graph=AnimeGraph.build(labels, successor, len(PHONEMES), members),
        index=SuffixIndex(
            arrays[f"{name}_index_transitions"],
            part["index_low"],
            part["index_high"],
            part["index_ends"],
            part["index_text_anime"],
        ),
        pairs=PairIndex.build(labels, successor, len(PHONEMES), members),
        cluster_graph=cluster_graph,
        cluster_of=assignment,
    )


def view_clusters(clusters: int, members: int, total: int) -> int:
    """k for a view of ``members`` of ``total`` animes, when the whole corpus gets ``clusters``."""
    if clusters == 0:
        return 0
    return max(1, round(clusters * members / max(total, 1)))
