"""Writing a ``Corpus`` as a directory that ``load_corpus`` reads back.

Sketch: per utterance, ``<stem>.csv`` (``time`` = i / fps, then one column
per channel, ``%.6f``), the phones as ``<stem>.TextGrid`` (tier ``phones``) or
``<stem>.lab`` (seconds, or HTK 100-ns units), ``<stem>.wav`` (16-bit PCM)
when there is audio and ``<stem>.json`` with emotion, speaker and text; then
``corpus.json`` with name, fps, channels and held-out stems. It refuses to
write into a directory that already holds corpus files, so no stale
utterance can join the new corpus.
"""

from __future__ import annotations

from pathlib import Path

from ..audio import write_wav
from ..errors import CorpusError
from .config import CONFIG_FILE, CorpusConfig, write_corpus_config
from .frames_csv import TIME_COLUMN, write_frames_csv
from .lab import write_lab_phones
from .layout import (
    AUDIO_SUFFIX,
    FRAMES_SUFFIX,
    LAB_SUFFIX,
    METADATA_SUFFIX,
    TEXTGRID_SUFFIX,
    is_corpus_file,
)
from .livelink import TIMECODE_COLUMN
from .metadata import UtteranceMetadata, write_utterance_metadata
from .model import Corpus, Utterance
from .textgrid import write_textgrid_phones

PHONE_FORMATS = ("textgrid", "lab", "htk")


def write_corpus(corpus: Corpus, path: str | Path, *, phones_format: str = "textgrid") -> None:
    """Write ``corpus`` into directory ``path`` (created if missing).

    ``phones_format``: ``"textgrid"``, ``"lab"`` (seconds) or ``"htk"`` (``.lab``
    in 100-ns units).
    """
    if phones_format not in PHONE_FORMATS:
        raise CorpusError(
            f"phones_format must be one of {', '.join(PHONE_FORMATS)}, got {phones_format!r}",
            where="write_corpus",
        )
    root = Path(path)
    _check_target(root, corpus)
    root.mkdir(parents=True, exist_ok=True)
    for utterance in corpus.utterances:
        _write_utterance(root, corpus.channels, utterance, phones_format)
    config = CorpusConfig(corpus.name, corpus.fps, corpus.channels, corpus.heldout)
    write_corpus_config(root / CONFIG_FILE, config)


def _check_target(root: Path, corpus: Corpus) -> None:
    if root.exists() and not root.is_dir():
        raise CorpusError("corpus path exists and is not a directory", where=str(root))
    if root.is_dir():
        existing = sorted(path.name for path in root.iterdir() if is_corpus_file(path))
        if existing:
            raise CorpusError(
                f"directory already holds corpus files ({', '.join(existing[:3])}...); "
                "write into an empty or new directory",
                where=str(root),
            )
    for reserved in (TIME_COLUMN, TIMECODE_COLUMN):
        if reserved in corpus.channels:
            raise CorpusError(
                f"a channel may not be named {reserved!r}", where=f"corpus {corpus.name!r}"
            )
    for utterance in corpus.utterances:
        if not utterance.phones:
            raise CorpusError("has no phones to write", where=f"utterance {utterance.stem!r}")
    for stem in corpus.stems:
        if (
            not stem
            or Path(stem).name != stem
            or stem.startswith(".")
            or stem + METADATA_SUFFIX == CONFIG_FILE
        ):
            raise CorpusError(
                f"stem {stem!r} cannot name a file in the corpus", where=f"corpus {corpus.name!r}"
            )


def _write_utterance(
    root: Path, channels: tuple[str, ...], utterance: Utterance, phones_format: str
) -> None:
    stem = utterance.stem
    write_frames_csv(root / f"{stem}{FRAMES_SUFFIX}", utterance.frames, channels, utterance.fps)
    if phones_format == "textgrid":
        write_textgrid_phones(root / f"{stem}{TEXTGRID_SUFFIX}", utterance.phones)
    else:
        units = "seconds" if phones_format == "lab" else "htk"
        write_lab_phones(root / f"{stem}{LAB_SUFFIX}", utterance.phones, units=units)
    if utterance.audio is not None:
        write_wav(root / f"{stem}{AUDIO_SUFFIX}", utterance.audio)
    metadata = UtteranceMetadata(
        utterance.emotion, utterance.speaker, utterance.text, utterance.alignment_confidence
    )
    write_utterance_metadata(root / f"{stem}{METADATA_SUFFIX}", metadata)
