"""Build the demo corpus: the shipped sentences spoken and performed by the demo character.

Sketch: sentence ``i`` (0-based) becomes utterance ``demo_{i+1:04d}``. Emotions
cycle neutral, happy, angry, sad; the speaker changes every four sentences, so
every twelve sentences hold each (speaker, emotion) pair once. espeak-ng speaks
each sentence with the speaker's voice at the emotion's rate and pitch (all of
them in order in one fresh process, so the audio is reproducible), the audio
is padded with 0.2-0.4 s of silence at each end, and ``generate_face``
performs the phones. One utterance per block of ten is held out, chosen so
the held-out emotions rotate neutral, happy, angry, sad. The corpus is the
same on every run, and its first k utterances do not depend on how many
sentences were asked for.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
from tqdm import tqdm

from ..audio import Audio
from ..corpus import EMOTIONS, Corpus, Utterance
from ..errors import InvalidRequestError
from ..phonemes import SILENCE
from ..speech.espeak import PITCH_RANGE, RATE_RANGE_WPM, EspeakSynthesizer
from ..timeline import PhonemeSpan
from .expression import emotion_style
from .face import DEMO_CHANNELS, generate_face
from .sentences import load_sentences
from .speakers import DEMO_SPEAKERS, Speaker
from .speech_batch import speak_batch

CORPUS_NAME = "demo"
PADDING_S = (0.2, 0.4)
HELDOUT_BLOCK = 10
_PADDING_SEED = 20240
_Item = TypeVar("_Item")


@dataclass(frozen=True)
class DemoUtterancePlan:
    """What utterance ``index`` of the demo corpus says, and how."""

    index: int
    stem: str
    sentence: str
    emotion: str
    speaker: Speaker

    @property
    def seed(self) -> int:
        return self.index + 1


def demo_stem(index: int) -> str:
    """Stem of the 0-based ``index``-th utterance: ``demo_0001`` for 0."""
    return f"demo_{index + 1:04d}"


def plan_demo_utterances(sentences: list[str]) -> list[DemoUtterancePlan]:
    """The emotion and speaker pattern over ``sentences`` (see the module sketch)."""
    return [
        DemoUtterancePlan(
            index=index,
            stem=demo_stem(index),
            sentence=sentence,
            emotion=EMOTIONS[index % len(EMOTIONS)],
            speaker=DEMO_SPEAKERS[(index // len(EMOTIONS)) % len(DEMO_SPEAKERS)],
        )
        for index, sentence in enumerate(sentences)
    ]


def heldout_indices(n_utterances: int) -> list[int]:
    """One index per block of ten: in block ``b`` the one whose emotion is
    ``EMOTIONS[b % 4]`` (so held-out emotions rotate evenly), moving through
    the block so speakers rotate too. A single utterance is never held out."""
    n_emotions = len(EMOTIONS)
    chosen: list[int] = []
    if n_utterances < 2:
        return chosen
    for block in range((n_utterances + HELDOUT_BLOCK - 1) // HELDOUT_BLOCK):
        wanted = block % n_emotions
        offset = (wanted - block * HELDOUT_BLOCK) % n_emotions
        offset += n_emotions * ((block // n_emotions) % 2)
        index = block * HELDOUT_BLOCK + offset
        if index < n_utterances:
            chosen.append(index)
    return chosen


def synthesizer_for(speaker: Speaker, emotion: str) -> EspeakSynthesizer:
    """The speaker's voice with the emotion's rate, pitch and pitch range."""
    style = emotion_style(emotion)
    rate = int(np.clip(round(style.rate_wpm * speaker.rate_factor), *RATE_RANGE_WPM))
    pitch = int(np.clip(speaker.pitch + style.pitch_offset, *PITCH_RANGE))
    return EspeakSynthesizer(
        voice=speaker.voice, rate=rate, pitch=pitch, pitch_range=style.pitch_range
    )


def pad_with_silence(
    audio: Audio, spans: list[PhonemeSpan], lead_s: float, tail_s: float
) -> tuple[Audio, list[PhonemeSpan]]:
    """Audio with ``lead_s`` and ``tail_s`` seconds of silence added, spans shifted to
    match and still covering the whole audio (edge silences merged)."""
    lead = round(lead_s * audio.sample_rate)
    tail = round(tail_s * audio.sample_rate)
    samples = np.concatenate(
        [np.zeros(lead, np.float32), audio.samples, np.zeros(tail, np.float32)]
    )
    padded = Audio(samples, audio.sample_rate)
    shift = lead / audio.sample_rate
    moved = [PhonemeSpan(span.phoneme, span.start + shift, span.end + shift) for span in spans]
    if moved[0].phoneme == SILENCE:
        moved[0] = PhonemeSpan(SILENCE, 0.0, moved[0].end)
    else:
        moved.insert(0, PhonemeSpan(SILENCE, 0.0, shift))
    if moved[-1].phoneme == SILENCE:
        moved[-1] = PhonemeSpan(SILENCE, moved[-1].start, padded.duration)
    else:
        moved.append(PhonemeSpan(SILENCE, moved[-1].end, padded.duration))
    return padded, moved


def build_demo_utterance(
    plan: DemoUtterancePlan, speech: tuple[Audio, list[PhonemeSpan]], fps: float
) -> Utterance:
    """Pad the planned utterance's ``speech`` (audio, spans) and perform it."""
    audio, spans = speech
    lead_s, tail_s = np.random.default_rng([_PADDING_SEED, plan.index]).uniform(*PADDING_S, size=2)
    audio, spans = pad_with_silence(audio, spans, float(lead_s), float(tail_s))
    frames = generate_face(
        spans, audio.duration, emotion=plan.emotion, speaker=plan.speaker, fps=fps, seed=plan.seed
    )
    return Utterance(
        stem=plan.stem,
        frames=frames,
        phones=spans,
        fps=fps,
        audio=audio,
        emotion=plan.emotion,
        speaker=plan.speaker.name,
    )


def _chosen_sentences(n_sentences: int | None) -> list[str]:
    sentences = load_sentences()
    if n_sentences is None:
        return sentences
    if (
        isinstance(n_sentences, bool)
        or not isinstance(n_sentences, int)
        or not (1 <= n_sentences <= len(sentences))
    ):
        raise InvalidRequestError(
            f"must be an integer in [1, {len(sentences)}], got {n_sentences!r}", where="n_sentences"
        )
    return sentences[:n_sentences]


def _with_progress(items: list[_Item], progress: bool) -> Iterator[_Item]:
    if progress:
        yield from tqdm(items, desc="demo corpus", unit="utt", file=sys.stderr)
    else:
        yield from items


def generate_demo_corpus(
    *, n_sentences: int | None = None, fps: float = 120.0, progress: bool = False
) -> Corpus:
    """The demo corpus over the first ``n_sentences`` shipped sentences (all by default).

    Frames are ``DEMO_CHANNELS`` at ``fps``; every utterance has audio,
    contiguous phones, an emotion and a speaker; about 10% are held out.
    """
    plans = plan_demo_utterances(_chosen_sentences(n_sentences))
    speech = speak_batch(
        [(synthesizer_for(plan.speaker, plan.emotion), plan.sentence) for plan in plans]
    )
    utterances = [
        build_demo_utterance(plan, spoken, fps)
        for plan, spoken in _with_progress(list(zip(plans, speech)), progress)
    ]
    heldout = tuple(plans[index].stem for index in heldout_indices(len(plans)))
    return Corpus(
        name=CORPUS_NAME, fps=fps, channels=DEMO_CHANNELS, utterances=utterances, heldout=heldout
    )
