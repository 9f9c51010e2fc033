"""The demo character's motion against real faces, on the four measures it is calibrated to.

Sketch: every corpus is first resampled onto the real set's frame grid (25 fps, each channel
by ``np.interp``), so speeds and timings are read at one resolution. Then, from the lip
aperture (``jawOpen - mouthClose``) and the rounding (``mouthFunnel + mouthPucker``):

1. **closure timing**: per /p b m/ span, the centre of the aperture's closure plateau
   (``evaluation.closure_centre``, within the span widened by ``evaluation.LAG_WINDOW_S``
   each side, as ``bench --real`` times closures) less the span's acoustic start, in ms,
   and as a share of the span's duration;
2. **aperture dynamics**: per utterance, the fastest opening and closing over the speech
   frames (one-frame differences times the frame rate) divided by the aperture's range
   there (its 98th less its 2nd percentile), so a face's own scale drops out; the median
   over utterances, in ranges per second;
3. **anticipatory rounding**: per rounded vowel (``ROUNDED_VOWELS``) after a consonant, the
   time the rounding first rises halfway from its lowest in the ``ROUND_LOOKBACK_S`` before
   the vowel to its highest inside the vowel, less the vowel's acoustic start (negative:
   the lips round before the vowel sounds), in ms. Vowels whose rounding rises by less than
   ``MIN_ROUND_RISE`` are not timed;
4. **lip aperture by phoneme**: per phone span, the mean aperture over the span's frames as
   a share of the utterance's range over its speech frames (0 at its 2nd percentile, 1 at
   its 98th), so a face's own scale drops out; mean and sd per phoneme.

``python -m lipstream.bench.demo_calibration --corpus before=DIR --corpus after=DIR``
measures the shipped GRID set and each named corpus in one run and writes
``bench/demo_calibration.json``. The real set is also measured talker by talker: each
talker with at least ``TALKER_MIN_CLIPS`` clips on its own (``real: NAME``), the others
pooled (``real: other talkers``), so one talker who holds most of the set does not pass
for all of them.
"""

from __future__ import annotations

import argparse
import platform
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from .._version import __version__
from ..corpus import Corpus, Utterance, load_corpus
from ..errors import InvalidRequestError
from ..evaluation import BILABIALS, LAG_WINDOW_S, closure_centre, lip_aperture
from ..phonemes import SILENCE
from ..results_file import write_results
from ..timeline import PhonemeSpan
from .real_faces import speech_mask
from .real_set import real_set_parser

COMMAND = "python -m lipstream.bench.demo_calibration"
MEASURE_FPS = 25.0
"""The real set's frame rate: every corpus is measured on this grid."""
ROUNDED_VOWELS = frozenset({"UW", "UH", "OW", "AO"})
ROUND_LOOKBACK_S = 0.3
MIN_ROUND_RISE = 0.05
RANGE_PERCENTILES = (2.0, 98.0)
TALKER_MIN_CLIPS = 5
OTHER_TALKERS = "other talkers"


@dataclass(frozen=True)
class Track:
    """One utterance on the measuring grid: aperture and rounding (n_frames,), phones."""

    aperture: np.ndarray
    rounding: np.ndarray
    phones: Sequence[PhonemeSpan]


@dataclass(frozen=True)
class Summary:
    """Mean, standard deviation and count of one measure's values."""

    mean: float | None
    sd: float | None
    count: int


def summarize(values: Sequence[float]) -> Summary:
    array = np.asarray(values, dtype=np.float64)
    return Summary(
        mean=float(array.mean()) if len(array) else None,
        sd=float(array.std(ddof=1)) if len(array) > 1 else None,
        count=len(array),
    )


@dataclass(frozen=True)
class MotionMeasures:
    """The four measures of one corpus (see the module sketch)."""

    closure_from_onset_ms: Summary
    closure_share: Summary
    opening_speed: Summary
    closing_speed: Summary
    opening_speed_median: float | None
    closing_speed_median: float | None
    rounding_half_rise_ms: Summary
    phone_apertures: dict[str, Summary]


def _channel(utterance: Utterance, channels: Sequence[str], name: str) -> np.ndarray:
    if name not in channels:
        raise InvalidRequestError(f"the corpus has no {name} channel", where=utterance.stem)
    return np.asarray(utterance.frames[:, list(channels).index(name)], dtype=np.float64)


def resample(values: np.ndarray, fps: float, new_fps: float) -> np.ndarray:
    """``values`` (n,) at ``fps`` read at ``new_fps`` over the same duration, by np.interp."""
    times = np.arange(len(values)) / fps
    grid = np.arange(int(np.floor(times[-1] * new_fps + 1e-9)) + 1) / new_fps
    return np.asarray(np.interp(grid, times, values))


