"""CPU per frame of a rig preset's map: scipy's NNLS per frame against the warm-started one.

Method: for each engine of the character, a sentence (``LABELS``, 80 ms a phoneme, 60 fps)
is synthesized once and mapped through every preset the model is offered, probed as the
server probes it (phoneme poses from the character's ``viseme-lerp`` model). The frames
go to a map in blocks of ``--block`` frames, as a stream's messages bring them, by two
paths: ``scipy`` (the map before issue 27: the pseudo-inverse product for the block, then
``scipy.optimize.nnls`` for each frame whose blend is not non-negative) and ``compiled``
(``RetargetStream.apply``: the same product, then the compiled active-set NNLS warm-started
from the frame before). The two paths alternate, pass by pass, after one unmeasured pass
of each (compiled kernels); each pass is read on the measuring thread's clock
(``time.thread_time``). Reported per preset: the median over passes of CPU µs per frame
for each path, their ratio, and the share of frames the NNLS solved.

    python -m lipstream.bench.retarget_cost --models DIR [--character demo]
        [--engine NAME ...] [--block 5] [--passes 7] [--json out.json]

``--json`` writes the rows (``rows``) after the command, date and machine.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import nnls

from ..engines.base import Model
from ..models import ModelRegistry
from ..output.probes import probe_rig
from ..output.retarget import RetargetMap
from ..output.rig_presets import model_maps

LABELS = tuple("sil HH AH0 L OW1 W ER1 L D sil M AA1 P B IY1 S T UW1 CH EH1 F sil".split())
PHONEME_S = 0.08
FPS = 60.0
SOURCE_ENGINE = "viseme-lerp"


@dataclass(frozen=True)
class RetargetCost:
    """One preset's CPU µs per frame on one engine's frames, by path."""

    engine: str
    preset: str
    frames: int
    nnls_share: float
    scipy_us: float
    compiled_us: float
    ratio: float


def scipy_apply(retarget: RetargetMap, frames: np.ndarray) -> np.ndarray:
    """The map's controls as computed before issue 27: ``scipy.optimize.nnls`` per frame (a
    diagonal map's closed form is unchanged)."""
    if retarget.diagonal is not None:
        return retarget.apply(frames)
    pairs = retarget.pairs
    fitted = pairs.channel_weights > 0
    targets = (frames - pairs.source_rest)[:, fitted] * pairs.channel_weights[fitted]
    system = retarget.system
    weights: np.ndarray = targets @ retarget._pseudo_inverse.T
    for index in np.flatnonzero((weights < 0).any(axis=1)):
        weights[index], _ = nnls(system, targets[index])
    blended = pairs.control_rest + weights @ (pairs.control_keys - pairs.control_rest)
    controls: np.ndarray = np.clip(blended, 0.0, 1.0)
    return controls


def sentence(model: Model) -> np.ndarray:
    spans = [
        (label, index * PHONEME_S, (index + 1) * PHONEME_S) for index, label in enumerate(LABELS)
    ]
    return np.asarray(model.synthesize(spans, fps=FPS).frames, dtype=np.float64)


def pass_cost(apply: Callable[[np.ndarray], np.ndarray], frames: np.ndarray, block: int) -> float:
    """CPU seconds per frame of mapping ``frames`` in blocks of ``block``."""
    started = time.thread_time()
    for first in range(0, len(frames), block):
        apply(frames[first : first + block])
    return (time.thread_time() - started) / len(frames)


def measure(
    engine: str, name: str, retarget: RetargetMap, frames: np.ndarray, block: int, passes: int
) -> RetargetCost:
    """The preset's ``RetargetCost``: ``passes`` alternating passes of each path after one
    unmeasured pass of each."""
    paths: dict[str, list[float]] = {"scipy": [], "compiled": []}
    for measured in [False] + [True] * passes:
        for path, costs in paths.items():
            apply = (
                (lambda block_frames: scipy_apply(retarget, block_frames))
                if path == "scipy"
                else retarget.stream().apply
            )
            cost = pass_cost(apply, frames, block)
            if measured:
                costs.append(cost)
    scipy_us = 1e6 * statistics.median(paths["scipy"])
    compiled_us = 1e6 * statistics.median(paths["compiled"])
    pairs = retarget.pairs
    fitted = pairs.channel_weights > 0
    targets = (frames - pairs.source_rest)[:, fitted] * pairs.channel_weights[fitted]
    bounded = ((targets @ retarget._pseudo_inverse.T) < 0).any(axis=1)
    diagonal = retarget.diagonal is not None
    return RetargetCost(
        engine,
        name,
        len(frames),
        0.0 if diagonal else round(float(bounded.mean()), 3),
        round(scipy_us, 2),
        round(compiled_us, 2),
        round(scipy_us / compiled_us, 1) if compiled_us > 0 else 0.0,
    )


def main(argv: Sequence[str] | None = None) -> None:
    from ..results_file import recorded, script_command, write_results

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", type=Path, required=True, help="model directory")
    parser.add_argument("--character", default="demo", help="character name")
    parser.add_argument("--engine", action="append", help="engine (repeatable; default all)")
    parser.add_argument("--block", type=int, default=5, help="frames per block (a message)")
    parser.add_argument("--passes", type=int, default=7, help="measured passes of each path")
    parser.add_argument("--json", type=Path, help="write the rows here")
    args = parser.parse_args(argv)
    registry = ModelRegistry.load(args.models)
    names = args.engine or registry.characters().get(args.character, [])
    source = registry.find(SOURCE_ENGINE, args.character)
    rows = []
    for engine in names:
        model = registry.find(engine, args.character)
        same = source is not None and source.channels == model.channels
        maps = model_maps(
            model, None, probe=probe_rig(model, phoneme_source=source if same else None)
        )
        frames = sentence(model)
        for name, retarget in maps.items():
            row = measure(engine, name, retarget, frames, args.block, args.passes)
            rows.append(row)
            print(
                f"{row.engine:15s} {row.preset:10s} nnls {row.nnls_share:5.2f}   "
                f"scipy {row.scipy_us:8.2f} µs   compiled {row.compiled_us:8.2f} µs   "
                f"ratio {row.ratio:6.1f}"
            )
    if args.json is not None:
        command = script_command("lipstream.bench.retarget_cost", argv)
        write_results({**recorded(command), "rows": [asdict(row) for row in rows]}, args.json)


if __name__ == "__main__":
    main()
