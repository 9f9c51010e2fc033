"""The motion-node database (Deng & Neumann §III): phoneme segments of the motion basis.

Method: every training utterance is projected on the motion basis; each
non-silence phone span becomes a node holding the basis frames from the frame
at or before its start to the frame at or after its end, its phoneme, its
utterance's emotion, its triphone context (the phonemes before and after,
``sil`` at the edges) and its captured neighbours: ``pre`` is the node of the
span just before in the same utterance, ``suc`` the one just after (-1 when
there is none). A silence span splits the sentence: it makes no node, and the
nodes on either side are not linked. A node's frames are spread evenly over
its phoneme's relative time [0, 1] (frame r of n at r / (n - 1)); the frames of
every node of one phoneme make that phoneme's cluster (``isomap``).

Derived at load and never stored: each node's viseme (the 15 classes of
``visemes.DENG15``), its boundary features (first and last position, first and
last velocity per second) and its shape: the node resampled to ``SHAPE_POINTS``
points, kept as the two halves of the direct smoothing cost's blend (``costs``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ...model_checks import ArrayReader
from ...numerics.basis import MotionBasis
from ...numerics.resample import sample_curves
from ...phonemes import PHONEME_INDEX, PHONEMES, SILENCE
from ...timeline import EMOTION_INDEX, EMOTIONS
from ...visemes import DENG15

SHAPE_POINTS = 6
SILENCE_INDEX = PHONEME_INDEX[SILENCE]
VISEME_OF_PHONEME = np.array([DENG15.index_of(phoneme) for phoneme in PHONEMES], dtype=np.int64)
STORED = (
    "node_phoneme",
    "node_emotion",
    "node_previous",
    "node_next",
    "node_pre",
    "node_suc",
    "node_offsets",
    "node_frames",
)


@dataclass(frozen=True)
class NodeDatabase:
    """Per node (N): ``phoneme``, ``emotion``, triphone context ``previous`` / ``next``
    (phoneme indices), captured neighbours ``pre`` / ``suc`` (node ids, -1 for none) and
    ``offsets`` (N + 1) into ``frames`` (F, K): the basis coefficients of every node's
    frames, node after node. ``fps`` is the rate the frames were recorded at."""

    phoneme: np.ndarray
    emotion: np.ndarray
    previous: np.ndarray
    next: np.ndarray
    pre: np.ndarray
    suc: np.ndarray
    offsets: np.ndarray
    frames: np.ndarray
    fps: float

    @property
    def size(self) -> int:
        return len(self.phoneme)

    def node_frames(self, node: int) -> np.ndarray:
        return self.frames[self.offsets[node] : self.offsets[node + 1]]

    def relative_times(self) -> np.ndarray:
        """Each frame's relative time in its node's phoneme, (F,)."""
        counts = np.diff(self.offsets)
        position = np.arange(len(self.frames)) - np.repeat(self.offsets[:-1], counts)
        return np.asarray(position / np.maximum(np.repeat(counts, counts) - 1, 1))

    def frame_nodes(self) -> np.ndarray:
        """The node of each frame, (F,)."""
        return np.repeat(np.arange(self.size), np.diff(self.offsets))

    def arrays(self) -> dict[str, np.ndarray]:
        values = (
            self.phoneme,
            self.emotion,
            self.previous,
            self.next,
            self.pre,
            self.suc,
            self.offsets,
            self.frames,
        )
        return dict(zip(STORED, values))

    @classmethod
    def from_arrays(cls, reader: ArrayReader, n_components: int, fps: float) -> NodeDatabase:
        """The stored database, every index and link checked."""
        n_phonemes = len(PHONEMES)
        phoneme = reader.integers("node_phoneme", (None,), 0, n_phonemes)
        n = len(phoneme)
        if n == 0:
            raise reader.error("node_phoneme", "is empty: a model needs at least one node")
        if (phoneme == SILENCE_INDEX).any():
            raise reader.error("node_phoneme", "holds a silence node (silences make no node)")
        frames = reader.floats("node_frames", (None, n_components))
        offsets = reader.offsets("node_offsets", n, len(frames), nonempty=True)
        pre = reader.integers("node_pre", (n,), -1, n)
        suc = reader.integers("node_suc", (n,), -1, n)
        linked = pre >= 0
        if not np.array_equal(suc[pre[linked]], np.flatnonzero(linked)):
            raise reader.error("node_pre", "is not the inverse of node_suc")
        if np.count_nonzero(suc >= 0) != np.count_nonzero(linked):
            raise reader.error("node_suc", "is not the inverse of node_pre")
        # plain ndarray views of the mapped pages (no copy): a memmap's indexing is slower
        return cls(
            phoneme=np.asarray(phoneme),
            emotion=np.asarray(reader.integers("node_emotion", (n,), 0, len(EMOTIONS))),
            previous=np.asarray(reader.integers("node_previous", (n,), 0, n_phonemes)),
            next=np.asarray(reader.integers("node_next", (n,), 0, n_phonemes)),
            pre=np.asarray(pre),
            suc=np.asarray(suc),
            offsets=np.asarray(offsets),
            frames=np.asarray(frames),
            fps=fps,
        )


def build_nodes(corpus: object, basis: MotionBasis) -> NodeDatabase:
    """The node database of every utterance of ``corpus`` (a ``lipstream.corpus.Corpus``)."""
    names = ("phoneme", "emotion", "previous", "next", "pre")
    columns: dict[str, list[int]] = {name: [] for name in names}
    pieces: list[np.ndarray] = []
    offsets = [0]
    fps = float(corpus.fps)  # type: ignore[attr-defined]
    for utterance in corpus.utterances:  # type: ignore[attr-defined]
        projected = basis.project(utterance.frames)
        last_row = len(projected) - 1
        spans = utterance.phones
        before = -1
        for index, span in enumerate(spans):
            if span.phoneme == SILENCE:
                before = -1
                continue
            first = min(math.floor(span.start * fps + 1e-9), last_row)
            last = max(min(math.ceil(span.end * fps - 1e-9), last_row), first)
            pieces.append(projected[first : last + 1])
            offsets.append(offsets[-1] + last + 1 - first)
            columns["phoneme"].append(PHONEME_INDEX[span.phoneme])
            columns["emotion"].append(EMOTION_INDEX[utterance.emotion])
            columns["previous"].append(
                PHONEME_INDEX[spans[index - 1].phoneme] if index > 0 else SILENCE_INDEX
            )
            columns["next"].append(
                PHONEME_INDEX[spans[index + 1].phoneme] if index + 1 < len(spans) else SILENCE_INDEX
            )
            columns["pre"].append(before)
            before = len(columns["phoneme"]) - 1
    pre = np.asarray(columns["pre"], dtype=np.int64)
    suc = np.full(len(pre), -1, dtype=np.int64)
    suc[pre[pre >= 0]] = np.flatnonzero(pre >= 0)
    return NodeDatabase(
        phoneme=np.asarray(columns["phoneme"], dtype=np.int64),
        emotion=np.asarray(columns["emotion"], dtype=np.int64),
        previous=np.asarray(columns["previous"], dtype=np.int64),
        next=np.asarray(columns["next"], dtype=np.int64),
        pre=pre,
        suc=suc,
        offsets=np.asarray(offsets, dtype=np.int64),
        frames=np.concatenate(pieces) if pieces else np.zeros((0, basis.n_components)),
        fps=fps,
    )


@dataclass(frozen=True)
class NodeFeatures:
    """What the costs read, derived from a database: ``viseme`` (N,), first/last positions
    and velocities (N, K), and the two halves of the blend's curvature (``blend_halves``
    of the nodes resampled to SHAPE_POINTS), (N, SHAPE_POINTS − 2, K)."""

    viseme: np.ndarray
    first_position: np.ndarray
    last_position: np.ndarray
    first_velocity: np.ndarray
    last_velocity: np.ndarray
    leaving: np.ndarray
    arriving: np.ndarray

    @classmethod
    def of(cls, nodes: NodeDatabase) -> NodeFeatures:
        starts, ends = nodes.offsets[:-1], nodes.offsets[1:] - 1
        single = ends == starts
        second = np.where(single, starts, starts + 1)
        before_last = np.where(single, ends, ends - 1)
        frames = nodes.frames
        leaving, arriving = blend_halves(resample_nodes(nodes, SHAPE_POINTS))
        return cls(
            viseme=VISEME_OF_PHONEME[nodes.phoneme],
            first_position=np.ascontiguousarray(frames[starts]),
            last_position=np.ascontiguousarray(frames[ends]),
            first_velocity=np.ascontiguousarray((frames[second] - frames[starts]) * nodes.fps),
            last_velocity=np.ascontiguousarray((frames[ends] - frames[before_last]) * nodes.fps),
            leaving=leaving,
            arriving=arriving,
        )


def resample_nodes(nodes: NodeDatabase, points: int) -> np.ndarray:
    """Every node time-warped (linearly) to ``points`` evenly spaced samples, (N, points, K)."""
    counts = np.diff(nodes.offsets)
    positions = np.linspace(0.0, 1.0, points)[None, :] * (counts[:, None] - 1)
    return np.asarray(sample_curves(nodes.frames, nodes.offsets, positions))


def blend_halves(shapes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Δ²g_m of the blend of a into p split as L_a,m + R_p,m, for every node: with
    w_m = m δ, δ = 1 / (M − 1), Δx_m = x_{m+1} − x_{m−1} and Δ²x_m = x_{m−1} − 2x_m + x_{m+1},
    Δ²g_m = [(1 − w_m) Δ²a_m − δ Δa_m] + [w_m Δ²p_m + δ Δp_m]. Both (N, M − 2, K)."""
    points = shapes.shape[1]
    step = 1.0 / (points - 1)
    w = (np.arange(1, points - 1) * step)[None, :, None]
    curvature = shapes[:, :-2] - 2.0 * shapes[:, 1:-1] + shapes[:, 2:]
    spread = shapes[:, 2:] - shapes[:, :-2]
    leaving = (1.0 - w) * curvature - step * spread
    arriving = w * curvature + step * spread
    return np.ascontiguousarray(leaving), np.ascontiguousarray(arriving)


def warp_node(frames: np.ndarray, relative: np.ndarray) -> np.ndarray:
    """A node's frames (n, K) time-warped to relative times ``relative`` in [0, 1], (m, K)."""
    positions = np.clip(relative, 0.0, 1.0) * (len(frames) - 1)
    whole = np.array([0, len(frames)])
    return np.asarray(sample_curves(frames, whole, positions[None, :])[0])


def node_context(nodes: NodeDatabase, node: int) -> Mapping[str, str]:
    """The triphone context of ``node`` as phoneme labels."""
    return {
        "previous": PHONEMES[int(nodes.previous[node])],
        "phoneme": PHONEMES[int(nodes.phoneme[node])],
        "next": PHONEMES[int(nodes.next[node])],
    }
