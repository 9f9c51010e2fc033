"""Phoneme onsets from TTS timings against espeak-ng's own, per format; and the speed of
words to spans.

Sketch: demo sentences are spoken by espeak-ng at several rates; its word and phoneme
events are the truth (``speech.spoken_words``). A duration model is trained on the
spans of the first sentences; the last ones, held out, are written in each provider's
shape (``tts_shapes``), read back as a file would be, turned into spans
(``frontends.words_to_spans``) and each derived phoneme onset is compared with the true
one (``tts_shapes.onset_errors``): median and 90th percentile in ms, of every phoneme and of
those after each word's first (which word timings give outright), with even spreading
within each given word as the baseline. Character timings are made from the true phonemes
by an alignment that knows no spelling (``tts_shapes.character_times``), on the
millisecond and, to see what a coarser aligner costs, on a grid of 11.6 ms. The real-time
factor is the time from the timing text to spans over the seconds of speech. The frames
a model (``--model``, default a ``viseme-lerp`` trained on a small demo corpus) gives for
the derived spans are compared with its frames for espeak-ng's own spans: RMS over every
frame and channel, and the lag of each /p b m/ closure (``evaluation.closure_lags``).
Writes ``bench/word_timings.json`` (``--json``) with machine, date and command;
``python -m lipstream.bench.report`` renders it.

    python -m lipstream.bench.word_timings --json bench/word_timings.json
    lipstream bench --word-timings --results bench/word_timings.json
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..demo.sentences import load_sentences
from ..engines import load_model
from ..engines.base import Model
from ..evaluation import closure_lags, lip_aperture
from ..frontends.formats import parse_timings
from ..frontends.word_durations import WordDurationModel
from ..frontends.words_to_spans import timings_to_spans
from ..results_file import recorded, write_results
from ..speech.spoken_words import SpokenUtterance, speak_words
from ..timeline import PhonemeSpan
from . import tts_shapes

TOOL = "python -m lipstream.bench.word_timings"
RATES_WPM = (140, 175, 220)
TRAINING_SENTENCES = 240
HELDOUT_SENTENCES = 60
TARGETS_MS = {"word timings median": 20.0, "character timings median": 10.0}
FRAMES_FPS = 60.0
FRAMES_RATE_WPM = 175
SMALL_CORPUS_SENTENCES = 40
FRAME_GRID_S = 256 / 22050
"""One hop of 256 samples at 22.05 kHz: character times an aligner of audio frames gives."""
FRAME_FORMATS = ("words", "elevenlabs", "polly", "azure visemes only")
FORMATS: dict[str, Callable[[SpokenUtterance], Any]] = {
    "words": tts_shapes.words_input,
    "elevenlabs": tts_shapes.elevenlabs_input,
    "elevenlabs, times on an 11.6 ms grid": lambda utterance: tts_shapes.elevenlabs_input(
        utterance, FRAME_GRID_S
    ),
    "azure": tts_shapes.azure_input,
    "polly": tts_shapes.polly_input,
    "ipa": tts_shapes.ipa_input,
    "azure visemes only": tts_shapes.azure_visemes,
    "polly visemes only": lambda utterance: tts_shapes.polly_input(utterance, words=False),
}


def _even(utterance: SpokenUtterance) -> list[PhonemeSpan]:
    spans = []
    for word in utterance.words:
        step = (word.end - word.start) / len(word.phonemes)
        for k, phoneme in enumerate(word.phonemes):
            start = word.start + k * step
            spans.append(PhonemeSpan(phoneme.phoneme, start, start + step))
    return spans


def _stats(
    heldout: Sequence[SpokenUtterance], derived: Sequence[Sequence[PhonemeSpan]]
) -> dict[str, float]:
    """Onset errors of every matched phoneme, and of those after each word's first."""
    row: dict[str, float] = {}
    for prefix, inner in (("", False), ("inner_", True)):
        errors = [
            error
            for utterance, spans in zip(heldout, derived)
            for error in tts_shapes.onset_errors(utterance.words, spans, inner=inner)
        ]
        errors_ms = np.array(errors) * 1000
        row[f"{prefix}pairs"] = len(errors_ms)
        row[f"{prefix}median_ms"] = round(float(np.median(errors_ms)), 2)
        row[f"{prefix}p90_ms"] = round(float(np.percentile(errors_ms, 90)), 2)
    return row


def bench(model: WordDurationModel, heldout: list[SpokenUtterance]) -> dict[str, Any]:
    """Onset errors and speed per format (and the even-spreading baseline), spread by
    ``model``."""
    speech_s = sum(utterance.audio.duration for utterance in heldout)
    results: dict[str, Any] = {}
    for name, build in FORMATS.items():
        texts = []
        for utterance in heldout:
            sent = build(utterance)
            texts.append(sent if isinstance(sent, str) else json.dumps(sent))
        started = time.perf_counter()
        derived = [timings_to_spans(parse_timings(text), model) for text in texts]
        elapsed = time.perf_counter() - started
        results[name] = _stats(heldout, derived) | {
            "real_time_factor": round(elapsed / speech_s, 5)
        }
    even = [_even(utterance) for utterance in heldout]
    results["words, spread evenly (baseline)"] = _stats(heldout, even)
    return results


