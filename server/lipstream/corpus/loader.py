"""Loading a corpus directory into a ``Corpus``.

Sketch: read ``corpus.json`` if present, find every stem's files, then per
utterance in sorted stem order: read the frames (plain CSV, or a Live Link
Face export recognized by its ``Timecode`` column), check the channel set
against the first utterance, read the phone intervals and check they stay
within the frames, resample the frames onto the corpus grid ``i / fps`` (the
only normalization; see ``grid``), and attach audio and metadata. A problem
does not stop the load: it goes on to the utterance's other files and the
next utterances, and at the end raises every problem found (up to
``validation.MAX_PROBLEMS``), each naming the file (and line or column) at
fault: one as its own ``CorpusError``, several as ``CorpusProblems``.
"""

from __future__ import annotations

import csv
import sys
from dataclasses import dataclass, replace
from pathlib import Path

from tqdm import tqdm

from ..audio import read_wav
from ..errors import CorpusError
from ..timeline import PhonemeSpan
from .config import CONFIG_FILE, CorpusConfig, read_corpus_config
from .frames_csv import read_frames_csv
from .grid import estimate_fps, resample_to_grid
from .intervals import LabelledInterval, to_phoneme_spans
from .lab import lab_spans, read_lab_intervals
from .layout import UtteranceFiles, discover_utterances
from .livelink import is_livelink_header, read_livelink_csv
from .metadata import UtteranceMetadata, read_utterance_metadata
from .model import Corpus, Utterance
from .table import FrameTable
from .textgrid import read_textgrid_tier
from .validation import (
    Problems,
    check_channel_selection,
    check_phones_within_frames,
    check_same_channels,
)


@dataclass
class _Grid:
    """What the first utterance fixes for the rest: frame rate and channel order."""

    fps: float
    channels: tuple[str, ...]
    reference_file: str
    reference_channels: tuple[str, ...]


def load_corpus(path: str | Path, *, progress: bool = False, tier: str | None = None) -> Corpus:
    """Load and validate the corpus in directory ``path``; ``progress`` shows a bar on stderr;
    ``tier`` names the TextGrids' phone tier (overriding ``corpus.json``'s ``tier``)."""
    root = Path(path)
    if not root.is_dir():
        raise CorpusError("corpus path is not a directory", where=str(root))
    config = _config(root)
    if tier is not None:
        config = replace(config, tier=tier)
    files = discover_utterances(root)
    if not files:
        raise CorpusError(
            "empty corpus: no utterances (<stem>.csv with <stem>.TextGrid or <stem>.lab)",
            where=str(root),
        )
    problems = Problems()
    problems.attempt(_check_heldout, config, files)
    name = config.name or root.resolve().name
    grid: _Grid | None = None
    utterances: list[Utterance] = []
    bar = tqdm(files, desc=f"loading {name}", unit="utt", disable=not progress, file=sys.stderr)
    for utterance_files in bar:
        if problems.full:
            problems.more = True
            break
        table = problems.attempt(read_frames, utterance_files.frames)
        if table is not None:
            settled = problems.attempt(_settle_grid, grid, config, utterance_files.frames, table)
            grid, table = (grid, None) if settled is None else (settled, table)
        utterance = _utterance(utterance_files, table, grid, config.tier, problems)
        if utterance is not None:
            utterances.append(utterance)
    problems.raise_any(where=str(root))
    assert grid is not None
    return Corpus(name, grid.fps, grid.channels, utterances, heldout=config.heldout)


def read_frames(path: Path) -> FrameTable:
    """A frames ``.csv`` of either kind, chosen by its header."""
    if is_livelink_header(_header(path)):
        return read_livelink_csv(path)
    return read_frames_csv(path)


def _header(path: Path) -> tuple[str, ...]:
    try:
        with open(path, encoding="utf-8-sig", newline="") as handle:
            first = next(csv.reader(handle), [])
    except (OSError, UnicodeDecodeError, csv.Error):
        return ()  # the full reader reports it with its location
    return tuple(cell.strip() for cell in first)


def _config(root: Path) -> CorpusConfig:
    config_path = root / CONFIG_FILE
    return read_corpus_config(config_path) if config_path.is_file() else CorpusConfig()


def _check_heldout(config: CorpusConfig, files: list[UtteranceFiles]) -> None:
    stems = {utterance_files.stem for utterance_files in files}
    unknown = [stem for stem in config.heldout if stem not in stems]
    if unknown:
        raise CorpusError(
            f"key 'heldout' names stems with no utterance: {', '.join(unknown)}",
            where=CONFIG_FILE,
        )


def _settle_grid(
    grid: _Grid | None, config: CorpusConfig, frames: Path, table: FrameTable
) -> _Grid:
    if grid is not None:
        check_same_channels(
            grid.reference_file, grid.reference_channels, frames.name, table.channels
        )
        return grid
    fps = config.fps if config.fps is not None else estimate_fps(table.times, frames.name)
    channels = table.channels
    if config.channels is not None:
        check_channel_selection(config.channels, table.channels, f"{CONFIG_FILE} (key 'channels')")
        channels = config.channels
    return _Grid(fps, channels, frames.name, table.channels)


def _utterance(
    files: UtteranceFiles,
    table: FrameTable | None,
    grid: _Grid | None,
    tier: str | None,
    problems: Problems,
) -> Utterance | None:
    """The utterance, or None when any of its files has a problem (added to ``problems``);
    its phones, metadata and audio are read even when its frames could not be, so their
    problems are found in the same run."""
    framed = table is not None and grid is not None
    frames_end = float(table.times[-1]) if table is not None else None
    phones = problems.attempt(_phones, files, tier, frames_end, grid.fps if grid else None)
    metadata = (
        problems.attempt(read_utterance_metadata, files.metadata)
        if files.metadata
        else UtteranceMetadata()
    )
    audio = problems.attempt(read_wav, files.audio) if files.audio else None
    if not framed or phones is None or metadata is None or (files.audio and audio is None):
        return None
    assert table is not None and grid is not None
    columns = [table.channels.index(name) for name in grid.channels]
    return Utterance(
        stem=files.stem,
        frames=resample_to_grid(table.times, table.frames[:, columns], grid.fps),
        phones=phones,
        fps=grid.fps,
        audio=audio,
        emotion=metadata.emotion,
        speaker=metadata.speaker,
        text=metadata.text,
        alignment_confidence=metadata.alignment_confidence,
    )


def _phones(
    files: UtteranceFiles, tier: str | None, frames_end: float | None, fps: float | None
) -> list[PhonemeSpan]:
    """The utterance's phones, checked to end with its frames when those could be read."""

    def check(intervals: list[LabelledInterval]) -> None:
        if frames_end is not None and fps is not None:
            check_phones_within_frames(intervals, frames_end, fps, files.frames.name)

    if files.phones_are_textgrid:
        phone_tier = read_textgrid_tier(files.phones, tier)
        check(phone_tier.intervals)
        return to_phoneme_spans(phone_tier.intervals, source=phone_tier.source)
    intervals = read_lab_intervals(files.phones, frames_duration=frames_end)
    check(intervals)
    return lab_spans(intervals)
