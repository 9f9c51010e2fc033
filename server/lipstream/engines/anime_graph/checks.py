"""What a stored anime-graph model must satisfy before its compiled kernels see it.

Sketch: ``check_stored_model`` runs once, in ``AnimeGraphModel.from_arrays``,
and declares every manifest field and array the model reads (see
``lipstream.model_checks``): hyperparameters and MFCC settings typed and
bounded; arrays of the right kind and shape, floats finite; the motion basis
orthonormal, its mean inside the recorded channel range and no stored pose
longer than that range allows (so no finite but huge value overflows on the
way to a frame); animes' labels, recordings and spans in range, a span ending
at most one frame period after its recording (what a corpus allows);
per-recording curves as offsets that give every recording at least one
sample (a kernel reads the first and last sample of each); audio summaries
and features as wide as a request's; every view's members whole recordings,
its stand-ins phonemes the view says, its clusters in range; every float
within ``MAX_MAGNITUDE``, and each smoothing cutoff a frequency from 0 to the
corpus's Nyquist rate (fps / 2 Hz).

The suffix automaton gets a structural check, since the greedy kernel follows
its transitions blindly and turns an occurrence into anime ids by arithmetic:
the text rebuilt from the view's recordings must match the stored anime of
each text position, ``ends`` must be a permutation of the text positions, no
transition may enter the root, and along every transition v -c-> u each end
e of u must have text[e] = c and, unless v is the root, e - 1 among the ends
of v. By induction every end of the state reached by reading a query q of
length L then closes an occurrence of q, so e - L + 1 >= 0 and the L text
positions are consecutive animes of one recording: every anime id the kernel
forms is in range. The check touches each (transition, end) pair once, at
most the text length times the longest recording's phoneme count.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from ...errors import ModelStoreError
from ...features import MfccConfig
from ...model_checks import ArrayReader, FieldReader, check_ascending, check_indices
from ...numerics.basis import read_components
from ...phonemes import PHONEMES
from ...store import ARRAYS_NAME, MANIFEST_NAME, ModelManifest
from .animes import SUMMARY_POINTS
from .index import join_text
from .options import GRAPHS
from .views import WHOLE

MAX_VIEWS = 64
_PAIRS_PER_CHUNK = 1 << 20
_ROWS_PER_CHUNK = 1 << 16


@dataclass(frozen=True)
class _Sizes:
    """Dimensions every array is checked against."""

    n_animes: int
    n_recordings: int
    n_components: int
    summary_width: int


def check_stored_model(
    manifest: ModelManifest, arrays: Mapping[str, np.ndarray], directory: Path
) -> None:
    """``model_invalid`` naming the file and the field or array at the first fault."""
    fields_of = FieldReader(str(directory / MANIFEST_NAME))
    graph, views, mfcc, has_audio = _check_manifest(manifest, fields_of)
    reader = ArrayReader(arrays, str(directory / ARRAYS_NAME))
    sizes = _check_animes(reader, len(manifest.channels), manifest.fps, mfcc, has_audio)
    labels = np.asarray(reader.arrays["anime_label"], dtype=np.int64)
    utterance = np.asarray(reader.arrays["anime_utterance"], dtype=np.int64)
    for name in views:
        clusters = _check_view(reader, name, labels, utterance, sizes)
        if name == WHOLE and graph == "clustered" and clusters == 0:
            raise fields_of.error(
                "hyperparameters.graph",
                f"is 'clustered' but the {WHOLE!r} view has no clusters",
            )


def _check_manifest(
    manifest: ModelManifest, fields_of: FieldReader
) -> tuple[str, list[str], MfccConfig, bool]:
    settings = manifest.hyperparameters
    for name, low in (("max_tile", 1), ("max_candidates", 1)):
        fields_of.integer(
            fields_of.member(settings, name, f"hyperparameters.{name}"),
            f"hyperparameters.{name}",
            low,
            10**6,
        )
    fields_of.number(
        fields_of.member(settings, "smoothing_window", "hyperparameters.smoothing_window"),
        "hyperparameters.smoothing_window",
        0.0,
        1.0,
    )
    graph = fields_of.string(
        fields_of.member(settings, "graph", "hyperparameters.graph"),
        "hyperparameters.graph",
        choices=GRAPHS,
    )
    extra = manifest.extra
    mfcc = _check_mfcc(
        fields_of.mapping(fields_of.member(extra, "mfcc", "extra.mfcc"), "extra.mfcc"), fields_of
    )
    has_audio = fields_of.flag(
        fields_of.member(extra, "audio_features", "extra.audio_features"), "extra.audio_features"
    )
    views = fields_of.strings(
        fields_of.member(extra, "views", "extra.views"), "extra.views", unique=True
    )
    if WHOLE not in views:
        raise fields_of.error("extra.views", f"must name the {WHOLE!r} view")
    if len(views) > MAX_VIEWS:
        raise fields_of.error("extra.views", f"must name at most {MAX_VIEWS} views")
    return graph, views, mfcc, has_audio


def _check_mfcc(values: Mapping[str, object], fields_of: FieldReader) -> MfccConfig:
    unknown = sorted(set(values) - {field.name for field in fields(MfccConfig)})
    if unknown:
        raise fields_of.error(f"extra.mfcc.{unknown[0]}", "is not an MFCC setting")

    def number(name: str, high: float, *, above: bool = True) -> float:
        field = f"extra.mfcc.{name}"
        return fields_of.number(
            fields_of.member(values, name, field), field, 0.0, high, above=above
        )

    def integer(name: str) -> int:
        field = f"extra.mfcc.{name}"
        return fields_of.integer(fields_of.member(values, name, field), field, 1, 512)

    config = MfccConfig(
        rate=number("rate", 1000.0),
        window_s=number("window_s", 1.0),
        n_mels=integer("n_mels"),
        n_coefficients=integer("n_coefficients"),
        f_min=number("f_min", 48000.0, above=False),
        f_max=number("f_max", 48000.0),
        pre_emphasis=number("pre_emphasis", 0.999, above=False),
    )
    if config.n_coefficients > config.n_mels:
        raise fields_of.error("extra.mfcc.n_coefficients", "must not exceed extra.mfcc.n_mels")
    if config.f_max <= config.f_min:
        raise fields_of.error("extra.mfcc.f_max", "must exceed extra.mfcc.f_min")
    return config


def _check_animes(
    reader: ArrayReader, n_channels: int, fps: float, mfcc: MfccConfig, has_audio: bool
) -> _Sizes:
    """The model-wide arrays: motion basis, channel range, animes, curves, summaries."""
    low = np.asarray(reader.floats("channel_low", (n_channels,)), dtype=np.float64)
    high = np.asarray(reader.floats("channel_high", (n_channels,)), dtype=np.float64)
    if (low > high).any():
        raise reader.error("channel_high", "lies below channel_low")
    slack = 1e-6 * (1.0 + np.abs(low) + np.abs(high))
    mean = reader.floats("basis_mean", (n_channels,))
    if ((mean < low - slack) | (mean > high + slack)).any():
        raise reader.error("basis_mean", "lies outside [channel_low, channel_high]")
    components = read_components(reader, "basis_components", n_channels)
    n_components = len(components)
    labels = reader.integers("anime_label", (None,), 0, len(PHONEMES))
    n_animes = len(labels)
    if n_animes < 1:
        raise reader.error("anime_label", "holds no anime")
    motion = reader.floats("motion", (None, n_components))
    # A projection of a pose inside the channel box is no longer than the box's diagonal.
    reach = 1.001 * float(np.linalg.norm(high - low)) + 1e-6
    for first in range(0, len(motion), _ROWS_PER_CHUNK):
        rows = np.asarray(motion[first : first + _ROWS_PER_CHUNK], dtype=np.float64)
        if (np.einsum("ij,ij->i", rows, rows) > reach * reach).any():
            raise reader.error("motion", "holds a pose outside the channels' recorded range")
    motion_offsets = reader.offsets("motion_offsets", None, len(motion), nonempty=True)
    n_recordings = len(motion_offsets) - 1
    utterance = reader.integers("anime_utterance", (n_animes,), 0, n_recordings)
    check_ascending(reader.where("anime_utterance"), utterance, strict=False)
    _check_times(reader, n_animes, np.diff(motion_offsets)[utterance] / fps)
    summary_width = 0
    if has_audio:
        features = reader.floats("features", (None, mfcc.n_coefficients))
        reader.offsets("feature_offsets", n_recordings, len(features), nonempty=True)
        summary_width = SUMMARY_POINTS * mfcc.n_coefficients
    reader.floats("anime_summary", (n_animes, summary_width))
    reader.floats("cutoffs", (n_components,), 0.0, fps / 2.0)  # Hz, up to Nyquist
    return _Sizes(n_animes, n_recordings, n_components, summary_width)


def _check_times(reader: ArrayReader, n_animes: int, recorded: np.ndarray) -> None:
    """Anime spans (s) ordered and inside their recording of ``recorded`` seconds per anime
    (a corpus lets a phone end up to one frame period after the last frame)."""
    start = np.asarray(reader.floats("anime_start", (n_animes,)))
    end = np.asarray(reader.floats("anime_end", (n_animes,)))
    if (start < 0.0).any():
        raise reader.error("anime_start", "holds a negative time")
    if (end < start).any():
        raise reader.error("anime_end", "holds an end before its start")
    if (end > recorded + 1e-6).any():
        at = int(np.argmax(end > recorded + 1e-6))
        raise reader.error("anime_end", f"anime {at} ends after its recording")


def _check_view(
    reader: ArrayReader, name: str, labels: np.ndarray, utterance: np.ndarray, sizes: _Sizes
) -> int:
    """One view's arrays; returns its number of clusters."""
    members = reader.integers(f"{name}_members", (None,), 0, sizes.n_animes)
    if len(members) == 0:
        raise reader.error(f"{name}_members", "holds no anime")
    check_ascending(reader.where(f"{name}_members"), members, strict=True)
    members = np.asarray(members, dtype=np.int64)
    held = np.bincount(utterance[members], minlength=sizes.n_recordings)
    whole = np.bincount(utterance, minlength=sizes.n_recordings)
    if ((held != 0) & (held != whole)).any():
        recording = int(np.argmax((held != 0) & (held != whole)))
        raise reader.error(f"{name}_members", f"holds part of recording {recording}, not all")
    said = np.zeros(len(PHONEMES), dtype=bool)
    said[labels[members]] = True
    substitution = reader.integers(f"{name}_substitution", (len(PHONEMES),), 0, len(PHONEMES))
    if not said[np.asarray(substitution, dtype=np.int64)].all():
        raise reader.error(f"{name}_substitution", "names a phoneme the view never says")
    _check_index(reader, name, labels, utterance, members)
    representative = reader.integers(f"{name}_cluster_representative", (None,), 0, sizes.n_animes)
    clusters = len(representative)
    reader.integers(
        f"{name}_cluster_assignment", (len(members) if clusters else 0,), 0, max(clusters, 1)
    )
    if clusters and not np.isin(representative, members).all():
        raise reader.error(f"{name}_cluster_representative", "names an anime outside the view")
    return clusters


