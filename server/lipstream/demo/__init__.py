"""The demo character: a deterministic synthetic facial-capture corpus.

Sketch: espeak-ng speaks the project's own sentences (``espeak``), and an
articulatory face model (``face``: targets, planning, dynamics, expression,
blinks) performs them as ARKit-style blendshape curves; ``generate`` puts
both together into a ``Corpus``. See docs/explanation/demo-character.md.
"""

from ..speech.espeak import EspeakSynthesizer
from .face import DEMO_CHANNELS, generate_face
from .generate import generate_demo_corpus
from .sentences import load_sentences
from .speakers import DEMO_SPEAKERS, Speaker

__all__ = [
    "DEMO_CHANNELS",
    "DEMO_SPEAKERS",
    "EspeakSynthesizer",
    "Speaker",
    "generate_demo_corpus",
    "generate_face",
    "load_sentences",
]
