"""The ``expressive-dp`` engine: ``fit`` builds the paper's database and chooses α by CV.

the motion basis (PCA keeping ``variance`` of every channel's variance) ->
α1..α6 by cross-validation (``weights``: the database of the training lines
but the validation ones, the validation lines synthesized by the full search
and post-processing) -> the node database of every training line, PNT, the
phoneme maps (``isomap``) -> durations and the causal rungs' κ. A corpus
without emotion labels is all neutral (the corpus model's default).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ...numerics.basis import MotionBasis, fit_basis
from ...phonemes import PHONEME_INDEX, SILENCE
from ...timeline import EMOTION_INDEX
from ..base import Engine, fill_gaps, frame_count
from ..damped_fit import best_following_kappa, validation_utterances
from ..durations import DurationModel
from .costs import ALPHA_NAMES, NodeBounds, Weights, unit_penalty
from .isomap import fit_maps
from .model import ExpressiveDpModel
from .nodes import NodeFeatures, build_nodes
from .postprocess import Renderer
from .search import LayerSpec, SearchSpace
from .synthesizer import extend_path, training_raw_curve
from .weights import DEFAULTS, frame_error, search_weights, total_error, validation_split


class ExpressiveDpEngine(Engine):
    """Deng & Neumann (2008); hyperparameters as in docs/explanation/engines/expressive-dp.md."""

    name = "expressive-dp"
    model_class = ExpressiveDpModel

    def __init__(
        self,
        variance: float = 0.985,
        lag: int = 4,
        smoothing_half: int = 3,
        smoothness: float = 1.0,
        evaluations: int = 24,
        restarts: int = 2,
        seed: int = 0,
    ) -> None:
        self.variance = variance
        self.lag = lag
        self.smoothing_half = smoothing_half
        self.smoothness = smoothness
        self.evaluations = evaluations
        self.restarts = restarts
        self.seed = seed

    def fit(self, corpus: Any, *, progress: bool = False) -> ExpressiveDpModel:
        recorded = np.concatenate([utterance.frames for utterance in corpus.utterances])
        basis, share = fit_basis(recorded, self.variance)
        with threadpool_limits(limits=1):
            database_rows, validation_rows = validation_split(len(corpus.utterances))
            cv = None
            alphas = DEFAULTS.copy()
            if validation_rows:
                part = replace(corpus, utterances=[corpus.utterances[i] for i in database_rows])
                held = [corpus.utterances[i] for i in validation_rows]
                cv = self._cross_validate(part, held, basis)
                alphas = cv.alphas
            nodes = build_nodes(corpus, basis)
            features = NodeFeatures.of(nodes)
            pnt = unit_penalty(features)
            points = fit_maps(nodes)
        rest = _rest_pose(corpus, basis)
        manifest = self.new_manifest(
            corpus,
            metrics={
                "nodes": nodes.size,
                "basis_components": basis.n_components,
                "basis_variance": share,
                **({"alphas": dict(zip(ALPHA_NAMES, alphas.tolist()))}),
                **(
                    {
                        "cv_error": cv.score,
                        "cv_error_defaults": cv.default_score,
                        "cv_evaluations": cv.evaluations,
                        "cv_lines": len(validation_rows),
                    }
                    if cv is not None
                    else {}
                ),
            },
            extra={"pnt": pnt},
        )
        arrays = {
            "basis_mean": basis.mean,
            "basis_components": basis.components,
            **nodes.arrays(),
            "alphas": alphas,
            "rest_pose": rest,
            "map_points": points,
            **DurationModel.fit(utterance.phones for utterance in corpus.utterances).arrays(),
            "causal_kappa": np.array([1.0]),
        }
        model = ExpressiveDpModel(manifest, arrays, None, nodes)
        utterances = validation_utterances(corpus)
        kappa = best_following_kappa(
            lambda utterance: training_raw_curve(model, utterance), model.basis, utterances
        )
        model.causal_kappa = kappa
        model.stored["causal_kappa"] = np.array([kappa])
        manifest.metrics["causal_kappa"] = kappa
        return model

    def _cross_validate(self, part: Any, held: list[Any], basis: MotionBasis) -> Any:
        nodes = build_nodes(part, basis)
        features = NodeFeatures.of(nodes)
        pnt = unit_penalty(features)
        renderer = Renderer(
            nodes,
            np.zeros(basis.n_components),
            float(part.fps),
            self.smoothing_half,
            self.smoothness,
        )

        def score(alphas: np.ndarray) -> float:
            packed = Weights(alphas, pnt).packed()
            space = SearchSpace(nodes, features, NodeBounds.of(nodes, features, packed), packed)
            errors = [frame_error(_synthesize(space, renderer, basis, u), u.frames) for u in held]
            return total_error(errors)

        return search_weights(score, self.evaluations, self.restarts, self.seed)


def _synthesize(
    space: SearchSpace, renderer: Renderer, basis: MotionBasis, utterance: Any
) -> np.ndarray:
    """One validation line by the full search, in channels at its own frame times."""
    spans = fill_gaps(utterance.phones)
    emotion = EMOTION_INDEX[utterance.emotion]
    layers = [LayerSpec(PHONEME_INDEX[span.phoneme], emotion) for span in spans]
    path: list[int] = []
    excluded = np.zeros(space.nodes.size, dtype=bool)
    extend_path(space, layers, excluded, None, path, True)
    times = np.arange(frame_count(spans[-1].end, utterance.fps)) / utterance.fps
    return basis.reconstruct(renderer.frames(spans, path, times))


def _rest_pose(corpus: Any, basis: MotionBasis) -> np.ndarray:
    """The mean frame of every silence in the corpus, in the basis (the mean frame if none)."""
    rows = []
    for utterance in corpus.utterances:
        for span in utterance.phones:
            if span.phoneme == SILENCE:
                first = int(np.ceil(span.start * corpus.fps - 1e-9))
                last = int(np.floor(span.end * corpus.fps + 1e-9))
                rows.append(utterance.frames[first : last + 1])
    frames = np.concatenate(rows) if rows and sum(map(len, rows)) else None
    if frames is None or len(frames) == 0:
        return np.zeros(basis.n_components)
    return np.asarray(basis.project(frames.mean(axis=0, keepdims=True))[0])
