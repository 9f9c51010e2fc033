"""Cross-mapping a model's channels to a target rig's controls (Lin et al., Appendix A).

Method, in two stages as in the appendix. A map holds K key poses in pairs: a
pose s_k in the model's channels and the rig controls c_k ∈ [0,1] that make
the rig show that pose, plus a rest pair (s_0, c_0). Stage 1, per frame x:
the frame is expressed as a non-negative blend of the key poses' deltas from
rest, α = argmin_{α≥0} ||W (D α − (x − s_0))||² with D = [s_k − s_0] and W
the per-channel fit weights (Lawson–Hanson NNLS, ``numerics.nnls``; K is at
most ``MAX_KEYS``). A block of frames is first solved without the bound by
one product with the pseudo-inverse of W D; a frame whose solution is
already non-negative has its NNLS optimum there (the unconstrained minimum
is feasible), and only the others are solved one by one, by the compiled
active-set solver on the map's precomputed Gram matrix, each started from
the active set of the frame solved before it. A stream keeps that set from
block to block (``RetargetMap.stream``: one ``RetargetStream`` per output
stream), so a frame usually costs one small Cholesky solve. The presets have
more keys than fitted channels, so α itself need not be unique (the
residual is); where it is not, the blend found may depend on the frames
before (docs/how-to/retarget.md). Stage 2: the
rig controls are the same blend of the key controls, c = c_0 + Σ α_k (c_k −
c_0), projected onto [0,1] — the bounded least-squares solution of
min ||c − c_0 − Σ α_k (c_k − c_0)||² over c ∈ [0,1], which is a clip. A
key pose maps to its controls exactly when the key deltas are linearly
independent (then α = e_k); ``reproduction_error`` reports what a map does
on its own key poses. When every key delta moves one channel of its own,
the NNLS is diagonal and is solved in closed form.

The key controls c_k themselves come from the appendix's second fit: given
the rig's transfer function as control shapes (what each control alone
does to the model's channels), ``fit_controls`` solves min ||T c − s_k||²
over c ∈ [0,1] by bounded least squares (``scipy.optimize.lsq_linear``).
The shipped rig presets (``rig_presets``) build their key-pose pairs from
the model itself; ``oculus15`` fits its key controls this way.

A map is stored as a directory (``retarget.json`` manifest plus uncompressed
``arrays.npz``, never pickle), read with the load-time checks of
``model_checks``: a malformed or mismatched file is ``model_invalid`` naming
the file and the field or array. Key-pose pairs files (JSON, or CSV:
``pairs_csv``) are read by ``read_pairs``; the formats are in docs/how-to/retarget.md.
"""

from __future__ import annotations

import csv
import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import lsq_linear

from ..errors import ModelStoreError
from ..model_checks import ArrayReader, FieldReader
from ..numerics.nnls import BoolArray, NnlsSystem, cold_passive, nnls_system, solve_nnls_rows
from ..store import load_arrays
from .pairs_csv import csv_document, document_csv

SCHEMA_VERSION = 1
MANIFEST_NAME = "retarget.json"
ARRAYS_NAME = "arrays.npz"
RETARGET_DIR = "retarget"
"""Subdirectory of a model directory holding its stored maps, one directory per map."""
MAX_KEYS = 256
MAX_CONTROLS = 1024
MAX_PAIRS_BYTES = 4 << 20
_MAP_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")
_ARRAYS = ("source_rest", "control_rest", "source_keys", "control_keys", "channel_weights")


@dataclass(frozen=True)
class KeyPosePairs:
    """Key poses in a model's channels and the rig controls of each, with a rest pair.

    ``source_keys`` (K, n_channels) pairs row by row with ``control_keys`` (K, n_controls);
    ``channel_weights`` (n_channels,) weighs each channel in the stage-1 fit (0 leaves it
    out)."""

    channels: tuple[str, ...]
    controls: tuple[str, ...]
    key_names: tuple[str, ...]
    source_rest: np.ndarray
    control_rest: np.ndarray
    source_keys: np.ndarray
    control_keys: np.ndarray
    channel_weights: np.ndarray


