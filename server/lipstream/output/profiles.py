"""Output profiles: which channels a request's frames carry, under which names and scaling.

Sketch: a profile (``lipstream_client.OutputProfile``) is resolved once per
request against the model's ARKit channel names, into a column gather (or a
viseme projection: Oculus 15 or Preston Blair) and per-column multiplier, offset and clamp
vectors, or, when it names a ``retarget`` map (``lipstream.output.retarget``), into
that map's rig controls. Applying it to a float32 block (n_frames,
n_model_channels) is then one gather, one multiply-add and one clip in numpy
(after the projection or the map, when there is one). The profile comes from
``start`` (its ``channels`` shorthand or its ``output``), else from the
character's preset, else it is ARKit naming with every channel. Presets are
read from the ``LIPSTREAM_PROFILES`` JSON file (``{"character": {output
profile}}``) or from a model manifest's ``extra["output_profile"]``, in the
JSON form of ``start.output``, and are validated by the same codec. The
command line (``lipstream synth``) resolves its profiles here too.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from lipstream_client import OutputProfile, ProtocolError, Start, decode
from lipstream_client.channels import VISEME_CHANNELS, canonical_viseme, rename_channel
from lipstream_client.errors import INVALID_REQUEST, UNKNOWN_CHANNEL, UNKNOWN_RETARGET
from lipstream_client.messages import VisemeSet

from ..engines.base import DEFAULT_EMOTION_KEY, Model, SynthesisResult
from ..errors import LipstreamError
from ..timeline import EMOTIONS
from .probes import mouth_channels, probe_key_poses
from .retarget import RetargetMap, RetargetStream
from .rig_presets import model_maps
from .viseme_projection import VISEME_SCHEMES, VisemeProjector

_FLOAT32_MAX = float(np.finfo(np.float32).max)


class ProfileError(LipstreamError):
    """A profile names a channel the rig lacks (``unknown_channel``) or is not usable
    (``invalid_request``)."""

    code = INVALID_REQUEST


@dataclass(frozen=True, eq=False)
class ResolvedProfile:
    """A profile bound to one model's channels.

    ``columns`` picks model columns or, in viseme mode (``projector`` set),
    columns of the viseme weights the projector computes first, or, with a
    ``retarget`` map, columns of the rig controls it computes first; then
    output column j is ``clip(value * multiplier[j] + offset[j], low[j], high[j])``.
    A profile is resolved per stream, so it holds the stream's retarget warm start.
    """

    channels: tuple[str, ...]
    columns: np.ndarray
    projector: VisemeProjector | None
    multiplier: np.ndarray
    offset: np.ndarray
    low: np.ndarray
    high: np.ndarray
    retarget: RetargetMap | None = None

    @property
    def n_channels(self) -> int:
        return len(self.channels)

    @cached_property
    def _retarget_stream(self) -> RetargetStream | None:
        return None if self.retarget is None else self.retarget.stream()

    @cached_property
    def identity(self) -> bool:
        """True when the profile passes model frames through unchanged."""
        return (
            self.projector is None
            and self.retarget is None
            and np.array_equal(self.columns, np.arange(len(self.columns)))
            and bool(np.all(self.multiplier == 1.0))
            and not np.any(self.offset)
            and bool(np.all(np.isinf(self.low)))
            and bool(np.all(np.isinf(self.high)))
        )

    def apply(self, frames: np.ndarray) -> np.ndarray:
        """Output frames float32 (n, n_channels) for model frames (n, n_model_channels).

        ProfileError (``invalid_request``) if a transform drives a value beyond float32;
        ValueError if the engine's frames are not finite (a server fault).
        """
        if self.identity and frames.shape[1] == len(self.columns):
            # One reduction, no temporary: a NaN or infinity makes the sum non-finite (float32
            # values cannot overflow a float64 sum; a float64 one that does looks further).
            total = float(np.add.reduce(frames, axis=None, dtype=np.float64))
            if not math.isfinite(total) and not np.isfinite(frames).all():
                raise ValueError("the engine produced non-finite values")
            return np.asarray(frames, dtype=np.float32)
        if self._retarget_stream is not None:
            source = self._retarget_stream.apply(frames)
        elif self.projector is not None:
            source = self.projector.weights(frames)
        else:
            source = np.asarray(frames, dtype=np.float64)
        selected = source[:, self.columns]
        values = np.clip(selected * self.multiplier + self.offset, self.low, self.high)
        if not np.all(np.abs(values) <= _FLOAT32_MAX):
            if not np.all(np.isfinite(selected)):
                raise ValueError("the engine produced non-finite values")
            raise ProfileError(
                "a transform drives a value beyond the float32 range", where="output.transforms"
            )
        return np.asarray(values, dtype=np.float32)


Lookup = Callable[[str, tuple[str, ...]], int | None]
ProjectorSource = Callable[[VisemeSet], VisemeProjector]
RetargetSource = Mapping[str, RetargetMap]
"""The retarget maps a model can be served through, by name."""


@dataclass(frozen=True)
class ProfileRequest:
    """A profile and the ``start`` field it came from (for error locations)."""

    profile: OutputProfile | None
    field: str = "output"

    def where(self, path: str) -> str:
        return f"{self.field}.{path}" if self.field else path


def requested_profile(start: Start, preset: OutputProfile | None) -> ProfileRequest:
    """The profile ``start`` asks for: its ``channels`` shorthand, its ``output``, else the
    character's preset (None: ARKit names, every channel)."""
    if start.channels is not None:
        return ProfileRequest(OutputProfile(channels=start.channels), "")
    if start.output is not None:
        return ProfileRequest(start.output)
    return ProfileRequest(preset, "preset")