def _check_index(
    reader: ArrayReader, name: str, labels: np.ndarray, utterance: np.ndarray, members: np.ndarray
) -> None:
    """The view's suffix automaton (see the module sketch)."""
    alphabet = len(PHONEMES)
    text, expected_anime = join_text(labels[members], utterance[members], members, alphabet)
    size = len(text)
    text_anime = reader.integers(f"{name}_index_text_anime", (size,))
    if not np.array_equal(text_anime, expected_anime):
        at = int(np.argmax(np.asarray(text_anime) != expected_anime))
        raise reader.error(
            f"{name}_index_text_anime", f"differs from the view's recordings at position {at}"
        )
    transitions = reader.integers(f"{name}_index_transitions", (None, alphabet + 1))
    n_states = len(transitions)
    if n_states < 1:
        raise reader.error(f"{name}_index_transitions", "holds no state")
    check_indices(reader.where(f"{name}_index_transitions"), transitions, -1, n_states)
    if (np.asarray(transitions) == 0).any():
        raise reader.error(f"{name}_index_transitions", "has a transition into the root")
    ends = reader.integers(f"{name}_index_ends", (size,), 0, size)
    if (np.bincount(ends, minlength=size) != 1).any():
        raise reader.error(f"{name}_index_ends", "is not a permutation of the text positions")
    low = reader.integers(f"{name}_index_low", (n_states,), 0, size + 1)
    high = reader.integers(f"{name}_index_high", (n_states,), 0, size + 1)
    if (np.asarray(low) > np.asarray(high)).any():
        raise reader.error(f"{name}_index_high", "lies below index_low")
    _check_transitions(
        reader.where(f"{name}_index_transitions"),
        np.asarray(transitions, dtype=np.int64),
        np.asarray(low, dtype=np.int64),
        np.asarray(high, dtype=np.int64),
        np.asarray(ends, dtype=np.int64),
        text,
    )


