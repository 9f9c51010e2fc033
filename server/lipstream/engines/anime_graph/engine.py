"""Training the anime-graph engine: corpus in, ``AnimeGraphModel`` out.

Sketch: PCA of every frame (95% of every channel's variance); the corpus cut into
animes with MFCC curves when every utterance has audio; per view (the whole
corpus, and each emotion's recordings) the suffix automaton over the
recordings' phoneme strings, K-means clustering of the duration-normalized
fragments for the clustered graph, and a stand-in for every phoneme the view
never says; the smoothing cutoffs learned from the PCA curves.
"""

from __future__ import annotations

import sys
from dataclasses import asdict
from typing import Any

import numpy as np
from tqdm import tqdm

from ...errors import CorpusError, LipstreamError
from ...features import DEFAULT_MFCC
from ...numerics.basis import fit_basis
from ...phonemes import PHONEMES
from ..base import Engine
from .animes import AnimeTable, segment_corpus
from .graph import ClusterGraph
from .model import AnimeGraphModel
from .options import GRAPHS
from .smoothing import energy_below, learn_cutoffs
from .views import WHOLE, fit_view, view_clusters, view_members

STAGES = ("pca", "animes", "views", "cutoffs")


def _invalid(name: str, message: str) -> LipstreamError:
    return LipstreamError(message, where=f"anime-graph.{name}", code="invalid_hyperparameter")