def resolve_profile(
    model_channels: tuple[str, ...],
    request: ProfileRequest,
    projector: ProjectorSource,
    retargets: RetargetSource | None = None,
) -> ResolvedProfile:
    """Bind the requested profile to ``model_channels``; ``projector`` is called, with the
    viseme set, only for visemes; ``retargets`` holds the maps ``retarget`` may name.

    ProfileError: ``unknown_channel`` naming the field and name the rig lacks,
    ``unknown_retarget`` for a ``retarget`` the model has no map of (listing its maps),
    ``invalid_request`` for names that collide after renaming or canonicalising.
    """
    profile = request.profile or OutputProfile()
    lookup: Lookup
    retarget = None
    if profile.retarget is not None:
        retarget = _retarget(retargets or {}, profile.retarget, model_channels, request)
        available, lookup = retarget.controls, _exact_lookup
    elif profile.visemes is not None:
        available = VISEME_CHANNELS[profile.visemes]
        lookup = _viseme_lookup(profile.visemes)
    else:
        available = _renamed(model_channels, profile, request)
        lookup = _exact_lookup
    positions = _subset(profile, available, lookup, request)
    names = tuple(available[position] for position in positions)
    multiplier, offset, low, high = _transforms(profile, names, lookup, request)
    return ResolvedProfile(
        channels=names,
        columns=np.asarray(positions, dtype=np.intp),
        projector=None
        if profile.visemes is None
        else _checked_projector(projector, profile.visemes, len(model_channels), request),
        multiplier=multiplier,
        offset=offset,
        low=low,
        high=high,
        retarget=retarget,
    )


def _retarget(
    retargets: RetargetSource, name: str, model_channels: tuple[str, ...], request: ProfileRequest
) -> RetargetMap:
    found = retargets.get(name)
    if found is None:
        known = ", ".join(retargets) or "none"
        raise ProfileError(
            f"no rig preset or retarget map {name!r} for this model; its maps: {known}",
            where=request.where("retarget"),
            code=UNKNOWN_RETARGET,
        )
    if found.channels != model_channels:
        raise ProfileError(
            f"retarget map {name!r} was fitted for other channels than this model's",
            where=request.where("retarget"),
        )
    return found


def _checked_projector(
    projector: ProjectorSource, visemes: VisemeSet, width: int, request: ProfileRequest
) -> VisemeProjector:
    built = projector(visemes)
    if built.n_channels != width:
        raise ProfileError(
            "the character's viseme key poses do not match this model's channels",
            where=request.where("visemes"),
        )
    return built


def _renamed(
    model_channels: tuple[str, ...], profile: OutputProfile, request: ProfileRequest
) -> tuple[str, ...]:
    naming = profile.naming or "arkit"
    names = tuple(rename_channel(name, naming) for name in model_channels)
    if len(set(names)) != len(names):
        clash = next(name for name in names if names.count(name) > 1)
        raise ProfileError(
            f"naming {naming!r} gives two channels the name {clash!r}",
            where=request.where("naming"),
        )
    return names


def _exact_lookup(name: str, available: tuple[str, ...]) -> int | None:
    return available.index(name) if name in available else None


def _viseme_lookup(visemes: VisemeSet) -> Lookup:
    def lookup(name: str, available: tuple[str, ...]) -> int | None:
        canonical = canonical_viseme(name, visemes)
        return available.index(canonical) if canonical in available else None

    return lookup


def _subset(
    profile: OutputProfile, available: tuple[str, ...], lookup: Lookup, request: ProfileRequest
) -> list[int]:
    if profile.channels is None:
        return list(range(len(available)))
    positions: list[int] = []
    for number, name in enumerate(profile.channels):
        where = request.where(f"channels[{number}]")
        position = lookup(name, available)
        if position is None:
            raise _unknown(name, where, available)
        if position in positions:
            raise ProfileError(f"{name!r} names {available[position]!r} a second time", where=where)
        positions.append(position)
    return positions


