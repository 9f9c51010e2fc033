"""The recipe that turns a visitor's recordings into a character.

Sketch: capture every take (face channels and aligned phones), then train ``ENGINES`` on all
the takes that captured (no held-out split: every sentence is precious). A job needs at
least ``MIN_GOOD_TAKES`` good takes; the session prompts ``PROMPT_COUNT`` sentences. The
numbers are set from the measured curve of held-out quality against the number of
sentences, ``bench/sentences_curve.json`` (``python -m lipstream.bench.sentences``:
every engine trained on seeded draws of N sentences of a generated speaker, scored beside
``viseme-lerp`` trained on the same draw and beside the demo character's shipped models),
rendered in docs/how-to/record-your-face.md#how-much-speech-is-enough. The rule: an engine
is in the recipe when, at ``PROMPT_COUNT`` sentences, its median held-out RMS is at most
``viseme-lerp``'s and its lip aperture follows the recording more closely (higher r).
"""

from __future__ import annotations

ENGINES: tuple[str, ...] = ("viseme-lerp", "cohen-massaro", "dam")
"""The engines trained on the recordings. ``viseme-lerp``: the character's key poses, the
viseme source every other engine of the character is projected through, and the best RMS
of all below ten sentences; it closes every /p b m/. ``cohen-massaro`` and ``dam``: on the
curve, both match or beat ``viseme-lerp`` in RMS from twenty sentences, in every draw at
forty, and follow the lip aperture more closely from ten; at forty both beat the demo
character's models of the same engine in RMS. Left out: ``anime-graph`` and ``expressive-dp``
follow the aperture closely but stay above ``viseme-lerp`` in RMS up to eighty sentences,
and ``hmm`` is behind it on both."""

MIN_GOOD_TAKES = 10
"""The fewest takes that captured (a face, speech, an alignment) a job trains on; with
fewer it fails with ``too_few_takes``, listing each failed take and why. From ten
sentences every engine of the recipe is within a few percent of ``viseme-lerp``'s RMS and
ahead of it in aperture r; at five, ``dam``'s worst draw is far behind."""

PROMPT_COUNT = 40
"""How many prompt sentences a session offers (``prompts.choose_prompts``), at most the
server's ``LIPSTREAM_MAX_TAKES``: forty is where every draw of ``dam`` and
``cohen-massaro`` beats ``viseme-lerp`` and the personal models beat the demo
character's in RMS; eighty gains little more."""
