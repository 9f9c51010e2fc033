"""Front ends: what speech engines give (word, character, viseme or phoneme timings) to
phoneme spans.

Sketch: a timing file or message is parsed by its format (``formats``) into one common
type, ``timings.SpeechTimings``, whose times are checked once (``timing_checks``). Words
get their phonemes from a lexicon (``lexicon``: CMUdict, espeak-ng for the rest), a
duration model trained on a corpus's phone alignments (``word_durations``) spreads them
over each word's time (``spreading``), pauses between words become silence, and viseme-
only input becomes spans of a representative phoneme (``viseme_spans``).
``words_to_spans.timings_to_spans`` runs the steps.
"""
