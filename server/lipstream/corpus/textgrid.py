"""Praat TextGrid phone alignments (MFA, WebMAUS and other aligners' output).

Sketch: praatio parses the file (long or short text format, UTF-8 or UTF-16)
keeping empty intervals, which are silence. The phones come from the interval
tier ``tiers.choose_phone_tier`` picks (``phones``, ``MAU``, ``phone``,
``segments``, MFA's ``<speaker> - phones``, or the one asked for), and their
labels are read in that tier's notation (``tiers.tier_source``): MFA's
ARPAbet or IPA, WebMAUS's SAMPA, or detected. ``textgrid_lines`` locates every interval's
line so that ordering and extent errors can point at it, and catches
intervals praatio would silently reorder or (short format) silently drop.
A file praatio rejects is first checked by that locator, so the error names
the line at fault (structure, order) whenever it can.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from praatio import textgrid as praat_textgrid
from praatio.data_classes.interval_tier import IntervalTier
from praatio.utilities.errors import PraatioException

from ..errors import CorpusError
from ..phonemes import SILENCE
from ..timeline import PhonemeSpan
from .intervals import LabelledInterval, to_phoneme_spans
from .textgrid_lines import TextGridLayoutError, TierLines, locate_interval_tiers
from .tiers import choose_phone_tier, tier_source
from .validation import at_line, check_interval_order

PHONES_TIER = "phones"  # the tier write_textgrid_phones writes


@dataclass(frozen=True)
class PhoneTier:
    """The phone tier of a TextGrid: its name, its labels' notation (a ``phonemes`` source)
    and its intervals in file order, each located by file:line."""

    name: str
    source: str
    intervals: list[LabelledInterval]


def read_textgrid_phones(path: str | Path, tier: str | None = None) -> list[PhonemeSpan]:
    """Contiguous phoneme spans (seconds) from the phone tier (``tier``: the tier's name, else
    the first aligner tier found); gaps become ``sil``."""
    found = read_textgrid_tier(path, tier)
    return to_phoneme_spans(found.intervals, source=found.source)


def read_textgrid_tier(path: str | Path, tier: str | None = None) -> PhoneTier:
    """The phone tier (named ``tier``, else the first aligner tier found) and its notation."""
    path = Path(path)
    text = _read_text(path)
    grid = _open_with_praatio(path, text)
    layout = _layout(path, text)
    name = choose_phone_tier(grid.tierNames, tier, path.name)
    praat_tier = grid.getTier(name)
    if not isinstance(praat_tier, IntervalTier) or name not in layout:
        raise CorpusError(f"tier {name!r} is a point tier, not an interval tier", where=path.name)
    lines = layout[name]
    if lines.declared != len(praat_tier.entries):
        raise CorpusError(
            f"tier {name!r} declares {lines.declared} intervals but praatio read "
            f"{len(praat_tier.entries)}",
            where=path.name,
        )
    check_interval_order(_located(path, lines))
    intervals = [
        LabelledInterval(
            entry.label,
            float(entry.start),
            float(entry.end),
            at_line(path.name, located.start_line),
            at_line(path.name, located.end_line),
        )
        for entry, located in zip(praat_tier.entries, lines.intervals)
    ]
    source = tier_source(
        name, (interval.label for interval in intervals), f"{path.name}: tier {name!r}"
    )
    return PhoneTier(name, source, intervals)


def _read_text(path: Path) -> str:
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise CorpusError(f"cannot read file: {exc.strerror}", where=str(path)) from None
    encoding = "utf-16" if raw[:2] in (b"\xff\xfe", b"\xfe\xff") else "utf-8-sig"
    try:
        return raw.decode(encoding)
    except UnicodeDecodeError:
        raise CorpusError(f"TextGrid is not valid {encoding} text", where=path.name) from None


def _open_with_praatio(path: Path, text: str) -> praat_textgrid.Textgrid:
    try:
        return praat_textgrid.openTextgrid(
            str(path), includeEmptyIntervals=True, reportingMode="error"
        )
    except (PraatioException, ValueError, IndexError, KeyError, UnicodeError) as exc:
        for lines in _layout(path, text).values():
            check_interval_order(_located(path, lines))
        detail = str(exc) or type(exc).__name__
        raise CorpusError(f"malformed TextGrid (praatio: {detail})", where=path.name) from None


def _layout(path: Path, text: str) -> dict[str, TierLines]:
    try:
        return locate_interval_tiers(text)
    except TextGridLayoutError as exc:
        raise CorpusError(
            f"malformed TextGrid: {exc.problem}", where=at_line(path.name, exc.line)
        ) from None


def _located(path: Path, lines: TierLines) -> list[LabelledInterval]:
    return [
        LabelledInterval(
            "",
            interval.start,
            interval.end,
            at_line(path.name, interval.start_line),
            at_line(path.name, interval.end_line),
        )
        for interval in lines.intervals
    ]


def write_textgrid_phones(path: str | Path, spans: Sequence[PhonemeSpan]) -> None:
    """Write ``spans`` as a long-format TextGrid with one ``phones`` tier; silence is ``""``.

    Written directly rather than through praatio, whose writer prints times with
    ``repr`` (``5e-05``), which its own long-format reader then rejects.
    """
    if not spans:
        raise CorpusError("cannot write a TextGrid without phones", where=str(path))
    start, end = _number(spans[0].start), _number(spans[-1].end)
    lines = [
        'File type = "ooTextFile"',
        'Object class = "TextGrid"',
        "",
        f"xmin = {start} ",
        f"xmax = {end} ",
        "tiers? <exists> ",
        "size = 1 ",
        "item []: ",
        "    item [1]:",
        '        class = "IntervalTier" ',
        f'        name = "{PHONES_TIER}" ',
        f"        xmin = {start} ",
        f"        xmax = {end} ",
        f"        intervals: size = {len(spans)} ",
    ]
    for index, span in enumerate(spans, start=1):
        lines += [
            f"        intervals [{index}]:",
            f"            xmin = {_number(span.start)} ",
            f"            xmax = {_number(span.end)} ",
            f'            text = "{_label(span.phoneme)}" ',
        ]
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")


def _number(value: float) -> str:
    return np.format_float_positional(float(value), trim="-")


def _label(phoneme: str) -> str:
    return "" if phoneme == SILENCE else phoneme.replace('"', '""')
