"""The ``dam`` and ``cohen-massaro`` engines: ``fit`` is the paper's training loop.

the bilabials' articulatory spans (``bilabial_lead.lead_bilabials``: /p b m/ started up to
``bilabial_lead_s`` before their acoustic onset, as synthesis starts them) -> the motion
basis (PCA keeping ``variance`` of every channel's variance, see
docs/explanation/engines/dam.md for why components rather than channels) -> modes
(resample + affinity propagation + contexts) -> EM (E-step, then M-step
and E-step until converged) -> the tail that bounds streaming's truncation error ->
phoneme durations and the causal rungs' filter speed κ (``causal``; both on the acoustic
spans, which the causal rungs keep).
``cohen-massaro`` is the same code with constant animemes (M = 0).
"""

from __future__ import annotations

import inspect
from dataclasses import replace
from typing import Any, NamedTuple

import numpy as np
from threadpoolctl import threadpool_limits

from ...bilabial_lead import lead_bilabials
from ...numerics.basis import fit_basis
from ...store import ModelManifest
from ..base import Engine
from ..damped_fit import KAPPAS, validation_utterances
from ..durations import DurationModel
from . import em
from .causal import fit_causal_kappa
from .model import CohenMassaroModel, DamModel
from .modes import assign_modes, collect_occurrences, resample
from .tails import choose_tail, truncation_errors

DAM_BILABIAL_LEAD_S = 0.02
COHEN_MASSARO_BILABIAL_LEAD_S = 0.02
"""The leads of /p b m/ by the sweep of ``bench.closure_timing``: the closure centres
nearest the character's, on the demo's held-out lines and on the real-face set's phones,
without the held-out RMS rising (``closure_timing.best_lead_ms``)."""


def led_corpus(corpus: Any, lead_s: float) -> Any:
    """``corpus`` with every line's bilabials led by ``lead_s`` (``lead_bilabials``)."""
    if lead_s <= 0.0:
        return corpus
    return replace(
        corpus,
        utterances=[replace(u, phones=lead_bilabials(u.phones, lead_s)) for u in corpus.utterances],
    )


class EmFit(NamedTuple):
    """What ``DamEngine.fit_em`` fitted; ``frames`` are the recorded frames in the basis."""

    occurrences: Any
    recorded: np.ndarray
    basis: Any
    frames: np.ndarray
    modes: Any
    mode_of: np.ndarray
    settings: em.Settings
    fitted: Any


