"""The recipe that turns a visitor's recordings into a character.

Sketch: capture every take (face channels and aligned phones), then train ``ENGINES`` on all
the takes that captured (no held-out split: every sentence is precious). A job needs at
least ``MIN_GOOD_TAKES`` good takes; the session prompts ``PROMPT_COUNT`` sentences. The
numbers are set from the measured curve of quality against the number of sentences
(docs/how-to/record-your-face.md).
"""

from __future__ import annotations

ENGINES: tuple[str, ...] = ("viseme-lerp", "dam")
"""The engines trained on the recordings: ``viseme-lerp`` (the character's key poses, and
the viseme source every other engine of the character is projected through) and ``dam``
(its coarticulation). Both train in seconds on ten sentences."""

MIN_GOOD_TAKES = 5
"""The fewest takes that captured (a face, speech, an alignment) a job trains on; with
fewer it fails with ``too_few_takes``, listing each failed take and why."""

PROMPT_COUNT = 20
"""How many prompt sentences a session offers (``prompts.choose_prompts``), at most the
server's ``LIPSTREAM_MAX_TAKES``."""
