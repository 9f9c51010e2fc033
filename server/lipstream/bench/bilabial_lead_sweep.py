"""The bilabial lead of ``hmm``, ``anime-graph`` and ``expressive-dp``: swept on the demo
corpus's held-out lines, and read on the real-face set.

Sketch: as ``closure_timing`` sweeps ``dam``'s lead, ``hmm`` is trained on the train split
with each lead of ``HMM_LEADS_MS`` as its ``bilabial_lead_s`` (the phoneme
categoricals read from the spans with every /p b m/ started that much earlier,
``bilabial_lead.lead_bilabials``; the facial HMM, fitted to the face alone, is the same at
every lead), from each EM seed of ``--seeds`` (EM finds a different model from each, which
moves the closures too). Every model is run driven by phonemes on the held-out lines on
each rung (``hmm.model.RUNGS``; ``full`` and ``short`` read the led spans, ``causal_lead``
and ``causal`` the acoustic ones) and its closures timed against the recordings as
``closure_timing.time_frames`` times them (plateau centre less the acoustic onset; RMS).
Each model's ``full`` rung is also timed on the real-face set's force-aligned phones,
behind the character rendered on them (``closure_sources.RealPhones``) and, for
information, behind the real lips (plateau centres as ``evaluation.closure_lags``).
``best_lead_ms`` (``closure_timing``) picks, averaged over the seeds, the lead whose
closures sit nearest the character's on both the held-out lines and the real phones
without the RMS rising.

``anime-graph`` and ``expressive-dp`` (``EVALUATED``), which do not lead, are evaluated as
leading them would make them: trained on the train split with the demo models'
hyperparameters on lines whose spans were led by each lead of ``LEADS_MS``
(``dam.engine.led_corpus``) and run on led spans, timed the same way on their default rung;
``best_lead_ms`` by the same criterion.

``python -m lipstream.bench.bilabial_lead_sweep --home DIR --json bench/bilabial_lead_sweep.json``
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ..bilabial_lead import lead_bilabials
from ..corpus import Corpus, load_corpus
from ..engines import get_engine_class, load_model
from ..engines.base import Model
from ..engines.dam.engine import led_corpus
from ..engines.hmm.engine import HmmEngine
from ..engines.hmm.model import RUNGS, HmmModel
from ..results_file import recorded, script_command, write_results
from .closure_sources import RealPhones
from .closure_timing import LEADS_MS, best_lead_ms, time_frames
from .real_set import real_set_parser

MODULE = "lipstream.bench.bilabial_lead_sweep"
EVALUATED = ("anime-graph", "expressive-dp")
SEEDS = (0, 1, 2, 3)
HMM_LEADS_MS = (*LEADS_MS, 60.0, 70.0, 80.0)
"""``closure_timing.LEADS_MS`` and on: ``hmm``'s held-out lag is still above 0 at 50 ms."""
FULL = RUNGS[0][0]


def rung_options(rung: str) -> dict[str, Any]:
    """The engine options of the ``hmm`` rung named ``rung``."""
    lag_ms, window_ms = next((lag, window) for name, lag, window in RUNGS if name == rung)
    return {"lag_ms": lag_ms, "window_ms": window_ms}


def frames_on(
    model: Model, corpus: Corpus, lead_s: float = 0.0, **options: Any
) -> list[np.ndarray]:
    """``model``'s frames for every line of ``corpus`` from its phones alone, the bilabials
    led by ``lead_s`` first, each line with its emotion."""
    return [
        model.synthesize(
            lead_bilabials(u.phones, lead_s), fps=corpus.fps, emotion=u.emotion, **options
        ).frames
        for u in corpus.utterances
    ]


def timed(frames: list[np.ndarray], heldout: Corpus) -> dict[str, Any]:
    """``closure_timing.time_frames`` without the groups."""
    found = time_frames(frames, heldout)
    return {key: value for key, value in found.items() if key != "groups"}


def hmm_sweep(
    settings: dict[str, Any],
    train: Corpus,
    heldout: Corpus,
    real: RealPhones,
    seeds: Sequence[int],
) -> list[dict[str, Any]]:
    """Per lead of ``HMM_LEADS_MS`` and seed: ``hmm`` trained on ``train`` with ``settings``,
    timed on ``heldout`` on every rung, and its ``full`` rung's lag on the ``real`` phones
    behind the character and behind the real lips."""
    rows = []
    for lead_ms in HMM_LEADS_MS:
        for seed in seeds:
            hyper = settings | {"bilabial_lead_s": lead_ms / 1000.0, "seed": seed}
            model = HmmEngine(**hyper).fit(train)
            assert isinstance(model, HmmModel)
            rungs = {
                name: timed(frames_on(model, heldout, **rung_options(name)), heldout)
                for name, _, _ in RUNGS
            }
            found = real.timed(model)
            rows.append(
                {
                    "lead_ms": lead_ms,
                    "seed": seed,
                    "rungs": rungs,
                    "real_phones_lag_ms": found["behind_character"]["mean_ms"],
                    "real": found["behind_real"],
                }
            )
    return rows