def _check_transitions(
    where: str,
    transitions: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    ends: np.ndarray,
    text: np.ndarray,
) -> None:
    """Along every transition v -c-> u, each end e of u has text[e] == c and, for v other
    than the root, e - 1 among the ends of v; pairs are checked in bounded chunks."""
    rank = np.empty(len(ends), dtype=np.int64)
    rank[ends] = np.arange(len(ends))
    sources, symbols = np.nonzero(transitions >= 0)
    targets = transitions[sources, symbols]
    sizes = high[targets] - low[targets]
    bounds = np.cumsum(sizes)
    first = 0
    while first < len(sources):
        base = int(bounds[first - 1]) if first else 0
        stop = max(int(np.searchsorted(bounds, base + _PAIRS_PER_CHUNK, side="right")), first + 1)
        chunk = slice(first, stop)
        owner = np.repeat(np.arange(stop - first), sizes[chunk])
        heads = np.cumsum(sizes[chunk]) - sizes[chunk]
        position = low[targets[chunk]][owner] + np.arange(len(owner)) - heads[owner]
        end = ends[position]
        source = sources[chunk][owner]
        wrong = text[end] != symbols[chunk][owner]
        inner = source != 0
        before = rank[np.maximum(end - 1, 0)]
        wrong |= inner & ((end == 0) | (before < low[source]) | (before >= high[source]))
        if wrong.any():
            bad = int(np.argmax(wrong))
            raise ModelStoreError(
                f"the transition of state {int(source[bad])} on symbol "
                f"{int(symbols[chunk][owner][bad])} reaches an occurrence ending at text "
                f"position {int(end[bad])} that does not spell it",
                where=where,
            )
        first = stop
