"""Front ends: what a speech engine gives (text, timings, IPA in any language) as phoneme spans.

Sketch: each module is one step. ``ipa_features`` describes IPA symbols by
their articulation, ``phoneme_prototypes`` describes the phoneme set the
same way, ``ipa_segments`` reads a label into segments, ``nearest_phoneme``
maps each segment to the phoneme nearest by features, ``espeak_ipa`` reads
espeak-ng's phoneme names as IPA, and ``espeak_languages`` names the
languages and voice variants espeak-ng speaks (``lipstream.bench.languages``
surveys which of them map fully).
"""
