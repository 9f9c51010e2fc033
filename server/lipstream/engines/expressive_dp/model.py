"""The trained ``expressive-dp`` model: node database, weights, maps; options and rungs.

The model holds the motion basis, the node database (``nodes``), α1..α6 and PNT
(``costs``), the phoneme maps (``isomap``), the rest pose, the duration model
and the causal rungs' κ. Contaminated nodes live in ``contamination.json``
beside the model (``contamination``), re-read when it changes.

Options: ``lag`` (an integer in [0, ``MAX_LAG``] phonemes, or ``"full"``: the
whole optimum, whose frames wait for the end of the input), ``constraints``
(hard constraints: an object mapping a phoneme index of the request, as a
string, to a node id, or a list of [index, node] pairs), ``causal`` and
``lead_ms`` (the causal rungs). Emotion modifiers are the spans' own emotions
(else the request's). Ladder: ``lag-<L>`` for the model's lag, then 2, 1 and
0 below it (lookahead L + 2 phonemes), ``causal_lead`` and ``causal``.

Stored ranges (checked at load): each α inside the bounds its weight search covers
(``weights.BOUNDS``: α1 [0.01, 10], α2 [0.001, 10], α3 [0.01, 100], α4 [0.01, 0.99],
α5 and α6 [0.1, 100]); κ in [0.1, 100] (``damped_fit.KAPPA_RANGE``); durations as in
``durations``; every other float (node frames, rest pose, map points) within
``MAX_MAGNITUDE``.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InvalidRequestError
from ...model_checks import ArrayReader, FieldReader
from ...numerics.basis import MotionBasis, read_components
from ...numerics.direct_call import DirectCall
from ...store import ARRAYS_NAME, MANIFEST_NAME, ModelManifest
from ..base import (
    Lookahead,
    Model,
    Rung,
    SynthesisRequest,
    Synthesizer,
    causal_lead_ms,
    causal_rungs,
    causal_shift_s,
    resolved_rung,
)
from ..damped_fit import KAPPA_RANGE
from ..durations import DurationModel
from .causal_curve import NodeCurves, follow_raw
from .contamination import Contamination
from .costs import ALPHA_NAMES, NodeBounds, Weights
from .isomap import PhonemeMaps
from .nodes import NodeDatabase, NodeFeatures
from .postprocess import Renderer
from .search import SearchSpace
from .synthesizer import CausalSynthesizer, LagSynthesizer
from .weights import BOUNDS

MAX_LAG = 64
LADDER_LAGS = (2, 1, 0)
Resolved = tuple[str, float | int | None]


class ExpressiveDpModel(Model):
    """See the module docstring; arrays as ``engine.ExpressiveDpEngine.fit`` stores them."""

    engine = "expressive-dp"
    option_names = ("lag", "constraints", "causal", "lead_ms")

    def __init__(
        self,
        manifest: ModelManifest,
        arrays: Mapping[str, np.ndarray],
        directory: Path | None = None,
        nodes: NodeDatabase | None = None,
    ) -> None:
        super().__init__(manifest)
        self.stored = {name: np.asarray(value) for name, value in arrays.items()}
        hyper = manifest.hyperparameters
        self.basis = MotionBasis(self.stored["basis_mean"], self.stored["basis_components"])
        self.nodes = nodes or NodeDatabase(
            phoneme=self.stored["node_phoneme"],
            emotion=self.stored["node_emotion"],
            previous=self.stored["node_previous"],
            next=self.stored["node_next"],
            pre=self.stored["node_pre"],
            suc=self.stored["node_suc"],
            offsets=self.stored["node_offsets"],
            frames=self.stored["node_frames"],
            fps=float(manifest.fps),
        )
        self.features = NodeFeatures.of(self.nodes)
        self.weights = Weights(self.stored["alphas"], float(manifest.extra["pnt"]))
        packed = self.weights.packed()
        bounds = NodeBounds.of(self.nodes, self.features, packed)
        self.space = SearchSpace(self.nodes, self.features, bounds, packed)
        self.rest_pose = self.stored["rest_pose"]
        self.curves = NodeCurves(self.nodes.frames, self.nodes.offsets, self.rest_pose)
        # Every request's causal frames go through one DirectCall: the argument types are the
        # model's and the synthesizer's buffers', the same for every request.
        self.follow = DirectCall(follow_raw)
        self.lag = int(hyper["lag"])
        self.renderer = Renderer(
            self.nodes,
            self.rest_pose,
            float(manifest.fps),
            int(hyper["smoothing_half"]),
            float(hyper["smoothness"]),
        )
        self.maps = PhonemeMaps(self.nodes, self.stored["map_points"])
        self.contamination = Contamination(self.nodes.size, directory)
        self.durations = DurationModel(
            self.stored["duration_count"],
            self.stored["duration_log_mean"],
            self.stored["duration_log_std"],
        )
        self.causal_kappa = float(self.stored["causal_kappa"][0])

    @property
    def causal_omegas(self) -> np.ndarray:
        """The causal rungs' filter rate ω of every phoneme: κ / its median duration."""
        return self.causal_kappa / self.durations.expected_all_s()

    # -- options, lookahead, ladder -------------------------------------------------------

    def resolve(self, options: Mapping[str, Any]) -> Resolved:
        """("lag", L or None for the full search) or ("causal", lead ms), defaults filled."""
        lead = causal_lead_ms(options)
        if lead is not None:
            return ("causal", lead)
        lag = options.get("lag", self.lag)
        if lag == "full":
            return ("lag", None)
        if isinstance(lag, bool) or not isinstance(lag, int) or not 0 <= lag <= MAX_LAG:
            raise InvalidRequestError(
                f'lag must be an integer in [0, {MAX_LAG}] or "full", got {lag!r}',
                where="options.lag",
            )
        return ("lag", lag)

    def constraints(self, options: Mapping[str, Any]) -> dict[int, int]:
        """The hard constraints of ``options``: phoneme index -> node id, each checked."""
        given = options.get("constraints", {})
        if isinstance(given, Mapping):
            pairs: list[Any] = list(given.items())
        elif isinstance(given, list):
            pairs = given
        else:
            raise InvalidRequestError(
                "constraints must be an object {phoneme index: node id} or a list of "
                f"[index, node] pairs, got {type(given).__name__}",
                where="options.constraints",
            )
        found: dict[int, int] = {}
        excluded = self.contamination.mask()
        for position, pair in enumerate(pairs):
            where = f"options.constraints.{position}"
            if not (isinstance(pair, (list, tuple)) and len(pair) == 2):
                raise InvalidRequestError("must be an [index, node] pair", where=where)
            index, node = _index(pair[0]), pair[1]
            if index is None:
                raise InvalidRequestError(
                    f"phoneme index must be a non-negative integer, got {pair[0]!r}", where=where
                )
            where = f"options.constraints.{index}"
            if isinstance(node, bool) or not isinstance(node, int):
                raise InvalidRequestError(f"node id must be an integer, got {node!r}", where=where)
            if not 0 <= node < self.nodes.size:
                raise InvalidRequestError(
                    f"node {node} does not exist: node ids run from 0 to {self.nodes.size - 1}",
                    where=where,
                )
            if excluded[node]:
                raise InvalidRequestError(f"node {node} is marked contaminated", where=where)
            if index in found:
                raise InvalidRequestError(
                    f"phoneme index {index} is constrained twice", where=where
                )
            found[index] = node
        return found

    def shift_s(self, lead_ms: float) -> float:
        return causal_shift_s(lead_ms, self.durations.pooled_median_s(), self.causal_kappa)

    @property
    def lookahead(self) -> Lookahead:
        return Lookahead(phonemes=self.lag + 2)

    def lookahead_for(self, options: Mapping[str, Any]) -> Lookahead | None:
        kind, value = self.resolve(options)
        if kind == "causal":
            return Lookahead(seconds=self.shift_s(float(value or 0.0)))
        return None if value is None else Lookahead(phonemes=int(value) + 2)

    def fidelity_ladder(self) -> tuple[Rung, ...]:
        rungs = [
            Rung(f"lag-{lag}", Lookahead(phonemes=lag + 2), {"lag": lag})
            for lag in sorted({self.lag, *(x for x in LADDER_LAGS if x < self.lag)}, reverse=True)
        ]
        return (*rungs, *causal_rungs(self.shift_s))

    def rung_for(self, options: Mapping[str, Any]) -> Rung | None:
        """The rung of the resolved lag or lead; constraints do not change the work."""
        return resolved_rung(self.fidelity_ladder(), options, self.resolve)

    def synthesizer(self, request: SynthesisRequest) -> Synthesizer:
        kind, value = self.resolve(request.options)
        constraints = self.constraints(request.options)
        if kind == "causal":
            return CausalSynthesizer(self, request, self.shift_s(float(value or 0.0)), constraints)
        return LagSynthesizer(self, request, None if value is None else int(value), constraints)

    # -- store ----------------------------------------------------------------------------

    def arrays(self) -> dict[str, np.ndarray]:
        return dict(self.stored)

    def save(self, path: str | Path) -> None:
        """The model directory, with ``contamination.json`` when nodes are contaminated."""
        super().save(path)
        nodes = self.contamination.nodes()
        if nodes:
            Contamination(self.nodes.size, Path(path)).change(nodes, [])

    @classmethod
    def from_arrays(
        cls, manifest: ModelManifest, arrays: Mapping[str, np.ndarray], path: Path
    ) -> ExpressiveDpModel:
        fields = FieldReader(str(path / MANIFEST_NAME))
        hyper = fields.mapping(manifest.hyperparameters, "hyperparameters")
        extra = fields.mapping(manifest.extra, "extra")
        fields.integer(
            fields.member(hyper, "lag", "hyperparameters.lag"), "hyperparameters.lag", 0, MAX_LAG
        )
        fields.integer(
            fields.member(hyper, "smoothing_half", "hyperparameters.smoothing_half"),
            "hyperparameters.smoothing_half",
            1,
            32,
        )
        fields.number(
            fields.member(hyper, "smoothness", "hyperparameters.smoothness"),
            "hyperparameters.smoothness",
            0.0,
            1e6,
        )
        fields.number(fields.member(extra, "pnt", "extra.pnt"), "extra.pnt", 0.0, 1e9, above=True)
        reader = ArrayReader(arrays, str(path / ARRAYS_NAME))
        n_channels = len(manifest.channels)
        checked: dict[str, np.ndarray] = {
            "basis_mean": reader.floats("basis_mean", (n_channels,)),
            "basis_components": read_components(reader, "basis_components", n_channels),
        }
        k = len(checked["basis_components"])
        nodes = NodeDatabase.from_arrays(reader, k, float(manifest.fps))
        checked.update(nodes.arrays())
        alphas = reader.floats("alphas", (len(ALPHA_NAMES),))
        low, high = np.exp(BOUNDS[:, 0]), np.exp(BOUNDS[:, 1])
        outside = (alphas < low * (1 - 1e-9)) | (alphas > high * (1 + 1e-9))
        if outside.any():
            at = int(np.argmax(outside))
            raise reader.error(
                "alphas",
                f"alpha{at + 1} is {alphas[at]:.6g}, outside the [{low[at]:g}, {high[at]:g}] "
                "its weight search covers",
            )
        checked["alphas"] = alphas
        checked["rest_pose"] = reader.floats("rest_pose", (k,))
        checked["map_points"] = reader.floats("map_points", (len(nodes.frames), 2))
        checked.update(DurationModel.from_arrays(reader).arrays())
        checked["causal_kappa"] = reader.floats("causal_kappa", (1,), *KAPPA_RANGE)
        return cls(manifest, checked, path, nodes)


def _index(value: Any) -> int | None:
    """A phoneme index given as an integer or a decimal string (JSON object keys)."""
    if isinstance(value, bool):
        return None
    if isinstance(value, str) and value.isdigit():
        return int(value)
    if isinstance(value, int) and value >= 0:
        return value
    return None