def tracks(corpus: Corpus, fps: float = MEASURE_FPS) -> list[Track]:
    """Every utterance of ``corpus`` on a grid of ``fps``."""
    out = []
    for utterance in corpus.utterances:
        aperture = lip_aperture(utterance.frames, corpus.channels)
        if aperture is None:
            raise InvalidRequestError(
                "the corpus has no jawOpen and mouthClose channels", where=corpus.name
            )
        rounding = _channel(utterance, corpus.channels, "mouthFunnel") + _channel(
            utterance, corpus.channels, "mouthPucker"
        )
        out.append(
            Track(
                resample(aperture, corpus.fps, fps),
                resample(rounding, corpus.fps, fps),
                utterance.phones,
            )
        )
    return out


def closure_timings(track: Track, fps: float) -> list[tuple[float, float]]:
    """Per /p b m/ span: (closure centre less the span's start in s, as a share of the span)."""
    out = []
    for span in track.phones:
        if span.phoneme not in BILABIALS or span.end <= span.start:
            continue
        first = max(0, int(np.ceil((span.start - LAG_WINDOW_S) * fps)))
        stop = min(int(np.ceil((span.end + LAG_WINDOW_S) * fps)), len(track.aperture))
        if stop - first < 2:
            continue
        offset = (first + closure_centre(track.aperture[first:stop])) / fps - span.start
        out.append((offset, offset / (span.end - span.start)))
    return out


def peak_speeds(track: Track, fps: float) -> tuple[float, float] | None:
    """(fastest opening, fastest closing) over the speech frames, in aperture ranges per
    second; None when the aperture does not move."""
    speech = speech_mask(track.phones, fps, len(track.aperture))
    low, high = np.percentile(track.aperture[speech], RANGE_PERCENTILES)
    moving = speech[1:] & speech[:-1]
    if high <= low or not moving.any():
        return None
    speeds = np.diff(track.aperture)[moving] * fps / (high - low)
    return float(speeds.max()), float(-speeds.min())


def _half_rise(rounding: np.ndarray, start: int, peak: int, level: float) -> float:
    """The fractional frame where ``rounding`` last rises through ``level`` before ``peak``."""
    index = peak
    while index > start and rounding[index - 1] >= level:
        index -= 1
    if index == start:
        return float(start)
    below, above = rounding[index - 1], rounding[index]
    return float(index - 1 + (level - below) / (above - below))


def rounding_half_rises(track: Track, fps: float) -> list[float]:
    """Per rounded vowel after a consonant, the halfway rise of rounding less the vowel's
    acoustic start (s)."""
    out = []
    n_frames = len(track.rounding)
    for previous, span in zip(track.phones, track.phones[1:], strict=False):
        if span.phoneme not in ROUNDED_VOWELS or previous.phoneme == SILENCE:
            continue
        start = max(0, int(np.ceil((span.start - ROUND_LOOKBACK_S) * fps)))
        onset = min(int(np.ceil(span.start * fps)), n_frames - 1)
        stop = min(int(np.ceil(span.end * fps)), n_frames)
        if stop <= onset or onset <= start:
            continue
        lowest = start + int(np.argmin(track.rounding[start : onset + 1]))
        peak = onset + int(np.argmax(track.rounding[onset:stop]))
        rise = track.rounding[peak] - track.rounding[lowest]
        if rise < MIN_ROUND_RISE:
            continue
        level = track.rounding[lowest] + 0.5 * rise
        out.append(_half_rise(track.rounding, lowest, peak, level) / fps - span.start)
    return out


def phone_apertures(track: Track, fps: float) -> list[tuple[str, float]]:
    """Per non-silence phone span holding a frame: (phoneme, mean aperture over its frames
    as a share of the utterance's speech range)."""
    speech = speech_mask(track.phones, fps, len(track.aperture))
    if not speech.any():
        return []
    low, high = np.percentile(track.aperture[speech], RANGE_PERCENTILES)
    if high <= low:
        return []
    times = np.arange(len(track.aperture)) / fps
    out = []
    for span in track.phones:
        inside = (times >= span.start) & (times < span.end)
        if span.phoneme != SILENCE and inside.any():
            share = (float(track.aperture[inside].mean()) - low) / (high - low)
            out.append((span.phoneme, share))
    return out


def _median(values: Sequence[float]) -> float | None:
    return float(np.median(values)) if len(values) else None