def seed_means(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per lead, the ``full`` rung's centre, closing and release lag and RMS averaged over
    the seeds, with every rung's centre lag and the real lag so averaged."""
    means = []
    for lead_ms in sorted({row["lead_ms"] for row in rows}):
        chosen = [row for row in rows if row["lead_ms"] == lead_ms]
        full = [row["rungs"][FULL] for row in chosen]
        means.append(
            {
                "lead_ms": lead_ms,
                "seeds": len(chosen),
                **{
                    key: float(np.mean([row[key] for row in full]))
                    for key in ("lag_ms", "closing_lag_ms", "release_lag_ms", "rms")
                },
                "rungs": {
                    name: {
                        key: float(np.mean([row["rungs"][name][key] for row in chosen]))
                        for key in ("lag_ms", "rms")
                    }
                    for name, _, _ in RUNGS
                },
                "real_phones_lag_ms": float(np.mean([row["real_phones_lag_ms"] for row in chosen])),
                "real_lag_ms": float(np.mean([row["real"]["mean_ms"] for row in chosen])),
            }
        )
    return means


def evaluated(
    name: str,
    settings: dict[str, Any],
    corpora: tuple[Corpus, Corpus],
    real: RealPhones,
) -> list[dict[str, Any]]:
    """Per lead of ``LEADS_MS``, engine ``name`` with ``settings`` trained on the train
    split of ``corpora`` led by hand and run on led spans: timed on the held-out split and
    on the ``real`` phones, behind the character and behind the real lips."""
    train, heldout = corpora
    rows = []
    for lead_ms in LEADS_MS:
        lead_s = lead_ms / 1000.0
        model = get_engine_class(name)(**settings).fit(led_corpus(train, lead_s))
        found = real.timed(model, lead_s)
        rows.append(
            {
                "lead_ms": lead_ms,
                **timed(frames_on(model, heldout, lead_s), heldout),
                "real_phones_lag_ms": found["behind_character"]["mean_ms"],
                "real": found["behind_real"],
            }
        )
    return rows


def run(home: Path, real_set: Path, seeds: Sequence[int], command: str) -> dict[str, Any]:
    corpus = load_corpus(home / "demo" / "corpus")
    train, heldout = corpus.split()
    real = RealPhones.load(real_set)
    with threadpool_limits(limits=1):
        built = load_model(home / "demo" / "models" / "hmm")
        settings = {
            key: value
            for key, value in built.manifest.hyperparameters.items()
            if key != "bilabial_lead_s"
        }
        rows = hmm_sweep(settings, train, heldout, real, seeds)
        means = seed_means(rows)
        chosen = HmmEngine().hyperparameters()["bilabial_lead_s"]
        engines: dict[str, Any] = {
            "hmm": {
                "seeds": list(seeds),
                "runs": rows,
                "leads": means,
                "best_lead_ms": best_lead_ms(means),
                "chosen_lead_ms": round(1000.0 * chosen, 6),
            }
        }
        for name in EVALUATED:
            hyper = dict(load_model(home / "demo" / "models" / name).manifest.hyperparameters)
            leads = evaluated(name, hyper, (train, heldout), real)
            engines[name] = {"leads": leads, "best_lead_ms": best_lead_ms(leads)}
    return {
        **recorded(command),
        "corpus": {"name": corpus.name, "digest": corpus.digest(), "fps": corpus.fps},
        "real_set": {"name": real.name, "clips": len(real.clips), "fps": real.fps},
        "rungs": [name for name, _, _ in RUNGS],
        "engines": engines,
    }


def format_sweep(results: dict[str, Any]) -> str:
    lines = []
    for engine, found in results["engines"].items():
        for row in found["leads"]:
            real = row["real_lag_ms"] if "real_lag_ms" in row else row["real"]["mean_ms"]
            line = (
                f"{engine} lead {row['lead_ms']:g} ms: held-out lag {row['lag_ms']:+.1f} ms,"
                f" RMS {row['rms']:.5f}; behind the character on the real phones"
                f" {row['real_phones_lag_ms']:+.1f} ms; real lag {real:+.1f} ms"
            )
            if "rungs" in row:
                line += "; rungs " + ", ".join(
                    f"{name} {rung['lag_ms']:+.1f}/{rung['rms']:.4f}"
                    for name, rung in row["rungs"].items()
                )
            lines.append(line)
        lines.append(f"{engine}: best lead {found['best_lead_ms']:g} ms")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    parser = real_set_parser(f"python -m {MODULE}", __doc__, home=True)
    parser.add_argument(
        "--seeds", type=int, nargs="+", default=list(SEEDS), help="EM seeds to train hmm from"
    )
    parser.add_argument("--json", type=Path, required=True, help="results file to write")
    args = parser.parse_args(argv)
    results = run(args.home, args.real, args.seeds, script_command(MODULE, argv))
    write_results(results, args.json)
    print(format_sweep(results))


if __name__ == "__main__":
    main()