@dataclass(frozen=True, eq=False)
class RetargetMap:
    """A fitted map from model frames to rig controls in [0,1] (see the module sketch)."""

    name: str
    pairs: KeyPosePairs

    @property
    def channels(self) -> tuple[str, ...]:
        return self.pairs.channels

    @property
    def controls(self) -> tuple[str, ...]:
        return self.pairs.controls

    @cached_property
    def system(self) -> np.ndarray:
        """Stage-1 matrix (fitted channels, K): weighted key deltas."""
        pairs = self.pairs
        fitted = pairs.channel_weights > 0
        deltas = (pairs.source_keys - pairs.source_rest).T
        return np.asarray(deltas[fitted] * pairs.channel_weights[fitted, None], dtype=np.float64)

    @cached_property
    def _nnls(self) -> NnlsSystem:
        """The stage-1 system with its Gram matrix, for the compiled NNLS."""
        return nnls_system(self.system)

    @cached_property
    def _pseudo_inverse(self) -> np.ndarray:
        """(K, fitted channels): the unconstrained least-squares solve of stage 1."""
        return np.linalg.pinv(self.system)

    @cached_property
    def diagonal(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(row of each key, its delta) when every key moves one fitted channel of its own."""
        system = self.system
        nonzero = system != 0
        if not (nonzero.sum(axis=0) == 1).all():
            return None
        rows = np.argmax(nonzero, axis=0)
        if len(set(rows.tolist())) != len(rows):
            return None
        return rows, system[rows, np.arange(system.shape[1])]

    def stream(self) -> RetargetStream:
        """A mapper for one stream of frames, keeping the NNLS warm start between blocks."""
        return RetargetStream(self, cold_passive(self._nnls))

    def blend_weights(self, frames: np.ndarray, passive: BoolArray | None = None) -> np.ndarray:
        """Stage 1: non-negative blend weights α float64 (n_frames, K) of the key poses.

        ``passive`` (K,) bool is the NNLS warm start, the active set of the frame solved
        before (updated in place); None starts the block cold."""
        pairs = self.pairs
        fitted = pairs.channel_weights > 0
        residual = np.asarray(frames, dtype=np.float64) - pairs.source_rest
        targets = residual[:, fitted] * pairs.channel_weights[fitted]
        if self.diagonal is not None:
            rows, scale = self.diagonal
            diagonal: np.ndarray = np.maximum(targets[:, rows] / scale, 0.0)
            return diagonal
        weights: np.ndarray = targets @ self._pseudo_inverse.T
        # A non-finite frame (an engine fault) stays non-finite, for the caller to report.
        bounded = (weights < 0).any(axis=1) & np.isfinite(targets).all(axis=1)
        if bounded.any():
            state = cold_passive(self._nnls) if passive is None else passive
            rows = np.flatnonzero(bounded).astype(np.intp)
            solve_nnls_rows(self._nnls, np.ascontiguousarray(targets), rows, state, weights)
        return weights

    def apply(self, frames: np.ndarray, passive: BoolArray | None = None) -> np.ndarray:
        """Rig controls float64 (n_frames, n_controls) in [0,1] for model frames
        (n_frames, n_channels); ``passive`` as in ``blend_weights``."""
        pairs = self.pairs
        blended = pairs.control_rest + self.blend_weights(frames, passive) @ (
            pairs.control_keys - pairs.control_rest
        )
        controls: np.ndarray = np.clip(blended, 0.0, 1.0)
        return controls

    def reproduction_error(self) -> dict[str, float]:
        """Per key, the largest control error of the map applied to its own key pose."""
        errors = np.abs(self.apply(self.pairs.source_keys) - self.pairs.control_keys).max(axis=1)
        return {name: float(error) for name, error in zip(self.pairs.key_names, errors)}


@dataclass(frozen=True, eq=False)
class RetargetStream:
    """One stream's mapper: ``map`` applied block after block, each NNLS frame started from
    the active set the stream's previous one ended with (``passive``, (K,) bool)."""

    map: RetargetMap
    passive: BoolArray

    def apply(self, frames: np.ndarray) -> np.ndarray:
        """Rig controls float64 (n_frames, n_controls) in [0,1], as ``RetargetMap.apply``."""
        return self.map.apply(frames, self.passive)


def fit_controls(
    shapes: np.ndarray, rest: np.ndarray, pose: np.ndarray, weights: np.ndarray | None = None
) -> np.ndarray:
    """Rig controls c ∈ [0,1] (n_controls,) that best show ``pose`` (n_channels,): bounded
    least squares on the rig's linear transfer ``rest + Σ c_j (shapes[j] − rest)``, with
    ``shapes`` (n_controls, n_channels) each control's pose alone and ``weights`` per channel.
    """
    weights = np.ones(len(rest)) if weights is None else weights
    transfer = (shapes - rest).T * weights[:, None]
    target = (pose - rest) * weights
    solution = lsq_linear(transfer, target, bounds=(0.0, 1.0), method="bvls")
    return np.clip(np.asarray(solution.x, dtype=np.float64), 0.0, 1.0)


def fit_map(name: str, pairs: KeyPosePairs) -> RetargetMap:
    """The map of ``pairs`` (checked: shapes, finite values, controls in [0,1]); ``name`` is
    also its directory's name, so letters, digits, ``.``, ``_`` and ``-`` only."""
    if not _MAP_NAME.match(name):
        raise ModelStoreError(
            "a retarget map name is 1 to 64 letters, digits, '.', '_' or '-', "
            f"not starting with '.', '_' or '-'; got {name!r}",
            where="name",
        )
    _check_pairs(pairs, f"retarget map {name}")
    return RetargetMap(name, pairs)


def _check_pairs(pairs: KeyPosePairs, source: str) -> None:
    """Shapes, finiteness and bounds of ``pairs``; ``model_invalid`` naming ``source`` and the
    array."""
    n_channels, n_controls = len(pairs.channels), len(pairs.controls)
    n_keys = len(pairs.key_names)
    reader = ArrayReader(
        {name: np.asarray(getattr(pairs, name), dtype=np.float64) for name in _ARRAYS}, source
    )
    if not 1 <= n_keys <= MAX_KEYS:
        raise reader.error("source_keys", f"must hold 1 to {MAX_KEYS} key poses, got {n_keys}")
    reader.floats("source_rest", (n_channels,))
    reader.floats("source_keys", (n_keys, n_channels))
    for name, shape in (("control_rest", (n_controls,)), ("control_keys", (n_keys, n_controls))):
        values = reader.floats(name, shape)
        if values.size and not ((values >= 0.0) & (values <= 1.0)).all():
            raise reader.error(name, "rig controls must lie in [0, 1]")
    weights = reader.floats("channel_weights", (n_channels,))
    if (weights < 0).any() or not (weights > 0).any():
        raise reader.error("channel_weights", "must be >= 0 with at least one channel fitted")


def save_map(directory: Path, retarget: RetargetMap) -> Path:
    """Write ``retarget`` to ``directory`` (created; files replaced atomically)."""
    directory.mkdir(parents=True, exist_ok=True)
    pairs = retarget.pairs
    temp_arrays = directory / (ARRAYS_NAME + ".tmp")
    with open(temp_arrays, "wb") as handle:
        arrays: dict[str, Any] = {
            name: np.ascontiguousarray(getattr(pairs, name)) for name in _ARRAYS
        }
        np.savez(handle, **arrays)
    temp_arrays.replace(directory / ARRAYS_NAME)
    manifest = {
        "schema_version": SCHEMA_VERSION,
        "name": retarget.name,
        "channels": list(pairs.channels),
        "controls": list(pairs.controls),
        "keys": list(pairs.key_names),
        "reproduction_error": retarget.reproduction_error(),
    }
    temp_manifest = directory / (MANIFEST_NAME + ".tmp")
    temp_manifest.write_text(json.dumps(manifest, indent=2, allow_nan=False) + "\n", "utf-8")
    temp_manifest.replace(directory / MANIFEST_NAME)
    return directory


def load_map(directory: Path, channels: Sequence[str] | None = None) -> RetargetMap:
    """The map stored in ``directory``, checked; with ``channels`` (a model's), its channels
    must be exactly those. ``model_invalid`` naming the file and field or array."""
    where = str(directory / MANIFEST_NAME)
    data = _read_json(directory / MANIFEST_NAME)
    fields = FieldReader(where)
    version = fields.member(data, "schema_version", "schema_version")
    if isinstance(version, bool) or version != SCHEMA_VERSION:
        raise fields.error("schema_version", f"must be {SCHEMA_VERSION}, got {version!r}")
    name = fields.string(fields.member(data, "name", "name"), "name")
    map_channels = fields.strings(
        fields.member(data, "channels", "channels"), "channels", unique=True, min_count=1
    )
    if channels is not None and tuple(map_channels) != tuple(channels):
        raise fields.error("channels", "do not match the model's channels (refit the map)")
    controls = fields.strings(
        fields.member(data, "controls", "controls"), "controls", unique=True, min_count=1
    )
    if len(controls) > MAX_CONTROLS:
        raise fields.error("controls", f"must name at most {MAX_CONTROLS} controls")
    keys = fields.strings(fields.member(data, "keys", "keys"), "keys", unique=True, min_count=1)
    arrays = load_arrays(directory)
    reader = ArrayReader(arrays, str(directory / ARRAYS_NAME))
    read = {
        name: np.asarray(
            reader.floats(name, (None,) * (2 if "keys" in name else 1)), dtype=np.float64
        )
        for name in _ARRAYS
    }
    pairs = KeyPosePairs(tuple(map_channels), tuple(controls), tuple(keys), **read)
    _check_pairs(pairs, str(directory / ARRAYS_NAME))
    return RetargetMap(name, pairs)


def stored_maps(model_directory: Path, channels: Sequence[str]) -> dict[str, RetargetMap]:
    """Every map stored under ``model_directory/retarget/``, by directory name."""
    root = model_directory / RETARGET_DIR
    if not root.is_dir():
        return {}
    return {
        directory.name: load_map(directory, channels)
        for directory in sorted(root.iterdir())
        if directory.is_dir()
    }


def read_pairs(path: Path, channels: Sequence[str]) -> KeyPosePairs:
    """Key-pose pairs from a JSON file, or a CSV file when its name ends in ``.csv``
    (docs/how-to/retarget.md, ``pairs_csv``), for a model with ``channels``; ``model_invalid``
    naming the file and field."""
    where = str(path)
    data = _read_csv(path) if _is_csv(path) else _read_json(path)
    fields = FieldReader(where)
    controls = fields.strings(
        fields.member(data, "controls", "controls"), "controls", unique=True, min_count=1
    )
    rest = fields.mapping(data.get("rest", {}), "rest")
    source_rest = _pose(fields, rest.get("source", {}), "rest.source", channels, None)
    control_rest = _pose(fields, rest.get("controls", {}), "rest.controls", controls, None)
    entries = data.get("keys")
    if not isinstance(entries, list) or not 1 <= len(entries) <= MAX_KEYS:
        raise fields.error("keys", f"must be a list of 1 to {MAX_KEYS} key poses")
    names, source_keys, control_keys = [], [], []
    for number, entry in enumerate(entries):
        field = f"keys[{number}]"
        key = fields.mapping(entry, field)
        names.append(fields.string(fields.member(key, "name", f"{field}.name"), f"{field}.name"))
        source = fields.member(key, "source", f"{field}.source")
        source_keys.append(_pose(fields, source, f"{field}.source", channels, source_rest))
        target = fields.member(key, "controls", f"{field}.controls")
        control_keys.append(_pose(fields, target, f"{field}.controls", controls, control_rest))
    if len(set(names)) != len(names):
        raise fields.error("keys", "key names must be unique")
    weights = _pose(
        fields, data.get("channel_weights", {}), "channel_weights", channels, np.ones(len(channels))
    )
    pairs = KeyPosePairs(
        tuple(channels),
        tuple(controls),
        tuple(names),
        source_rest,
        control_rest,
        np.stack(source_keys),
        np.stack(control_keys),
        weights,
    )
    _check_pairs(pairs, where)
    return pairs


def write_pairs(path: Path, pairs: KeyPosePairs) -> None:
    """Write ``pairs`` as a key-pose pairs file (CSV when the name ends in ``.csv``, else
    JSON) that ``read_pairs`` reads back exactly: each pose lists only the values that
    differ from rest."""

    def sparse(values: np.ndarray, names: Sequence[str], rest: np.ndarray) -> dict[str, float]:
        return {name: float(v) for name, v, r in zip(names, values, rest) if v != r}

    zeros_c, zeros_k = np.zeros(len(pairs.channels)), np.zeros(len(pairs.controls))
    data = {
        "controls": list(pairs.controls),
        "rest": {
            "source": sparse(pairs.source_rest, pairs.channels, zeros_c),
            "controls": sparse(pairs.control_rest, pairs.controls, zeros_k),
        },
        "keys": [
            {
                "name": name,
                "source": sparse(source, pairs.channels, pairs.source_rest),
                "controls": sparse(controls, pairs.controls, pairs.control_rest),
            }
            for name, source, controls in zip(
                pairs.key_names, pairs.source_keys, pairs.control_keys
            )
        ],
        "channel_weights": sparse(
            pairs.channel_weights, pairs.channels, np.ones(len(pairs.channels))
        ),
    }
    if _is_csv(path):
        path.write_text(document_csv(data, pairs.channels), encoding="utf-8")
        return
    path.write_text(json.dumps(data, indent=1, allow_nan=False) + "\n", encoding="utf-8")


def _is_csv(path: Path) -> bool:
    return path.suffix.lower() == ".csv"


def _pose(
    fields: FieldReader,
    value: Any,
    field: str,
    names: Sequence[str],
    default: np.ndarray | None,
) -> np.ndarray:
    """Values by name (``{name: number}``) over ``names``; names not given take ``default``
    (zeros when None)."""
    pose = np.zeros(len(names)) if default is None else np.array(default, dtype=np.float64)
    index = {name: position for position, name in enumerate(names)}
    for name, number in fields.mapping(value, field).items():
        if name not in index:
            raise fields.error(f"{field}.{name}", f"is not one of the {len(names)} names")
        pose[index[name]] = fields.number(number, f"{field}.{name}", -1e6, 1e6)
    return pose


def _read_bytes(path: Path) -> bytes:
    try:
        with open(path, "rb") as handle:
            raw = handle.read(MAX_PAIRS_BYTES + 1)
    except OSError as error:
        raise ModelStoreError(f"cannot read: {error}", where=str(path)) from None
    if len(raw) > MAX_PAIRS_BYTES:
        raise ModelStoreError(f"is larger than {MAX_PAIRS_BYTES} bytes", where=str(path))
    return raw


def _read_csv(path: Path) -> Mapping[str, Any]:
    raw = _read_bytes(path)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        raise ModelStoreError(f"is not UTF-8 text: {error}", where=str(path)) from None
    try:
        return csv_document(text, str(path))
    except csv.Error as error:
        raise ModelStoreError(f"is not valid CSV: {error}", where=str(path)) from None


def _read_json(path: Path) -> Mapping[str, Any]:
    raw = _read_bytes(path)
    try:
        data = json.loads(raw.decode("utf-8"), parse_constant=_refuse_constant)
    except (ValueError, UnicodeDecodeError, RecursionError) as error:
        raise ModelStoreError(f"is not valid JSON: {error}", where=str(path)) from None
    if not isinstance(data, dict):
        raise ModelStoreError("must hold a JSON object", where=str(path))
    return data


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number")