def measure_motion(corpus: Corpus, fps: float = MEASURE_FPS) -> MotionMeasures:
    """The four measures of ``corpus``, read on a grid of ``fps``."""
    closures: list[tuple[float, float]] = []
    speeds: list[tuple[float, float]] = []
    rises: list[float] = []
    by_phoneme: dict[str, list[float]] = {}
    for track in tracks(corpus, fps):
        for phoneme, share in phone_apertures(track, fps):
            by_phoneme.setdefault(phoneme, []).append(share)
        closures.extend(closure_timings(track, fps))
        peak = peak_speeds(track, fps)
        if peak is not None:
            speeds.append(peak)
        rises.extend(rounding_half_rises(track, fps))
    opening = [pair[0] for pair in speeds]
    closing = [pair[1] for pair in speeds]
    return MotionMeasures(
        closure_from_onset_ms=summarize([1000.0 * pair[0] for pair in closures]),
        closure_share=summarize([pair[1] for pair in closures]),
        opening_speed=summarize(opening),
        closing_speed=summarize(closing),
        opening_speed_median=_median(opening),
        closing_speed_median=_median(closing),
        rounding_half_rise_ms=summarize([1000.0 * value for value in rises]),
        phone_apertures={p: summarize(values) for p, values in sorted(by_phoneme.items())},
    )


def corpus_entry(corpus: Corpus, path: Path) -> dict[str, Any]:
    return {
        "path": str(path),
        "name": corpus.name,
        "digest": corpus.digest(),
        "fps": corpus.fps,
        "utterances": len(corpus.utterances),
        "measures": asdict(measure_motion(corpus)),
    }


def talker_groups(corpus: Corpus, min_clips: int = TALKER_MIN_CLIPS) -> list[tuple[str, Corpus]]:
    """``corpus`` split by talker: each with at least ``min_clips`` utterances alone, in
    order of first appearance, then the rest pooled as ``OTHER_TALKERS``; empty when that
    leaves one group."""
    by_talker: dict[str, list[Utterance]] = {}
    for utterance in corpus.utterances:
        by_talker.setdefault(str(utterance.speaker or utterance.stem), []).append(utterance)
    groups = [(name, kept) for name, kept in by_talker.items() if len(kept) >= min_clips]
    others = [u for kept in by_talker.values() if len(kept) < min_clips for u in kept]
    if others:
        groups.append((OTHER_TALKERS, others))
    if len(groups) < 2:
        return []
    return [
        (name, Corpus(corpus.name, corpus.fps, corpus.channels, utterances))
        for name, utterances in groups
    ]


def run(real: Path, named: Sequence[tuple[str, Path]], command: str) -> dict[str, Any]:
    """The real set (whole, then talker by talker) and each (name, corpus directory)
    measured in one run."""
    real_set = load_corpus(real)
    corpora = {"real": corpus_entry(real_set, real)}
    for talker, group in talker_groups(real_set):
        corpora[f"real: {talker}"] = corpus_entry(group, real)
    for name, path in named:
        corpora[name] = corpus_entry(load_corpus(path), path)
    return {
        "lipstream_version": __version__,
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "command": command,
        "machine": {
            "python": platform.python_version(),
            "processor": platform.machine(),
            "system": platform.system(),
        },
        "measure_fps": MEASURE_FPS,
        "corpora": corpora,
    }


def _named(text: str) -> tuple[str, Path]:
    name, _, path = text.partition("=")
    if not name or not path:
        raise argparse.ArgumentTypeError(f"expected NAME=DIR, got {text!r}")
    return name, Path(path)


def main(argv: Sequence[str] | None = None) -> None:
    parser = real_set_parser(COMMAND, __doc__)
    parser.add_argument(
        "--corpus", type=_named, action="append", default=[], help="NAME=DIR, repeatable"
    )
    parser.add_argument("--json", type=Path, required=True, help="results file to write")
    args = parser.parse_args(argv)
    named = [(name, path) for name, path in args.corpus]
    command = " ".join(
        [COMMAND, *(f"--corpus {n}={p}" for n, p in named), "--json", str(args.json)]
    )
    results = run(args.real, named, command)
    write_results(results, args.json)
    for name, entry in results["corpora"].items():
        print(f"{name:<8} {_line(entry['measures'])}")


def _line(measures: dict[str, Any]) -> str:
    closure, rounding = measures["closure_from_onset_ms"], measures["rounding_half_rise_ms"]
    return (
        f"closure {_fmt(closure['mean'], '+.1f')} ms (n {closure['count']}); opening "
        f"{_fmt(measures['opening_speed_median'], '.2f')}/s, closing "
        f"{_fmt(measures['closing_speed_median'], '.2f')}/s; rounding half-rise "
        f"{_fmt(rounding['mean'], '+.1f')} ms (n {rounding['count']})"
    )


def _fmt(value: float | None, pattern: str) -> str:
    return "n/a" if value is None else format(value, pattern)


if __name__ == "__main__":
    main()