class DamEngine(Engine):
    """Dominated Animeme Models (Lin et al.).

    Hyperparameters as in docs/explanation/engines/dam.md.
    """

    name = "dam"
    model_class = DamModel

    def __init__(
        self,
        *,
        degree: int = 4,
        variance: float = 0.99,
        points: int = 8,
        min_occurrences: int = 3,
        eps: float = 1e-4,
        tol: float = 1e-3,
        ridge: float = 1e-6,
        sigma_init: float = 0.2,
        sigma_max: float = 0.6,
        n_iter: int = 3,
        em_tol: float = 1e-4,
        truncation_bound: float = 0.01,
        alpha: float = 1.0,
        w_context: float = 1000.0,
        w_smooth: float = 1.0,
        search_behind: int = 2,
        search_ahead: int = 2,
        bilabial_lead_s: float = DAM_BILABIAL_LEAD_S,
    ) -> None:
        self.degree = degree
        self.variance = variance
        self.points = points
        self.min_occurrences = min_occurrences
        self.eps = eps
        self.tol = tol
        self.ridge = ridge
        self.sigma_init = sigma_init
        self.sigma_max = sigma_max
        self.n_iter = n_iter
        self.em_tol = em_tol
        self.truncation_bound = truncation_bound
        self.alpha = alpha
        self.w_context = w_context
        self.w_smooth = w_smooth
        self.search_behind = search_behind
        self.search_ahead = search_ahead
        self.bilabial_lead_s = bilabial_lead_s

    def polynomial_degree(self) -> int:
        return self.degree

    def fit_em(self, corpus: Any) -> EmFit:
        """The EM fit of ``corpus`` that ``fit`` starts from: occurrences, motion basis,
        modes and the fitted dominance widths and coefficients (one BLAS thread), on the
        bilabials' articulatory spans."""
        occurrences, recorded = collect_occurrences(led_corpus(corpus, self.bilabial_lead_s))
        basis, _ = fit_basis(recorded, self.variance)
        frames = basis.project(recorded)
        modes, mode_of = assign_modes(
            occurrences, resample(occurrences, frames, self.points), self.min_occurrences
        )
        settings = em.Settings(
            self.polynomial_degree(), self.eps, self.tol, self.ridge, self.sigma_max
        )
        with threadpool_limits(limits=1):
            fitted = em.fit(
                occurrences,
                mode_of,
                modes.count,
                frames,
                settings,
                self.n_iter,
                self.em_tol,
                self.sigma_init,
            )
        return EmFit(occurrences, recorded, basis, frames, modes, mode_of, settings, fitted)

    def fit(self, corpus: Any, *, progress: bool = False) -> DamModel:
        occurrences, recorded, basis, _, modes, mode_of, settings, fitted = self.fit_em(corpus)
        with threadpool_limits(limits=1):
            args = (
                occurrences,
                mode_of,
                fitted.sigma,
                fitted.coefficients,
                basis,
                recorded,
                settings,
            )
            tail, tail_error = choose_tail(*args, self.truncation_bound)
            rung_errors = {
                f"tail_ahead={ahead}": float(truncation_errors(*args, (tail, ahead)).max())
                for ahead in sorted({tail, min(1, tail), 0})
            }
        manifest = self.new_manifest(
            corpus,
            metrics={
                "modes": modes.count,
                "basis_components": basis.n_components,
                "occurrences": len(occurrences.start),
                "em_objective": [round(value, 6) for value in fitted.history],
                "fit_rms": float(np.sqrt(fitted.history[-1] / recorded.size)),
                "truncation_error": {"tail": tail_error, **rung_errors},
            },
            extra={"tail": tail, "reference_duration": float(np.mean(occurrences.duration))},
        )
        arrays = {
            "basis_mean": basis.mean,
            "basis_components": basis.components,
            "mode_phoneme": modes.phoneme,
            "mode_offsets": modes.offsets,
            "stand_in": modes.stand_in,
            "sigma": fitted.sigma,
            "coefficients": fitted.coefficients,
            "count_previous": modes.previous,
            "count_following": modes.following,
            "count_emotion": modes.emotion,
            **DurationModel.fit(utterance.phones for utterance in corpus.utterances).arrays(),
            "causal_kappa": np.array([KAPPAS[0]]),
        }
        # κ is fitted on the model's own causal curves, which do not depend on it
        kappa = fit_causal_kappa(self.make_model(manifest, arrays), validation_utterances(corpus))
        manifest.metrics["causal_kappa"] = kappa
        return self.make_model(manifest, {**arrays, "causal_kappa": np.array([kappa])})

    def make_model(self, manifest: ModelManifest, arrays: dict[str, np.ndarray]) -> DamModel:
        return DamModel(manifest, arrays)


class CohenMassaroEngine(DamEngine):
    """Cohen-Massaro: the DAM code with constant targets (M = 0), served as its own engine."""

    name = "cohen-massaro"
    model_class = CohenMassaroModel

    def __init__(self, **hyperparameters: Any) -> None:
        """DAM's hyperparameters but ``degree``, which is 0 here (constant targets), and
        ``bilabial_lead_s`` defaults to its own; the signature below names them, read from
        ``DamEngine``'s."""
        hyperparameters.setdefault("bilabial_lead_s", COHEN_MASSARO_BILABIAL_LEAD_S)
        super().__init__(degree=0, **hyperparameters)
        del self.degree  # M is no hyperparameter here: it is 0

    def polynomial_degree(self) -> int:
        return 0

    def make_model(self, manifest: ModelManifest, arrays: dict[str, np.ndarray]) -> DamModel:
        return CohenMassaroModel(manifest, arrays)


def _cohen_massaro_signature(signature: inspect.Signature) -> inspect.Signature:
    """DAM's signature without ``degree``, with Cohen-Massaro's own bilabial lead."""
    return signature.replace(
        parameters=[
            p.replace(default=COHEN_MASSARO_BILABIAL_LEAD_S) if p.name == "bilabial_lead_s" else p
            for p in signature.parameters.values()
            if p.name != "degree"
        ]
    )


# Engine.hyperparameter_names reads a signature, as scikit-learn's get_params does: give the
# derived constructor DAM's, less degree, instead of listing seventeen parameters again.
CohenMassaroEngine.__init__.__signature__ = _cohen_massaro_signature(  # type: ignore[attr-defined]
    inspect.signature(DamEngine.__init__)
)
