"""Phonetics below every layer that reads labels: IPA symbols described by their articulation
and the phoneme set described the same way, so any language's IPA maps to lipstream's phonemes.

Sketch: ``ipa_features`` describes IPA symbols (place, manner, voicing, height, backness,
rounding, nasality, rhoticity), ``phoneme_prototypes`` describes the 39 phonemes by their
General American realization, ``ipa_segments`` reads a label into segments (base symbols and
their diacritics), and ``nearest_phoneme`` maps each segment to the phoneme nearest by
weighted features. ``lipstream.phonemes`` normalizes IPA through it; the front ends
(``frontends.espeak_ipa``, languages) build on both. Nothing here imports another lipstream
module.
"""