class AnimeGraphEngine(Engine):
    """Hyperparameters: ``variance`` kept by PCA, of every channel's own variance when
    ``variance_per_channel`` (else of the total, as in the paper); ``graph`` served by
    default; ``clusters`` k of K-means (0: no clustered graph); ``max_tile`` phonemes per
    tile (bounds the streaming lookahead); ``max_candidates`` occurrences ranked per tile;
    ``energy`` share under the smoothing cutoff; ``smoothing_window`` FIR half-length (s);
    ``use_audio`` (MFCC features when the corpus has audio); ``seed`` for K-means."""

    name = "anime-graph"
    model_class = AnimeGraphModel

    def __init__(
        self,
        variance: float = 0.95,
        graph: str = "unclustered",
        clusters: int = 1000,
        max_tile: int = 10,
        max_candidates: int = 128,
        energy: float = 0.99,
        smoothing_window: float = 0.1,
        use_audio: bool = True,
        seed: int = 0,
        variance_per_channel: bool = True,
    ) -> None:
        if not 0.0 < variance <= 1.0:
            raise _invalid("variance", f"variance must be in (0, 1], got {variance!r}")
        if graph not in GRAPHS:
            raise _invalid("graph", f"graph must be one of {', '.join(GRAPHS)}, got {graph!r}")
        if graph == "clustered" and clusters < 1:
            raise _invalid("clusters", "the clustered graph needs clusters >= 1")
        for name, value, low in (
            ("clusters", clusters, 0),
            ("max_tile", max_tile, 1),
            ("max_candidates", max_candidates, 1),
            ("seed", seed, 0),
        ):
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise _invalid(name, f"{name} must be an integer >= {low}, got {value!r}")
        if not 0.0 < energy <= 1.0:
            raise _invalid("energy", f"energy must be in (0, 1], got {energy!r}")
        if not 0.0 <= smoothing_window <= 1.0:
            raise _invalid(
                "smoothing_window",
                f"smoothing_window must be in [0, 1] s, got {smoothing_window!r}",
            )
        self.variance = float(variance)
        self.variance_per_channel = bool(variance_per_channel)
        self.graph = graph
        self.clusters = clusters
        self.max_tile = max_tile
        self.max_candidates = max_candidates
        self.energy = float(energy)
        self.smoothing_window = float(smoothing_window)
        self.use_audio = bool(use_audio)
        self.seed = seed

    def fit(self, corpus: Any, *, progress: bool = False) -> AnimeGraphModel:
        utterances = list(corpus.utterances)
        if not utterances:
            raise CorpusError("the corpus has no utterances", where=f"corpus {corpus.name!r}")
        bar = tqdm(
            total=len(STAGES),
            desc="anime-graph",
            unit="stage",
            file=sys.stderr,
            disable=not progress,
        )
        bar.set_postfix_str("pca")
        all_frames = np.concatenate([u.frames for u in utterances])
        basis, explained = fit_basis(all_frames, self.variance, self.variance_per_channel)
        bar.update()
        bar.set_postfix_str("animes: segmenting the corpus")
        use_audio = self.use_audio and all(u.audio is not None for u in utterances)
        animes = segment_corpus(corpus, basis, DEFAULT_MFCC, use_audio)
        bar.update()
        bar.set_postfix_str("views: one search index per emotion")
        views = view_members([u.emotion for u in utterances], animes.utterance)
        shapes = animes.shapes() if self.clusters else np.zeros((animes.size, 0))
        arrays: dict[str, np.ndarray] = {}
        for name, members in views.items():
            k = view_clusters(self.clusters, len(members), animes.size)
            arrays |= fit_view(name, members, animes.labels, animes.utterance, shapes, k, self.seed)
        bar.update()
        bar.set_postfix_str("cutoffs: low-pass filter")
        curves = [animes.motion.rows(u) for u in range(len(utterances))]
        cutoffs = learn_cutoffs(curves, animes.motion.rate, self.energy)
        bar.update()
        bar.close()
        arrays |= {
            "basis_mean": basis.mean,
            "basis_components": basis.components,
            "channel_low": all_frames.min(axis=0),
            "channel_high": all_frames.max(axis=0),
            "anime_label": animes.labels,
            "anime_utterance": animes.utterance,
            "anime_start": animes.start,
            "anime_end": animes.end,
            "motion": animes.motion.values,
            "motion_offsets": animes.motion.offsets,
            "features": animes.features.values if animes.features else np.zeros((0, 0), np.float32),
            "feature_offsets": (
                animes.features.offsets if animes.features else np.zeros(1, np.int64)
            ),
            "anime_summary": animes.summaries(),
            "cutoffs": cutoffs,
        }
        manifest = self.new_manifest(
            corpus,
            metrics=_metrics(
                animes,
                basis.n_components,
                explained,
                arrays,
                list(views),
                cutoffs,
                energy_below(curves, animes.motion.rate, cutoffs),
            ),
            extra={"mfcc": asdict(DEFAULT_MFCC), "audio_features": use_audio, "views": list(views)},
        )
        return AnimeGraphModel(manifest, arrays)


def _metrics(
    animes: AnimeTable,
    n_components: int,
    explained: float,
    arrays: dict[str, np.ndarray],
    views: list[str],
    cutoffs: np.ndarray,
    kept: np.ndarray,
) -> dict[str, Any]:
    metrics: dict[str, Any] = {
        "animes": animes.size,
        "pca_components": n_components,
        "explained_variance": round(explained, 5),
        "index_states": int(arrays[f"{WHOLE}_index_transitions"].shape[0]),
        "cutoffs_hz": [round(float(c), 4) for c in cutoffs],
        "energy_below_cutoff": [round(float(k), 5) for k in kept],
        "views": {name: len(arrays[f"{name}_members"]) for name in views},
    }
    representative = arrays[f"{WHOLE}_cluster_representative"]
    if len(representative):
        assignment = np.full(animes.size, -1, dtype=np.int64)
        assignment[arrays[f"{WHOLE}_members"]] = arrays[f"{WHOLE}_cluster_assignment"]
        degree = ClusterGraph.build(
            assignment, representative, animes.labels, animes.successors(), len(PHONEMES)
        ).degree()
        metrics |= {
            "clusters": len(representative),
            "cluster_degree_mean": round(float(degree.mean()), 3),
            "cluster_degree_max": int(degree.max()),
        }
    return metrics
