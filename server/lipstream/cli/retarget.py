"""``lipstream retarget``: fit a rig map from key-pose pairs, store a rig preset fitted on a
model, or show the presets and a model's maps."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from lipstream_client.channels import RETARGET_PRESETS

from ..config import Settings
from ..errors import LipstreamError

if TYPE_CHECKING:
    from ..engines.base import Model
    from ..output.retarget import RetargetMap
    from .commands import Commands


def _retarget(args: argparse.Namespace, settings: Settings) -> None:
    from ..engines import load_model
    from ..output.retarget import RETARGET_DIR, fit_map, read_pairs, save_map, write_pairs
    from ..output.rig_presets import preset_pairs

    if args.model is None:
        if args.action != "show":
            raise LipstreamError(f"retarget {args.action} needs --model DIR", where="--model")
        _show_presets(args.name)
        return
    directory = Path(args.model)
    model = load_model(directory)
    if args.action == "show":
        _show_maps(model, directory, args.name)
        return
    if args.action == "fit":
        pairs = read_pairs(Path(args.pairs), model.channels)
        name = args.name
    else:
        pairs = preset_pairs(model, args.target)
        name = args.name or args.target
        if args.pairs_out:
            write_pairs(Path(args.pairs_out), pairs)
    retarget = fit_map(name, pairs)
    out = save_map(Path(args.out) if args.out else directory / RETARGET_DIR / name, retarget)
    worst = max(retarget.reproduction_error().values())
    print(f"wrote retarget map {name} to {out} (largest key-pose error {worst:.3g})")


def _show_presets(name: str | None) -> None:
    """The shipped rig presets (or only ``name``): the rig each drives and its controls."""
    from ..output.rig_presets import PRESETS, preset

    shown = PRESETS.values() if name is None else [preset(name, "name")]
    for shipped in shown:
        arkit = ", for models with ARKit channel names" if shipped.needs_arkit else ""
        print(f"{shipped.name}: {shipped.rig}; {len(shipped.controls)} controls{arkit}")
        print(f"  controls: {', '.join(shipped.controls)}")


def _show_maps(model: Model, directory: Path, name: str | None) -> None:
    for shown, retarget in _shown_maps(model, directory, name).items():
        errors = retarget.reproduction_error()
        print(
            f"{shown}: {len(retarget.channels)} channels -> {len(retarget.controls)} controls, "
            f"{len(errors)} key poses, largest key-pose error {max(errors.values()):.3g}"
        )
        print(f"  controls: {', '.join(retarget.controls)}")
        print(f"  keys: {', '.join(retarget.pairs.key_names)}")


def _shown_maps(model: Model, directory: Path, name: str | None) -> dict[str, RetargetMap]:
    """Every map the model is served through, or only the one named (``unknown_retarget``
    when it has none of that name)."""
    from ..output.rig_presets import model_maps, offered_presets

    maps = model_maps(model, directory, only=name)
    if name is None:
        return maps
    if name not in maps:
        known = ", ".join(dict.fromkeys([*offered_presets(model.channels), *maps]))
        raise LipstreamError(
            f"the model has no retarget map {name!r}; its maps: {known}",
            where=str(directory),
            code="unknown_retarget",
        )
    return {name: maps[name]}


def add_retarget_parser(commands: Commands) -> None:
    retarget = commands.add_parser("retarget", help="fit, build or show rig presets and maps")
    actions = retarget.add_subparsers(dest="action", required=True)
    fit = actions.add_parser("fit", help="fit a map from a key-pose pairs file")
    fit.add_argument(
        "--pairs", required=True, help="key-pose pairs, JSON or .csv (docs/how-to/retarget.md)"
    )
    fit.add_argument("--name", required=True, help="the map's name (output.retarget)")
    build = actions.add_parser("build", help="store a rig preset fitted on the model")
    build.add_argument(
        "--target", required=True, help=f"a rig preset: {', '.join(RETARGET_PRESETS)}"
    )
    build.add_argument("--name", help="the map's name (default: the preset's)")
    build.add_argument(
        "--pairs-out", help="also write its key-pose pairs to this file (.csv for CSV, else JSON)"
    )
    show = actions.add_parser(
        "show", help="list the rig presets, or with --model the maps the model is served through"
    )
    show.add_argument("name", nargs="?", help="only this preset or map")
    show.add_argument("--model", help="the model directory")
    for action in (fit, build):
        action.add_argument("--model", required=True, help="the model directory")
        action.add_argument("--out", help="map directory (default: MODEL/retarget/NAME)")
    retarget.set_defaults(run=_retarget)
