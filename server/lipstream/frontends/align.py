"""Forced alignment: recorded speech and its transcript in, phoneme spans out.

Sketch: the transcript is cut into words (lower case, punctuation dropped, hyphens split);
each word's pronunciation comes from pocketsphinx's own CMUdict, or, for a word it lacks
(names, numbers), from espeak-ng's phonemes for that word mapped to ARPAbet. The audio is
resampled to 16 kHz 16-bit mono, the rate of pocketsphinx's en-us acoustic model. Two
passes of pocketsphinx's alignment search (its documented recipe: words, then phones)
place every phone on its 10 ms frame grid; when the search finds no path, it is run again
over the audio with a faint noise floor added (``NOISE_FLOORS``), which synthetic speech
with digital silence needs; the gaps pocketsphinx leaves and its ``SIL``
become ``sil``, so the spans cover [0, audio duration] contiguously.

Confidence: pocketsphinx's scores are log-likelihoods whose scale depends on the voice
and the recording, so the confidence is measured against a second, unconstrained
decoding of the same audio: a free phone loop (pocketsphinx's ``allphone`` search with its
en-us phone language model). It is the share of the transcript's phones that the free
loop also heard, with the same label, within the aligned phone's span, times the share of
the free loop's phone time that lies inside the transcript's phones (so speech the
transcript leaves out lowers it too). pocketsphinx refuses most transcripts of other
sentences outright (no path through the words); below ``MIN_CONFIDENCE`` the rest are refused
as ``transcript_mismatch``. The phone loop is noisy on real speech, so matching
transcripts score well under 1 (docs/how-to/capture-from-video.md gives the spread on
GRID). Every failure is a ``LipstreamError`` naming the audio file.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.signal import resample_poly

from ..audio import Audio
from ..errors import LipstreamError
from ..phonemes import SILENCE, normalize_phoneme
from ..timeline import PhonemeSpan

ALIGNER_RATE_HZ = 16000
FRAME_S = 0.01  # pocketsphinx's frame period (100 frames a second)
MIN_CONFIDENCE = 0.25
# Noise floors tried in turn (seeded, so runs repeat) until one aligns: digital silence,
# as synthetic speech has, gives log-energy features pocketsphinx's search cannot follow,
# while added noise can lose a real recording that aligned without it.
NOISE_FLOORS = (0.0, 1e-4, 1e-3)
NOISE_SEED = 0
EMPTY_TRANSCRIPT = "empty_transcript"
ALIGNMENT_FAILED = "alignment_failed"
TRANSCRIPT_MISMATCH = "transcript_mismatch"
NOT_SPEECH = "not_speech"
_POCKETSPHINX_SILENCES = frozenset({"SIL", "<sil>", "<s>", "</s>", "+SPN+", "+NSN+", "(NULL)"})
_WORD = re.compile(r"[a-z0-9]+(?:'[a-z0-9]+)*")

Pronouncer = Callable[[Sequence[str]], dict[str, list[str]]]


@dataclass(frozen=True)
class WordSpan:
    """One transcript word and where it was said, in seconds."""

    word: str
    start: float
    end: float


@dataclass(frozen=True)
class Alignment:
    """A forced alignment: ``phones`` contiguous over [0, ``duration``] s in lipstream's
    phoneme set, the transcript's ``words`` (silence left out), and ``confidence`` in
    [0, 1] (the module sketch says how it is measured)."""

    phones: list[PhonemeSpan]
    words: list[WordSpan]
    confidence: float
    duration: float


def transcript_words(transcript: str) -> list[str]:
    """The words the aligner looks up: lower case, hyphens split, punctuation dropped."""
    text = transcript.lower().replace("\u2019", "'").replace("-", " ")
    return _WORD.findall(text)


def align(
    audio: Audio,
    transcript: str,
    *,
    where: str,
    min_confidence: float = MIN_CONFIDENCE,
    pronounce: Pronouncer | None = None,
) -> Alignment:
    """Align ``transcript`` to ``audio``; ``where`` names the audio in every error.

    ``pronounce``: pronunciations of the words pocketsphinx's dictionary lacks (default:
    espeak-ng's). Raises ``empty_transcript``, ``not_speech`` (silent or too short audio),
    ``alignment_failed`` (a word without a pronunciation, or no alignment produced) or
    ``transcript_mismatch`` (no path through the words, or confidence below
    ``min_confidence``).
    """
    words = transcript_words(transcript)
    if not words:
        raise LipstreamError(
            "the transcript has no words to align", where=where, code=EMPTY_TRANSCRIPT
        )
    samples = _at_aligner_rate(audio, where)
    decoder = _decoder()
    _add_missing_words(decoder, words, pronounce or espeak_pronunciations, where)
    for attempt, floor in enumerate(NOISE_FLOORS, start=1):
        pcm = _pcm16(samples, floor)
        try:
            entries = _aligned_phones(decoder, pcm, " ".join(words), where)
            break
        except LipstreamError:
            if attempt == len(NOISE_FLOORS):
                raise
    phones = _spans(entries, audio.duration)
    confidence = _confidence(phones, _free_phone_loop(pcm))
    if confidence < min_confidence:
        raise LipstreamError(
            f"the transcript does not match the speech: only {confidence:.0%} of its phones "
            f"were heard where the alignment puts them (at least {min_confidence:.0%} needed)",
            where=where,
            code=TRANSCRIPT_MISMATCH,
        )
    return Alignment(phones, _words(decoder), confidence, audio.duration)


def _at_aligner_rate(audio: Audio, where: str) -> np.ndarray:
    samples = np.asarray(audio.samples, dtype=np.float64)
    if audio.duration < 0.1 or not np.any(np.abs(samples) > 1e-4):
        raise LipstreamError(
            f"the audio ({audio.duration:.2f} s) holds no speech to align",
            where=where,
            code=NOT_SPEECH,
        )
    common = math.gcd(ALIGNER_RATE_HZ, audio.sample_rate)
    resampled: np.ndarray = resample_poly(
        samples, ALIGNER_RATE_HZ // common, audio.sample_rate // common
    )
    return resampled


def _pcm16(samples: np.ndarray, noise_floor: float) -> bytes:
    noise = np.random.default_rng(NOISE_SEED).standard_normal(len(samples))
    return (np.clip(samples + noise_floor * noise, -1.0, 1.0) * 32767.0).astype("<i2").tobytes()


def _decoder(**options: object) -> Any:
    from pocketsphinx import Decoder

    return Decoder(samprate=ALIGNER_RATE_HZ, loglevel="FATAL", **options)


def _add_missing_words(
    decoder: Any, words: Sequence[str], pronounce: Pronouncer, where: str
) -> None:
    missing = sorted({word for word in words if decoder.lookup_word(word) is None})
    if not missing:
        return
    pronunciations = pronounce(missing)
    for word in missing:
        phones = pronunciations.get(word)
        if not phones:
            raise LipstreamError(
                f"no pronunciation for the word {word!r}", where=where, code=ALIGNMENT_FAILED
            )
        decoder.add_word(word, " ".join(phones), word == missing[-1])


def espeak_pronunciations(words: Sequence[str]) -> dict[str, list[str]]:
    """Each word's phonemes as espeak-ng speaks it alone, in ARPAbet (silence dropped)."""
    from ..speech.espeak import phoneme_spans
    from ..speech.worker import SpeechRequest, speak_in_worker

    spoken = speak_in_worker([SpeechRequest(word) for word in words])
    found: dict[str, list[str]] = {}
    for word, (pcm, rate, events) in zip(words, spoken):
        duration = len(pcm) / 2 / rate
        starts = [(name, ms / 1000.0) for name, ms in events]
        spans = phoneme_spans(starts, duration, where=f"espeak-ng({word!r})")
        found[word] = [span.phoneme for span in spans if span.phoneme != SILENCE]
    return found


