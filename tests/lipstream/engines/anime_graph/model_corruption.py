"""Corrupted copies of a stored anime-graph model, and a sweep that loads and serves each.

Every ``Corruption`` changes one array or one manifest field of a real model
and names the file and the array or field a ``model_invalid`` error must name.
Arrays of a view are named ``all_<array>`` (the whole corpus) or
``emotion_<array>``, which stands for the model's first emotion view.

Run as a module (``python -m tests.lipstream.engines.anime_graph.model_corruption
MODEL SCRATCH [RANDOM]``), the sweep writes each variant into SCRATCH in turn,
loads it with ``lipstream.load_model`` and, when it loads, synthesizes a few
requests (with and without audio, clustered, PQ). It prints one JSON line when a
variant begins and one with its outcome, so a variant that kills the process by
a signal is the last one begun. ``RANDOM`` more variants set one integer of an
index array to a random value inside the array's own range.
"""

from __future__ import annotations

import json
import shutil
import sys
from collections.abc import Callable, Iterator, MutableMapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lipstream.store import ARRAYS_NAME, MANIFEST_NAME, load_arrays

Arrays = MutableMapping[str, np.ndarray]
Manifest = dict[str, Any]
EMOTION = "emotion"

VIEW_INDEX_ARRAYS = (
    "members",
    "substitution",
    "index_transitions",
    "index_low",
    "index_high",
    "index_ends",
    "index_text_anime",
    "cluster_assignment",
    "cluster_representative",
)
INDEX_ARRAYS = (
    "anime_label",
    "anime_utterance",
    "motion_offsets",
    "feature_offsets",
    *(f"{view}_{name}" for view in ("all", EMOTION) for name in VIEW_INDEX_ARRAYS),
)
ORDERED_ARRAYS = ("anime_utterance", "motion_offsets", "feature_offsets", "all_members")
FLOAT_ARRAYS = (
    "basis_mean",
    "basis_components",
    "channel_low",
    "channel_high",
    "anime_start",
    "anime_end",
    "motion",
    "features",
    "anime_summary",
    "cutoffs",
)
# Arrays whose truncation is first seen as a mismatch in the array sized by them.
TRUNCATION_BLAME = {
    "anime_label": ("anime_label", "anime_utterance"),
    "all_cluster_representative": ("all_cluster_representative", "all_cluster_assignment"),
    "emotion_cluster_representative": (
        "emotion_cluster_representative",
        "emotion_cluster_assignment",
    ),
}


@dataclass(frozen=True)
class Corruption:
    """``id`` names the variant; the error's ``where`` must name ``file`` and one of
    ``names`` (a field path or an array name)."""

    id: str
    file: str
    names: tuple[str, ...]
    arrays: Callable[[Arrays], None] | None = None
    manifest: Callable[[Manifest], str] | None = None


