"""Synthetic DAM problems: occurrences laid out by hand and curves made by a known DAM,
summed by plain loops (independent of the engine's vectorised code)."""

from __future__ import annotations

import math

import numpy as np

from lipstream.engines.dam.modes import Occurrences


def layout(
    durations: list[list[float]], fps: float, phoneme: int = 0
) -> tuple[Occurrences, np.ndarray]:
    """Occurrences of utterances with these span durations (s), every span the same
    phoneme; returns them and the number of frames of each utterance."""
    columns: dict[str, list[float]] = {k: [] for k in ("first_row", "rows", "start", "duration")}
    counts, first = [], 0
    for spans in durations:
        rows = math.floor(sum(spans) * fps + 1e-9) + 1
        start = 0.0
        for duration in spans:
            columns["first_row"].append(first)
            columns["rows"].append(rows)
            columns["start"].append(start)
            columns["duration"].append(duration)
            start += duration
        counts.append(rows)
        first += rows
    n = len(columns["start"])
    zeros = np.full(n, phoneme, dtype=np.int64)
    occurrences = Occurrences(
        first_row=np.asarray(columns["first_row"], dtype=np.int64),
        rows=np.asarray(columns["rows"], dtype=np.int64),
        start=np.asarray(columns["start"]),
        duration=np.asarray(columns["duration"]),
        phoneme=zeros,
        previous=zeros,
        following=zeros,
        emotion=np.zeros(n, dtype=np.int64),
        fps=fps,
    )
    return occurrences, np.asarray(counts)


def known_dam(
    occurrences: Occurrences,
    mode: np.ndarray,
    sigma: np.ndarray,
    coefficients: np.ndarray,
    eps: float,
) -> np.ndarray:
    """Eq. 2 by loops over every frame and every occurrence of its utterance (no cut-off):
    D = exp(-g^2 / (2 sigma^2 + eps)), A at local time clamped to [0, 1]."""
    n_rows = int((occurrences.first_row + occurrences.rows).max())
    frames = np.zeros((n_rows, coefficients.shape[2]))
    for j in range(len(occurrences.start)):
        first, rows = int(occurrences.first_row[j]), int(occurrences.rows[j])
        for i in range(rows):
            u = (i / occurrences.fps - occurrences.start[j]) / occurrences.duration[j]
            gap = u if u < 0 else (u - 1.0 if u > 1 else 0.0)
            weight = math.exp(-gap * gap / (2 * sigma[mode[j]] ** 2 + eps))
            clamped = min(max(u, 0.0), 1.0)
            for m in range(coefficients.shape[1]):
                frames[first + i] += weight * clamped**m * coefficients[mode[j], m]
    return frames
