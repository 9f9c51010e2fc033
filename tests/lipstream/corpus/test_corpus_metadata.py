"""``<stem>.json``: the transcript is kept, other keys are ignored with a warning naming them."""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import pytest

from lipstream.corpus import CorpusWarning, load_corpus, write_corpus


def test_text_is_read_and_written_back(build: Any, tmp_path: Path) -> None:
    source = tmp_path / "source"
    source.mkdir()
    build.write_utterance(source, "a", metadata={"text": "hello world", "speaker": "anna"})
    build.write_utterance(source, "b", metadata={"emotion": "sad"})
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # known keys warn about nothing
        corpus = load_corpus(source)
    first, second = corpus.utterances
    assert (first.text, first.speaker, first.emotion) == ("hello world", "anna", "neutral")
    assert (second.text, second.emotion) == (None, "sad")
    copy = tmp_path / "copy"
    write_corpus(corpus, copy)
    assert json.loads((copy / "a.json").read_text())["text"] == "hello world"
    assert "text" not in json.loads((copy / "b.json").read_text())
    assert load_corpus(copy).utterances[0].text == "hello world"


def test_unknown_keys_warn_naming_file_and_key_and_load(build: Any, tmp_path: Path) -> None:
    build.write_utterance(
        tmp_path, "a", metadata={"text": "hi", "duration": 1.0, "id": "utt-7", "emotion": "happy"}
    )
    with pytest.warns(CorpusWarning) as caught:
        corpus = load_corpus(tmp_path)
    messages = [str(warning.message) for warning in caught]
    assert messages == [
        "a.json: unknown key 'duration' ignored; known keys: emotion, speaker, text, alignment_confidence",
        "a.json: unknown key 'id' ignored; known keys: emotion, speaker, text, alignment_confidence",
    ]
    assert (corpus.utterances[0].text, corpus.utterances[0].emotion) == ("hi", "happy")


def test_corpus_json_stays_strict_about_its_keys(build: Any, tmp_path: Path) -> None:
    build.write_utterance(tmp_path, "a")
    (tmp_path / "corpus.json").write_text(json.dumps({"fsp": 60}))
    with pytest.raises(Exception, match="unknown key 'fsp'; allowed keys: name, fps, channels"):
        load_corpus(tmp_path)
