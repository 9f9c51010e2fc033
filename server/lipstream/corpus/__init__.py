"""Training corpora: frame-sampled control curves aligned to phones.

Sketch: a corpus is a directory of utterances sharing file stems (frames CSV
or Live Link Face export, TextGrid or .lab phones, optional WAV and JSON
metadata, optional ``corpus.json``); ``load_corpus`` validates it strictly
and resamples every utterance onto one ``i / fps`` grid, ``write_corpus``
writes one back. See ``docs/reference/corpus-formats.md``.
"""

from ..timeline import EMOTIONS
from .frames_csv import read_frames_csv, write_frames_csv
from .lab import read_lab_phones
from .livelink import read_livelink_csv
from .loader import load_corpus
from .metadata import CorpusWarning
from .model import Corpus, Utterance
from .textgrid import read_textgrid_phones
from .writer import write_corpus

__all__ = [
    "EMOTIONS",
    "Corpus",
    "CorpusWarning",
    "Utterance",
    "load_corpus",
    "read_frames_csv",
    "read_lab_phones",
    "read_livelink_csv",
    "read_textgrid_phones",
    "write_corpus",
    "write_frames_csv",
]
