"""The forced aligner's error codes (``align``), apart from it, so that the server can name
them without importing the aligner (and pocketsphinx) before a transcript arrives."""

EMPTY_TRANSCRIPT = "empty_transcript"
ALIGNMENT_FAILED = "alignment_failed"
TRANSCRIPT_MISMATCH = "transcript_mismatch"
NOT_SPEECH = "not_speech"
