"""The demo corpus: stems, emotions, speakers, padding, held-out set, determinism."""

from __future__ import annotations

import math
from collections import Counter
from itertools import pairwise

import numpy as np
import pytest

from lipstream.audio import Audio
from lipstream.corpus import EMOTIONS, Corpus
from lipstream.demo.face import DEMO_CHANNELS
from lipstream.demo.generate import (
    generate_demo_corpus,
    heldout_indices,
    pad_with_silence,
    synthesizer_for,
)
from lipstream.demo.speakers import DEMO_SPEAKERS
from lipstream.errors import InvalidRequestError
from lipstream.timeline import PhonemeSpan


@pytest.fixture(scope="module")
def small() -> Corpus:
    return generate_demo_corpus(n_sentences=8)


def test_small_corpus_layout(small: Corpus) -> None:
    assert small.name == "demo"
    assert small.fps == 120.0
    assert small.channels == DEMO_CHANNELS
    assert small.stems == tuple(f"demo_{i:04d}" for i in range(1, 9))
    emotions = [utterance.emotion for utterance in small.utterances]
    assert emotions == ["neutral", "happy", "angry", "sad"] * 2
    speakers = [utterance.speaker for utterance in small.utterances]
    assert speakers == [DEMO_SPEAKERS[0].name] * 4 + [DEMO_SPEAKERS[1].name] * 4
    assert small.heldout == ("demo_0001",)


def test_each_utterance_is_padded_aligned_and_framed(small: Corpus) -> None:
    for utterance in small.utterances:
        audio = utterance.audio
        assert audio is not None and audio.sample_rate == 22050
        phones = utterance.phones
        assert phones[0].start == 0.0 and phones[0].phoneme == "sil" and phones[0].duration >= 0.2
        assert phones[-1].phoneme == "sil" and phones[-1].duration >= 0.2
        assert phones[-1].end == pytest.approx(audio.duration, abs=1e-9)
        assert all(a.end == b.start for a, b in pairwise(phones))
        assert utterance.n_frames == math.floor(audio.duration * 120.0 + 1e-9) + 1
        lead = int(0.19 * audio.sample_rate)
        assert np.max(np.abs(audio.samples[:lead])) == 0.0
        assert np.max(np.abs(audio.samples)) > 0.1


def test_emotion_sets_the_speaking_rate(small: Corpus) -> None:
    # Utterances 4 (sad, 135 wpm) and 2 (happy, 180 wpm) speak different texts, so
    # compare the settings themselves and their effect on one text instead.
    sad = synthesizer_for(DEMO_SPEAKERS[0], "sad")
    happy = synthesizer_for(DEMO_SPEAKERS[0], "happy")
    assert sad.rate == round(135 * DEMO_SPEAKERS[0].rate_factor)
    assert happy.rate == round(180 * DEMO_SPEAKERS[0].rate_factor)
    assert sad.pitch < happy.pitch and sad.voice == happy.voice == DEMO_SPEAKERS[0].voice
    text = "The weather will be lovely all week long."
    assert sad.speak(text)[0].duration > 1.2 * happy.speak(text)[0].duration


def test_generation_is_deterministic(small: Corpus) -> None:
    again = generate_demo_corpus(n_sentences=8)
    assert again.digest() == small.digest()
    shorter = generate_demo_corpus(n_sentences=3, fps=60.0)
    assert shorter.fps == 60.0 and shorter.stems == small.stems[:3]
    for low, high in zip(shorter.utterances, small.utterances):
        assert low.phones == high.phones
        assert low.audio is not None and high.audio is not None
        assert low.audio.samples.tobytes() == high.audio.samples.tobytes()


def test_heldout_indices_rotate_emotions() -> None:
    assert heldout_indices(40) == [0, 13, 22, 31]
    chosen = heldout_indices(400)
    assert len(chosen) == 40
    assert Counter(EMOTIONS[index % 4] for index in chosen) == {emotion: 10 for emotion in EMOTIONS}
    assert heldout_indices(1) == []


def test_pad_with_silence_shifts_spans() -> None:
    audio = Audio(np.ones(1000, np.float32), 1000)
    spans = [PhonemeSpan("M", 0.0, 0.4), PhonemeSpan("AA", 0.4, 0.9), PhonemeSpan("sil", 0.9, 1.0)]
    padded, moved = pad_with_silence(audio, spans, 0.25, 0.3)
    assert len(padded.samples) == 1550
    assert moved == [
        PhonemeSpan("sil", 0.0, 0.25),
        PhonemeSpan("M", 0.25, 0.65),
        PhonemeSpan("AA", 0.65, 1.15),
        PhonemeSpan("sil", 1.15, 1.55),
    ]


def test_bad_sentence_count_raises() -> None:
    with pytest.raises(InvalidRequestError, match="n_sentences"):
        generate_demo_corpus(n_sentences=0)
    with pytest.raises(InvalidRequestError, match="n_sentences"):
        generate_demo_corpus(n_sentences=100000)


@pytest.mark.slow
def test_full_corpus_size_and_balance() -> None:
    corpus = generate_demo_corpus()
    assert len(corpus) >= 250
    minutes = sum(utterance.duration for utterance in corpus.utterances) / 60.0
    assert minutes >= 15.0
    pairs = Counter((utterance.speaker, utterance.emotion) for utterance in corpus.utterances)
    assert len(pairs) == len(DEMO_SPEAKERS) * len(EMOTIONS)
    assert max(pairs.values()) - min(pairs.values()) <= 1
    assert abs(len(corpus.heldout) - len(corpus) / 10) <= 1
    held = Counter(corpus.utterance(stem).emotion for stem in corpus.heldout)
    assert set(held) == set(EMOTIONS) and max(held.values()) - min(held.values()) <= 1