def _transforms(
    profile: OutputProfile, names: tuple[str, ...], lookup: Lookup, request: ProfileRequest
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    width = len(names)
    multiplier, offset = np.ones(width), np.zeros(width)
    low, high = np.full(width, -np.inf), np.full(width, np.inf)
    seen: set[int] = set()
    for name, transform in profile.transforms.items():
        where = request.where(f"transforms.{name}")
        column = lookup(name, names)
        if column is None:
            raise _unknown(name, where, names)
        if column in seen:
            raise ProfileError(f"a second transform for {names[column]!r}", where=where)
        seen.add(column)
        multiplier[column], offset[column] = transform.multiplier, transform.offset
        if transform.clamp is not None:
            low[column], high[column] = transform.clamp
    return multiplier, offset, low, high


def _unknown(name: str, where: str, available: tuple[str, ...]) -> ProfileError:
    shown = ", ".join(available[:8]) + (", ..." if len(available) > 8 else "")
    return ProfileError(
        f"no output channel {name!r}; the output channels are {shown}",
        where=where,
        code=UNKNOWN_CHANNEL,
    )


def parse_profile(value: object, where: str) -> OutputProfile:
    """An output profile in the JSON form of ``start.output``, validated by the codec."""
    payload = {
        "v": 1,
        "type": "start",
        "id": "preset",
        "engine": "preset",
        "character": "preset",
        "output": value,
    }
    decoded = decode(json.dumps(payload), "json", sender="client")
    if isinstance(decoded, ProtocolError) or not isinstance(decoded, Start):
        reason = str(decoded) if isinstance(decoded, ProtocolError) else "not a profile"
        raise LipstreamError(
            f"invalid output profile: {reason}", where=where, code="invalid_setting"
        )
    assert decoded.output is not None
    return decoded.output


def load_presets(path: Path) -> dict[str, OutputProfile]:
    """Per-character presets from a JSON file ``{"character": {output profile}, ...}``; a
    preset's ``default_emotion`` is not part of its profile (``load_default_emotions``)."""
    data = _json_object(path, "output profiles", "mapping characters to output profiles")
    return {
        str(name): parse_profile(_without_emotion(value), f"{path}: {name}")
        for name, value in data.items()
    }


def load_default_emotions(path: Path) -> dict[str, str]:
    """Per-character ``default_emotion`` of the presets in ``path`` that name one;
    ``invalid_setting`` for an emotion outside ``EMOTIONS``."""
    data = _json_object(path, "output profiles", "mapping characters to output profiles")
    emotions: dict[str, str] = {}
    for name, value in data.items():
        if not isinstance(value, Mapping) or DEFAULT_EMOTION_KEY not in value:
            continue
        emotion = value[DEFAULT_EMOTION_KEY]
        if emotion not in EMOTIONS:
            raise LipstreamError(
                f"default_emotion must be one of {', '.join(EMOTIONS)}, got {emotion!r}",
                where=f"{path}: {name}.{DEFAULT_EMOTION_KEY}",
                code="invalid_setting",
            )
        emotions[str(name)] = str(emotion)
    return emotions


def _without_emotion(value: object) -> object:
    if isinstance(value, Mapping):
        return {key: item for key, item in value.items() if key != DEFAULT_EMOTION_KEY}
    return value


def profile_fields(path: Path) -> dict[str, object]:
    """The fields of one output profile in a JSON file (validated by ``parse_profile`` once
    the caller has laid its own over them)."""
    return dict(_json_object(path, "the output profile", "holding an output profile"))


def _json_object(path: Path, what: str, holding: str) -> Mapping[str, object]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        raise LipstreamError(
            f"cannot read {what}: {error}", where=str(path), code="invalid_setting"
        ) from None
    if not isinstance(data, Mapping):
        raise LipstreamError(
            f"must be a JSON object {holding}", where=str(path), code="invalid_setting"
        )
    return data


def apply_to_result(
    model: Model,
    result: SynthesisResult,
    profile: OutputProfile | None,
    field: str = "profile",
    directory: Path | None = None,
) -> SynthesisResult:
    """A whole synthesis of ``model`` through ``profile`` (errors located under ``field``).

    The command line's path: visemes are projected onto key poses probed from ``model``
    itself, as the server does for a character without a ``viseme-lerp`` model; a
    ``retarget`` map is found as the server finds it, stored in the model's ``directory`` or
    shipped."""
    if profile is None:
        return result

    def projector(visemes: VisemeSet) -> VisemeProjector:
        poses = probe_key_poses(model, VISEME_SCHEMES[visemes])
        return VisemeProjector(poses, mouth_channels(model.channels))

    retargets = (
        model_maps(model, directory, only=profile.retarget) if profile.retarget is not None else {}
    )
    resolved = resolve_profile(model.channels, ProfileRequest(profile, field), projector, retargets)
    return SynthesisResult(
        resolved.apply(result.frames), resolved.channels, result.fps, dict(result.stats)
    )
