"""Writers for small test corpora, independent of ``lipstream.corpus.writer``.

Frames follow known generating functions so loaded values can be checked
exactly; TextGrids and .lab files are written as text so line numbers are
known to the tests. Tests get them through the ``build`` fixture (test
modules here are not importable by name, so helpers travel as a fixture).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

CHANNELS = ("jawOpen", "mouthClose", "mouthPucker")
INTERCEPTS = np.array([0.1, 0.5, -0.25])
SLOPES = np.array([0.3, -0.2, 0.75])

Interval = tuple[float, float, str]
PHONES: list[Interval] = [(0.0, 0.2, ""), (0.2, 0.45, "HH"), (0.5, 0.8, "AY1"), (0.8, 1.0, "")]


def linear_frames(times: np.ndarray) -> np.ndarray:
    """The generating function: channel c is INTERCEPTS[c] + SLOPES[c] * t, shape (n, 3)."""
    return np.asarray(INTERCEPTS[None, :] + SLOPES[None, :] * np.asarray(times)[:, None])


def write_frames(
    path: Path,
    times: np.ndarray,
    values: np.ndarray,
    channels: Sequence[str] = CHANNELS,
    time_column: str = "time",
) -> None:
    """A frames CSV at full float precision (repr)."""
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow([time_column, *channels])
        for time, row in zip(times, values):
            writer.writerow([repr(float(time)), *(repr(float(v)) for v in row)])


def textgrid_long(tiers: dict[str, Sequence[Interval]]) -> str:
    """A long-format TextGrid as Praat and MFA write it (several tiers allowed)."""
    xmax = max(tier[-1][1] for tier in tiers.values())
    lines = [
        'File type = "ooTextFile"',
        'Object class = "TextGrid"',
        "",
        "xmin = 0 ",
        f"xmax = {xmax} ",
        "tiers? <exists> ",
        f"size = {len(tiers)} ",
        "item []: ",
    ]
    for number, (name, intervals) in enumerate(tiers.items(), start=1):
        lines += [
            f"    item [{number}]:",
            '        class = "IntervalTier" ',
            f'        name = "{name}" ',
            "        xmin = 0 ",
            f"        xmax = {xmax} ",
            f"        intervals: size = {len(intervals)} ",
        ]
        for index, (start, end, label) in enumerate(intervals, start=1):
            lines += [
                f"        intervals [{index}]:",
                f"            xmin = {start} ",
                f"            xmax = {end} ",
                f'            text = "{label}" ',
            ]
    return "\n".join(lines) + "\n"


def textgrid_short(tiers: dict[str, Sequence[Interval]]) -> str:
    """The same in Praat's short text format."""
    xmax = max(tier[-1][1] for tier in tiers.values())
    lines = ['File type = "ooTextFile"', 'Object class = "TextGrid"', "", "0", str(xmax)]
    lines += ["<exists>", str(len(tiers))]
    for name, intervals in tiers.items():
        lines += ['"IntervalTier"', f'"{name}"', "0", str(xmax), str(len(intervals))]
        for start, end, label in intervals:
            lines += [str(start), str(end), f'"{label}"']
    return "\n".join(lines) + "\n"


def write_utterance(
    root: Path,
    stem: str,
    *,
    duration: float = 1.0,
    rate: float = 60.0,
    phones: Sequence[Interval] = PHONES,
    phones_format: str = "textgrid",
    generator: Callable[[np.ndarray], np.ndarray] = linear_frames,
    metadata: dict[str, object] | None = None,
) -> np.ndarray:
    """Frames on ``k / rate`` for ``k = 0 .. duration * rate`` plus phones; returns the times."""
    times = np.arange(round(duration * rate) + 1) / rate
    write_frames(root / f"{stem}.csv", times, generator(times))
    if phones_format == "textgrid":
        (root / f"{stem}.TextGrid").write_text(textgrid_long({"phones": phones}))
    else:
        lab = "".join(f"{start} {end} {label or 'sil'}\n" for start, end, label in phones)
        (root / f"{stem}.lab").write_text(lab)
    if metadata is not None:
        (root / f"{stem}.json").write_text(json.dumps(metadata))
    return times


def write_wav(path: Path, samples: np.ndarray, rate: int) -> None:
    wavfile.write(path, rate, np.round(samples * 32767).astype(np.int16))


def line_of(path: Path, text: str, occurrence: int = 1) -> int:
    """1-based line of the ``occurrence``-th line containing ``text``."""
    hits = [n for n, line in enumerate(path.read_text().splitlines(), start=1) if text in line]
    return hits[occurrence - 1]


def replace_line(path: Path, number: int, text: str) -> None:
    lines = path.read_text().splitlines()
    lines[number - 1] = text
    path.write_text("\n".join(lines) + "\n")


class Builders:
    """The helpers above, handed to tests by the ``build`` fixture."""

    CHANNELS = CHANNELS
    PHONES = PHONES
    linear_frames = staticmethod(linear_frames)
    write_frames = staticmethod(write_frames)
    textgrid_long = staticmethod(textgrid_long)
    textgrid_short = staticmethod(textgrid_short)
    write_utterance = staticmethod(write_utterance)
    write_wav = staticmethod(write_wav)
    line_of = staticmethod(line_of)
    replace_line = staticmethod(replace_line)


@pytest.fixture
def build() -> type[Builders]:
    return Builders