@dataclass(frozen=True)
class _Entry:
    label: str
    start: float
    end: float


def _aligned_phones(decoder: Any, pcm: bytes, text: str, where: str) -> list[_Entry]:
    """The two alignment passes (words, then phones), as pocketsphinx documents them."""
    try:
        decoder.set_align_text(text)
        _decode(decoder, pcm)
        if decoder.hyp() is None:
            raise RuntimeError("no path through the words")
        decoder.set_alignment()
        _decode(decoder, pcm)
        alignment = decoder.get_alignment()
    except RuntimeError as error:
        raise LipstreamError(
            f"the transcript does not match the speech: pocketsphinx found no path through "
            f"its words in the audio ({error})",
            where=where,
            code=TRANSCRIPT_MISMATCH,
        ) from None
    if alignment is None:
        raise LipstreamError(
            "pocketsphinx produced no alignment", where=where, code=ALIGNMENT_FAILED
        )
    return [
        _Entry(phone.name, phone.start * FRAME_S, (phone.start + phone.duration) * FRAME_S)
        for phone in alignment.phones()
    ]


def _decode(decoder: Any, pcm: bytes) -> None:
    decoder.start_utt()
    decoder.process_raw(pcm, full_utt=True)
    decoder.end_utt()


def _words(decoder: Any) -> list[WordSpan]:
    alignment = decoder.get_alignment()
    found = []
    for word in alignment.words():
        name = re.sub(r"\(\d+\)$", "", word.name)  # pronunciation variant: white(2)
        if name in _POCKETSPHINX_SILENCES:
            continue
        found.append(WordSpan(name, word.start * FRAME_S, (word.start + word.duration) * FRAME_S))
    return found


