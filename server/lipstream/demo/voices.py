"""The demo lines spoken again in other espeak-ng voices, for training and testing a model
that listens (``hmm`` driven by audio).

Sketch: a planned line keeps its sentence, emotion and speaker (so its face is performed
by the same person) but the speaker's voice is swapped for an espeak-ng variant
(``en-us+m1`` ... ``en-us+f5``) with the pitch moved by a step per voice. The line is
spoken afresh (its phone timings are the new voice's own) and performed from those
timings, as ``generate`` performs every line; its stem is the line's plus the variant's
name. All lines of a call are spoken in one fresh process, so the output is reproducible.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

from ..corpus import Utterance
from ..speech.espeak import PITCH_RANGE
from .generate import DemoUtterancePlan, build_demo_utterance, synthesizer_for
from .speech_batch import speak_batch


@dataclass(frozen=True)
class Voice:
    """An espeak-ng variant of the speaker's language and a pitch step (espeak units)."""

    variant: str
    pitch_shift: int = 0

    @property
    def tag(self) -> str:
        return self.variant.replace("+", "_").replace("-", "_")


TRAINING_VOICES: tuple[Voice, ...] = (Voice("m1", -12), Voice("f2", 8), Voice("m5", 0))
"""Voices the demo lines are spoken again in for a listening model's training."""
HELDOUT_VOICE = Voice("f5", 14)
"""A voice no training line is spoken in: the test of a voice the model has not heard."""


def revoiced_plan(plan: DemoUtterancePlan, voice: Voice) -> DemoUtterancePlan:
    """``plan`` with its speaker speaking in ``voice``."""
    speaker = plan.speaker
    language = speaker.voice.split("+")[0]
    low, high = PITCH_RANGE
    pitch = min(high, max(low, speaker.pitch + voice.pitch_shift))
    respoken = replace(speaker, voice=f"{language}+{voice.variant}", pitch=pitch)
    return replace(plan, stem=f"{plan.stem}_{voice.tag}", speaker=respoken)


def revoiced_utterances(
    plans: Sequence[DemoUtterancePlan], voices: Sequence[Voice], fps: float
) -> list[Utterance]:
    """Every plan spoken in every voice (voice by voice) and performed."""
    chosen = [revoiced_plan(plan, voice) for voice in voices for plan in plans]
    speech = speak_batch([(synthesizer_for(p.speaker, p.emotion), p.sentence) for p in chosen])
    return [build_demo_utterance(plan, spoken, fps) for plan, spoken in zip(chosen, speech)]