def frames_against_truth(
    model: Model, heldout: list[SpokenUtterance], durations: WordDurationModel
) -> dict[str, dict[str, float]]:
    """Per format: RMS of the frames of the derived spans against those of the true spans,
    and the /p b m/ closure lags (ms) of the first against the second."""
    results: dict[str, dict[str, float]] = {}
    for name in FRAME_FORMATS:
        squares: list[np.ndarray] = []
        lags: list[float] = []
        for utterance in heldout:
            sent = FORMATS[name](utterance)
            text = sent if isinstance(sent, str) else json.dumps(sent)
            derived = timings_to_spans(parse_timings(text), durations)
            guess = model.synthesize(derived, fps=FRAMES_FPS).frames
            truth = model.synthesize(utterance.spans, fps=FRAMES_FPS).frames
            n = min(len(guess), len(truth))
            squares.append(((guess[:n] - truth[:n]).astype(np.float64) ** 2).ravel())
            true_aperture = lip_aperture(truth[:n], model.channels)
            guess_aperture = lip_aperture(guess[:n], model.channels)
            if true_aperture is not None and guess_aperture is not None:
                lags += closure_lags(true_aperture, guess_aperture, utterance.spans, FRAMES_FPS)
        lags_ms = np.array(lags) * 1000
        results[name] = {
            "rms": round(float(np.sqrt(np.mean(np.concatenate(squares)))), 5),
            "closures": len(lags_ms),
            "closure_lag_median_abs_ms": round(float(np.median(np.abs(lags_ms))), 2),
            "closure_lag_p90_abs_ms": round(float(np.percentile(np.abs(lags_ms), 90)), 2),
        }
    return results


def _model(path: Path | None) -> tuple[Model, str]:
    """The model of ``--model``, or a viseme-lerp trained on a small demo corpus."""
    if path is not None:
        return load_model(path), str(path)
    from ..demo.generate import generate_demo_corpus
    from ..training import train_engine

    corpus = generate_demo_corpus(n_sentences=SMALL_CORPUS_SENTENCES)
    model = train_engine(corpus, "viseme-lerp")
    return model, f"viseme-lerp trained on {SMALL_CORPUS_SENTENCES} demo sentences"


def run(command: Sequence[str], model_path: Path | None = None) -> dict[str, Any]:
    """The results, recording ``command`` (the command line that asked for them)."""
    sentences = load_sentences()
    train_text = sentences[:TRAINING_SENTENCES]
    heldout_text = sentences[-HELDOUT_SENTENCES:]
    training = [u for rate in RATES_WPM for u in speak_words(train_text, rate=rate)]
    heldout = [u for rate in RATES_WPM for u in speak_words(heldout_text, rate=rate)]
    durations = WordDurationModel().fit(utterance.spans for utterance in training)
    model, described = _model(model_path)
    at_rate = speak_words(heldout_text, rate=FRAMES_RATE_WPM)
    return {
        **recorded(shlex.join(command)),
        "rates_wpm": list(RATES_WPM),
        "training_sentences": len(train_text),
        "heldout_sentences": len(heldout_text),
        "heldout_speech_s": round(sum(u.audio.duration for u in heldout), 2),
        "targets_ms": TARGETS_MS,
        "formats": bench(durations, heldout),
        "frames": {"model": described, "fps": FRAMES_FPS, "rate_wpm": FRAMES_RATE_WPM}
        | {"formats": frames_against_truth(model, at_rate, durations)},
    }


def print_summary(results: dict[str, Any]) -> None:
    for name, frames in results["frames"]["formats"].items():
        print(
            f"frames from {name:22s} RMS {frames['rms']:.4f} against the true phonemes'; "
            f"/p b m/ closure lag |median| {frames['closure_lag_median_abs_ms']:.1f} ms"
        )
    for name, row in results["formats"].items():
        rtf = row.get("real_time_factor")
        print(
            f"{name:32s} onset error median {row['median_ms']:5.1f} ms, p90 {row['p90_ms']:5.1f} "
            f"ms; after a word's first: {row['inner_median_ms']:5.1f}, {row['inner_p90_ms']:5.1f}"
            + (f", real-time factor {rtf:.5f}" if rtf is not None else "")
        )


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, help="write the results here")
    parser.add_argument(
        "--model", type=Path, help="model for the frame comparison (default: a quick viseme-lerp)"
    )
    args = parser.parse_args(argv)
    results = run([*TOOL.split(), *(sys.argv[1:] if argv is None else argv)], args.model)
    if args.json is not None:
        write_results(results, args.json)
    print_summary(results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
