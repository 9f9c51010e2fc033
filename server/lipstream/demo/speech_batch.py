"""Reproducible speech: a batch of utterances synthesized in a fresh process.

Sketch: libespeak-ng keeps process-wide state that no API call resets (its
pitch-flutter phase, among others), so the same request spoken twice in one
process can differ by a few samples and move phoneme boundaries by a
millisecond. A batch spoken by a new worker process (``speech.worker``)
starts from the library's initial state, so its output depends on the batch
alone; phoneme names are normalized here, in the caller.
"""

from __future__ import annotations

from collections.abc import Sequence

from ..audio import Audio
from ..speech.espeak import EspeakSynthesizer, check_text, speech_result
from ..speech.worker import SpeechRequest, speak_in_worker
from ..timeline import PhonemeSpan


def speak_batch(
    requests: Sequence[tuple[EspeakSynthesizer, str]],
) -> list[tuple[Audio, list[PhonemeSpan]]]:
    """Speak each (voice setting, text) in order in a fresh process.

    Returns what ``EspeakSynthesizer.speak`` returns, per request. The same
    batch gives identical output in every run and whatever the calling
    process spoke before.
    """
    for _, text in requests:
        check_text(text)
    batch = [SpeechRequest(text, s.voice, s.rate, s.pitch, s.pitch_range) for s, text in requests]
    raws = speak_in_worker(batch)
    return [
        speech_result(text, pcm, rate, events)
        for (_, text), (pcm, rate, events) in zip(requests, raws)
    ]
