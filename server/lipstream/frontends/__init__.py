"""Front ends: what a speech engine gives (text, timings, IPA in any language) as phoneme spans.

Sketch: each module is one step. ``ipa_features`` describes IPA symbols by
their articulation, ``phoneme_prototypes`` describes the phoneme set the
same way, ``ipa_segments`` reads a label into segments, ``nearest_phoneme``
maps each segment to the phoneme nearest by features, ``espeak_languages``
names the languages espeak-ng speaks and ``language_table`` renders which
of them map fully.
"""