def _label(name: str) -> str:
    if name in _POCKETSPHINX_SILENCES:
        return SILENCE
    return normalize_phoneme(name, source="arpabet", where="pocketsphinx")


def _spans(entries: Sequence[_Entry], duration: float) -> list[PhonemeSpan]:
    """Contiguous spans over [0, ``duration``]: gaps and pocketsphinx's silences become
    ``sil`` (touching silences merge), and nothing runs past the audio's end."""
    spans: list[PhonemeSpan] = []

    def add(label: str, start: float, end: float) -> None:
        end = min(end, duration)
        if end <= start:
            return
        if spans and label == SILENCE and spans[-1].phoneme == SILENCE:
            spans[-1] = PhonemeSpan(SILENCE, spans[-1].start, end)
        else:
            spans.append(PhonemeSpan(label, start, end))

    cursor = 0.0
    for entry in entries:
        if entry.start > cursor:
            add(SILENCE, cursor, entry.start)
        add(_label(entry.label), max(entry.start, cursor), entry.end)
        cursor = max(cursor, entry.end)
    if cursor < duration:
        add(SILENCE, cursor, duration)
    return spans


def _free_phone_loop(pcm: bytes) -> list[_Entry]:
    """What pocketsphinx hears with no transcript: its phone loop's best phone sequence."""
    from pocketsphinx import get_model_path

    phone_model = str(Path(get_model_path()) / "en-us" / "en-us-phone.lm.bin")
    decoder = _decoder(allphone=phone_model, lw=2.0, beam=1e-20, pbeam=1e-20)
    _decode(decoder, pcm)
    return [
        _Entry(segment.word, segment.start_frame * FRAME_S, (segment.end_frame + 1) * FRAME_S)
        for segment in decoder.seg()
        if segment.word not in _POCKETSPHINX_SILENCES
    ]


def _confidence(phones: Sequence[PhonemeSpan], heard: Sequence[_Entry]) -> float:
    """Agreement times coverage: the share of the transcript's phones the free loop heard
    within their span, times the share of the free loop's phone time that falls inside
    the transcript's phones (speech the transcript leaves out lowers it)."""
    spoken = [span for span in phones if span.phoneme != SILENCE]
    heard_s = sum(entry.end - entry.start for entry in heard)
    if not spoken or heard_s <= 0.0:
        return 0.0
    agreed = sum(
        any(
            entry.label == span.phoneme and entry.start < span.end and entry.end > span.start
            for entry in heard
        )
        for span in spoken
    )
    inside = sum(
        max(0.0, min(entry.end, span.end) - max(entry.start, span.start))
        for entry in heard
        for span in spoken
    )
    return (agreed / len(spoken)) * (inside / heard_s)


def write_alignment_textgrid(path: Path, alignment: Alignment) -> None:
    """A TextGrid (praatio, long format) with a ``phones`` tier (ARPAbet, silence empty)
    and a ``words`` tier, over [0, the audio's duration]."""
    from praatio import textgrid
    from praatio.utilities.constants import Interval

    end = alignment.duration
    phones = [
        Interval(_time(span.start), _time(span.end), span.phoneme)
        for span in alignment.phones
        if span.phoneme != SILENCE
    ]
    words = [Interval(_time(w.start), _time(w.end), w.word) for w in alignment.words]
    grid = textgrid.Textgrid(0.0, _time(end))
    grid.addTier(textgrid.IntervalTier("phones", phones, 0.0, _time(end)))
    grid.addTier(textgrid.IntervalTier("words", words, 0.0, _time(end)))
    grid.save(str(path), format="long_textgrid", includeBlankSpaces=True)


def _time(seconds: float) -> float:
    # praatio writes repr(float); microsecond rounding keeps its own reader happy
    return round(float(seconds), 6)
