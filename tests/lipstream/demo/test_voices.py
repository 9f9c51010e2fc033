"""Demo lines spoken again in other espeak-ng voices: the same person's face, a new voice."""

from __future__ import annotations

import numpy as np

from lipstream.demo.generate import generate_demo_corpus, plan_demo_utterances
from lipstream.demo.sentences import load_sentences
from lipstream.demo.voices import (
    HELDOUT_VOICE,
    TRAINING_VOICES,
    Voice,
    revoiced_plan,
    revoiced_utterances,
)


def test_a_revoiced_plan_keeps_the_line_and_the_face_and_changes_the_voice() -> None:
    plan = plan_demo_utterances(load_sentences()[:1])[0]
    again = revoiced_plan(plan, Voice("m1", -12))
    assert again.sentence == plan.sentence and again.emotion == plan.emotion
    assert again.stem == f"{plan.stem}_m1"
    assert again.speaker.voice == "en-us+m1"
    assert again.speaker.pitch == plan.speaker.pitch - 12
    assert again.speaker.jaw_scale == plan.speaker.jaw_scale
    assert again.seed == plan.seed


def test_the_held_out_voice_is_no_training_voice_nor_a_demo_speakers() -> None:
    demo = {plan.speaker.voice for plan in plan_demo_utterances(load_sentences()[:12])}
    assert HELDOUT_VOICE.variant not in {voice.variant for voice in TRAINING_VOICES}
    assert f"en-us+{HELDOUT_VOICE.variant}" not in demo


def test_revoiced_lines_are_spoken_anew_by_espeak_ng() -> None:
    corpus = generate_demo_corpus(n_sentences=2)
    plans = plan_demo_utterances(load_sentences()[:2])
    lines = revoiced_utterances(plans, [Voice("m1", -12)], corpus.fps)
    for original, again in zip(corpus.utterances, lines, strict=True):
        assert again.stem == f"{original.stem}_m1"
        assert again.audio is not None and original.audio is not None
        assert len(again.audio.samples) != len(original.audio.samples) or not np.array_equal(
            again.audio.samples, original.audio.samples
        )
        assert [span.phoneme for span in again.phones if span.phoneme != "sil"]
        starts = [span.start for span in again.phones]
        ends = [span.end for span in again.phones]
        assert starts[0] == 0.0 and ends[-1] == again.audio.duration
        assert starts[1:] == ends[:-1]
        assert again.frames.shape[1] == original.frames.shape[1]