def _set(name: str, value: float) -> Callable[[Arrays], None]:
    """One value halfway along a 1-D array; the whole first row of a 2-D one (the root's
    transitions, read by every search). Integer arrays too narrow for it are widened."""

    def apply(arrays: Arrays) -> None:
        array = arrays[name].copy()
        if (
            array.dtype.kind == "i"
            and not np.iinfo(array.dtype).min <= value <= np.iinfo(array.dtype).max
        ):
            array = array.astype(np.int64)
        if array.ndim == 1:
            array[len(array) // 2] = value
        else:
            array[0] = value
        arrays[name] = array

    return apply


def _truncate(name: str) -> Callable[[Arrays], None]:
    def apply(arrays: Arrays) -> None:
        array = arrays[name]
        arrays[name] = array[:-1].copy() if array.ndim == 1 else array[..., :-1].copy()

    return apply


def _drop(name: str) -> Callable[[Arrays], None]:
    def apply(arrays: Arrays) -> None:
        del arrays[name]

    return apply


def _unorder(name: str) -> Callable[[Arrays], None]:
    """Swap two neighbours that differ, halfway along: the array is no longer ascending."""

    def apply(arrays: Arrays) -> None:
        array = arrays[name].copy()
        changes = np.flatnonzero(np.diff(array))
        at = int(changes[len(changes) // 2])
        array[at], array[at + 1] = array[at + 1], array[at]
        arrays[name] = array

    return apply


def _scale(name: str, factor: float) -> Callable[[Arrays], None]:
    def apply(arrays: Arrays) -> None:
        arrays[name] = arrays[name] * factor

    return apply


def _field(path: str, value: Any) -> Callable[[Manifest], str]:
    """Set (or, with ``value`` ``_DELETE``, delete) the dotted ``path`` of the manifest."""

    def apply(manifest: Manifest) -> str:
        *parents, key = path.split(".")
        node = manifest
        for parent in parents:
            node = node[parent]
        if value is _DELETE:
            del node[key]
        else:
            node[key] = value
        return json.dumps(manifest)

    return apply


_DELETE = object()


def _nested(depth: int) -> Callable[[Manifest], str]:
    """``metrics.deep`` as ``depth`` nested lists, written by hand (json.dumps would
    recurse)."""

    def apply(manifest: Manifest) -> str:
        manifest["metrics"]["deep"] = "@"
        return json.dumps(manifest).replace('"@"', "[" * depth + "]" * depth)

    return apply


def _array_corruptions() -> list[Corruption]:
    found: list[Corruption] = []

    def add(name: str, kind: str, apply: Callable[[Arrays], None], *names: str) -> None:
        found.append(Corruption(f"{name}-{kind}", ARRAYS_NAME, names or (name,), arrays=apply))

    for name in INDEX_ARRAYS:
        add(name, "too_large", _set(name, 2**30))
        add(name, "negative", _set(name, -2))
        add(name, "truncated", _truncate(name), *TRUNCATION_BLAME.get(name, (name,)))
        add(name, "missing", _drop(name))
    for name in ORDERED_ARRAYS:
        add(name, "unordered", _unorder(name))
    for name in FLOAT_ARRAYS:
        add(name, "nan", _set(name, float("nan")))
        add(name, "inf", _set(name, float("inf")))
        add(name, "truncated", _truncate(name), *TRUNCATION_BLAME.get(name, (name,)))
        add(name, "missing", _drop(name))
    for name in ("basis_mean", "basis_components", "motion", "anime_end"):
        add(name, "huge", _scale(name, 1e30))
    add("anime_start", "negative", _set("anime_start", -1.0))
    add("channel_high", "below_low", _scale("channel_high", -1.0), "channel_high", "basis_mean")
    return found


def _manifest_corruptions() -> list[Corruption]:
    cases: list[tuple[str, Any]] = [
        ("fps", "sixty"),
        ("fps", -1),
        ("fps", 1e9),
        ("fps", True),
        ("fps", None),
        ("fps", _DELETE),
        ("channels", "jawOpen"),
        ("channels", [1, 2]),
        ("channels", []),
        ("channels", _DELETE),
        ("name", 5),
        ("name", ""),
        ("name", "a\nb"),
        ("name", _DELETE),
        ("engine", 7),
        ("engine", _DELETE),
        ("phoneme_set", ["AA"]),
        ("phoneme_set", "AA"),
        ("phoneme_set", _DELETE),
        ("hyperparameters", [1]),
        ("hyperparameters.max_tile", "ten"),
        ("hyperparameters.max_tile", 0),
        ("hyperparameters.max_tile", _DELETE),
        ("hyperparameters.max_candidates", 2.5),
        ("hyperparameters.smoothing_window", "wide"),
        ("hyperparameters.smoothing_window", 50),
        ("hyperparameters.graph", "dense"),
        ("extra", "none"),
        ("extra.mfcc", "default"),
        ("extra.mfcc.rate", "fast"),
        ("extra.mfcc.rate", 0),
        ("extra.mfcc.n_coefficients", 100),
        ("extra.mfcc.bogus", 1),
        ("extra.mfcc.n_mels", _DELETE),
        ("extra.views", "all"),
        ("extra.views", ["happy"]),
        ("extra.views", [["all"]]),
        ("extra.audio_features", "yes"),
        ("extra.audio_features", _DELETE),
    ]
    found = [
        Corruption(
            f"{path}={'deleted' if value is _DELETE else json.dumps(value)}",
            MANIFEST_NAME,
            (path,),
            manifest=_field(path, value),
        )
        for path, value in cases
    ]
    found += [
        Corruption("nested-10000", MANIFEST_NAME, (MANIFEST_NAME,), manifest=_nested(10_000)),
        Corruption("nested-40", MANIFEST_NAME, (MANIFEST_NAME,), manifest=_nested(40)),
        Corruption(
            "fps=NaN",
            MANIFEST_NAME,
            (MANIFEST_NAME,),
            manifest=lambda manifest: json.dumps(manifest).replace(
                f'"fps": {json.dumps(manifest["fps"])}', '"fps": NaN'
            ),
        ),
        Corruption(
            "channels+1",
            ARRAYS_NAME,
            ("basis_mean", "channel_low"),
            manifest=lambda manifest: json.dumps(
                {**manifest, "channels": [*manifest["channels"], "extraChannel"]}
            ),
        ),
    ]
    return found


CORRUPTIONS: tuple[Corruption, ...] = (*_array_corruptions(), *_manifest_corruptions())


def emotion_view(manifest: Manifest) -> str:
    """The view that ``emotion_`` names stand for: the model's first emotion view."""
    return str(next(view for view in manifest["extra"]["views"] if view != "all"))


def resolve(name: str, manifest: Manifest) -> str:
    """``name`` with an ``emotion_`` prefix replaced by the model's emotion view."""
    prefix = f"{EMOTION}_"
    return emotion_view(manifest) + "_" + name[len(prefix) :] if name.startswith(prefix) else name


def read_model(directory: Path) -> tuple[dict[str, np.ndarray], Manifest]:
    arrays = {name: np.array(array) for name, array in load_arrays(directory).items()}
    return arrays, json.loads((directory / MANIFEST_NAME).read_text(encoding="utf-8"))


def random_corruptions(
    manifest: Manifest, arrays: Arrays, count: int, seed: int
) -> list[Corruption]:
    """``count`` variants each setting one integer of an index array to a random value
    between the array's own minimum and maximum."""
    rng = np.random.default_rng(seed)
    names = [resolve(name, manifest) for name in INDEX_ARRAYS]
    found: list[Corruption] = []
    for number in range(count):
        name = names[int(rng.integers(len(names)))]
        array = arrays[name]
        if array.size == 0:
            continue
        position = int(rng.integers(array.size))
        value = int(rng.integers(int(array.min()), int(array.max()) + 1))

        def apply(
            target: Arrays, name: str = name, position: int = position, value: int = value
        ) -> None:
            changed = target[name].copy()
            changed.reshape(-1)[position] = value
            target[name] = changed

        found.append(
            Corruption(f"random{number}-{name}[{position}]={value}", ARRAYS_NAME, (name,), apply)
        )
    return found


def write_variant(corruption: Corruption, arrays: Arrays, manifest: Manifest, out: Path) -> None:
    """The model ``arrays`` and ``manifest`` with ``corruption`` applied, saved in ``out`` as
    ``lipstream.store`` lays a model out (uncompressed ``.npz``, JSON manifest)."""
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    changed = dict(arrays)
    if corruption.arrays is not None:
        corruption.arrays(_ViewAliases(changed, manifest))
    np.savez(out / ARRAYS_NAME, allow_pickle=False, **changed)
    declared = {
        "arrays_file_bytes": (out / ARRAYS_NAME).stat().st_size,
        "array_data_bytes": {name: int(np.asarray(a).nbytes) for name, a in changed.items()},
    }
    text = json.dumps({**manifest, **declared})
    if corruption.manifest is not None:
        text = corruption.manifest(json.loads(text))
    (out / MANIFEST_NAME).write_text(text, encoding="utf-8")


class _ViewAliases(MutableMapping[str, np.ndarray]):
    """The model's arrays, with ``emotion_<array>`` standing for the emotion view's."""

    def __init__(self, arrays: Arrays, manifest: Manifest) -> None:
        self._arrays = arrays
        self._manifest = manifest

    def __getitem__(self, name: str) -> np.ndarray:
        return self._arrays[resolve(name, self._manifest)]

    def __setitem__(self, name: str, value: np.ndarray) -> None:
        self._arrays[resolve(name, self._manifest)] = value

    def __delitem__(self, name: str) -> None:
        del self._arrays[resolve(name, self._manifest)]

    def __iter__(self) -> Iterator[str]:
        return iter(self._arrays)

    def __len__(self) -> int:
        return len(self._arrays)


def _serve(directory: Path) -> dict[str, Any]:
    """Load ``directory`` and synthesize a few requests: the outcome of each."""
    from lipstream.audio import Audio
    from lipstream.engines import load_model
    from lipstream.errors import LipstreamError

    try:
        model = load_model(directory)
    except LipstreamError as error:
        return {"code": error.code, "where": error.where, "message": error.message}
    except Exception as error:  # the sweep reports every failure, the test judges it
        return {"raised": f"{type(error).__name__}: {error}"}
    spans = [
        ("sil", 0.0, 0.1),
        ("HH", 0.1, 0.18, "happy"),
        ("AY", 0.18, 0.42),
        ("M", 0.42, 0.5, "sad"),
        ("sil", 0.5, 0.7),
    ]
    rng = np.random.default_rng(0)
    audio = Audio((0.1 * rng.standard_normal(int(0.8 * 16000))).astype(np.float32), 16000)
    requests: list[tuple[str, dict[str, Any], Audio | None]] = [
        ("greedy", {}, None),
        ("audio", {}, audio),
        ("clustered", {"graph": "clustered"}, None),
        ("pq", {"search": "pq", "pq_window": 2}, audio),
    ]
    outcomes: dict[str, str] = {}
    for label, options, sound in requests:
        try:
            frames = model.synthesize(spans, fps=60.0, audio=sound, **options).frames
            outcomes[label] = "finite" if np.isfinite(frames).all() else "not finite"
        except LipstreamError as error:
            outcomes[label] = error.code
        except Exception as error:  # the sweep reports every failure, the test judges it
            outcomes[label] = f"raised {type(error).__name__}: {error}"
    return {"loaded": outcomes}


def sweep(model: Path, scratch: Path, random_count: int, seed: int = 0) -> None:
    arrays, manifest = read_model(model)
    variants = [*CORRUPTIONS, *random_corruptions(manifest, arrays, random_count, seed)]
    for corruption in variants:
        print(json.dumps({"begin": corruption.id}), flush=True)
        write_variant(corruption, arrays, manifest, scratch / "model")
        print(json.dumps({"id": corruption.id, **_serve(scratch / "model")}), flush=True)


def read_sweep(output: str) -> tuple[dict[str, dict[str, Any]], str | None]:
    """The outcome of each variant, and the variant begun last without an outcome."""
    outcomes: dict[str, dict[str, Any]] = {}
    begun: str | None = None
    for line in output.splitlines():
        record = json.loads(line)
        if "begin" in record:
            begun = record["begin"]
        else:
            outcomes[record["id"]] = record
            begun = None
    return outcomes, begun


def main(argv: Sequence[str]) -> None:
    model, scratch, *rest = argv
    sweep(Path(model), Path(scratch), int(rest[0]) if rest else 0)


if __name__ == "__main__":
    main(sys.argv[1:])
