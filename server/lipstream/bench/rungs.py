"""The price of each fidelity rung: quality on held-out utterances, rung by rung.

For every rung of an engine's ``fidelity_ladder`` (best first), each held-out
utterance is synthesized offline at the corpus frame rate with the rung's
options (and the utterance's emotion and, for engines that use audio, its
audio: a rung that ignores audio is measured as it serves). Figures: the RMS
error against the recorded curves and the share of /p b m/ spans whose lips
close, as in the engine table, and the RMS against the engine's best rung (the
first), which says how far a cheaper rung strays from what the engine would
show without a budget. ``lookahead_ms`` is the rung's wait for input arriving
in real time with phonemes of at most ``MAX_PHONEME_MS`` (the server's
default); the compute time a server adds is measured at its start-up.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config import ServerSettings
from ..corpus import Corpus
from ..engines.base import Model, Rung
from ..evaluation import rms_error
from ..server.budget import lookahead_ms
from .closure import closure_rate

MAX_PHONEME_MS = ServerSettings().max_phoneme_ms


@dataclass
class RungRow:
    """One rung's figures on the held-out split."""

    engine: str
    rung: str
    lookahead_ms: float
    rms_error: float
    closure_rate: float | None
    rms_vs_best: float


def _predict(model: Model, rung: Rung, heldout: Corpus) -> list[np.ndarray]:
    return [
        model.synthesize(
            utterance.phones,
            fps=heldout.fps,
            audio=utterance.audio if model.uses_audio else None,
            emotion=utterance.emotion,
            **dict(rung.options),
        ).frames
        for utterance in heldout.utterances
    ]


def rung_rows(model: Model, heldout: Corpus, threshold: float | None) -> list[RungRow]:
    """Every rung of ``model``'s ladder, best first."""
    ladder = model.fidelity_ladder()
    predictions = [_predict(model, rung, heldout) for rung in ladder]
    best = predictions[0]
    rows = []
    for rung, predicted in zip(ladder, predictions):
        recorded = [rms_error(p, u.frames) for p, u in zip(predicted, heldout.utterances)]
        against_best = [rms_error(p, b) for p, b in zip(predicted, best)]
        rows.append(
            RungRow(
                engine=model.manifest.engine,
                rung=rung.name,
                lookahead_ms=lookahead_ms(rung, MAX_PHONEME_MS),
                rms_error=float(np.mean(recorded)),
                closure_rate=closure_rate(predicted, heldout, threshold),
                rms_vs_best=float(np.mean(against_best)),
            )
        )
    return rows


def format_rungs(rows: list[dict[str, Any]]) -> str:
    """The rung table: one line per ``RungRow`` (as a dict)."""
    header = (
        f"{'engine':<14}{'rung':<26}{'lookahead':>11}{'RMS':>9}{'closure':>9}{'RMS to best':>13}"
    )
    lines = [header, "-" * len(header)]
    for row in rows:
        closure = row["closure_rate"]
        closure_text = "n/a" if closure is None else format(closure, ".1%")
        lines.append(
            f"{row['engine']:<14}{row['rung']:<26}{row['lookahead_ms']:>8.0f} ms"
            f"{row['rms_error']:>9.4f}{closure_text:>9}{row['rms_vs_best']:>13.4f}"
        )
    return "\n".join(lines)
