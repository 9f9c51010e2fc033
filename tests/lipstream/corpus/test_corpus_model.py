"""Corpus/Utterance: digest, split, subset and construction checks."""

from __future__ import annotations

import copy
from collections.abc import Callable

import numpy as np
import pytest

from lipstream.audio import Audio
from lipstream.corpus import Corpus, Utterance
from lipstream.errors import CorpusError
from lipstream.timeline import PhonemeSpan

CHANNELS = ("jawOpen", "mouthClose")


def utterance(stem: str, seed: int = 0, emotion: str = "neutral") -> Utterance:
    frames = np.random.default_rng(seed).uniform(0, 1, size=(31, 2))
    return Utterance(stem, frames, [PhonemeSpan("AA", 0.0, 0.5)], fps=60.0, emotion=emotion)


def corpus(stems: list[str], heldout: tuple[str, ...] = ()) -> Corpus:
    return Corpus("c", 60.0, CHANNELS, [utterance(s, i) for i, s in enumerate(stems)], heldout)


def test_duration_and_times() -> None:
    item = utterance("a")
    assert item.duration == pytest.approx(0.5)
    assert item.times()[-1] == pytest.approx(0.5)
    assert item.frames.dtype == np.float32


def test_digest_is_stable_and_ignores_the_name() -> None:
    first, second = corpus(["a", "b"]), corpus(["a", "b"])
    assert first.digest() == second.digest()
    assert len(first.digest()) == 64 and int(first.digest(), 16) >= 0
    second.name = "renamed"
    assert first.digest() == second.digest()


def test_digest_changes_with_one_frame_value() -> None:
    base = corpus(["a", "b"])
    changed = copy.deepcopy(base)
    changed.utterances[1].frames[17, 1] += np.float32(1e-6)
    assert base.digest() != changed.digest()


@pytest.mark.parametrize(
    "change",
    [
        lambda c: setattr(c.utterances[0], "emotion", "sad"),
        lambda c: setattr(c.utterances[0], "phones", [PhonemeSpan("AA", 0.0, 0.51)]),
        lambda c: setattr(c.utterances[0], "phones", [PhonemeSpan("AE", 0.0, 0.5)]),
        lambda c: setattr(c, "fps", 30.0),
        lambda c: setattr(c, "channels", ("mouthClose", "jawOpen")),
        lambda c: setattr(c.utterances[0], "audio", Audio(np.zeros(10, np.float32), 8000)),
        lambda c: c.utterances.reverse(),
    ],
    ids=["emotion", "phone-time", "phone-label", "fps", "channel-order", "audio", "order"],
)
def test_digest_covers_what_training_sees(change: Callable[[Corpus], object]) -> None:
    base = corpus(["a", "b"])
    changed = copy.deepcopy(base)
    change(changed)
    assert base.digest() != changed.digest()


def test_split_takes_every_tenth_sorted_stem() -> None:
    stems = [f"u{k:02d}" for k in range(25)]
    shuffled = [stems[k] for k in np.random.default_rng(1).permutation(25)]
    train, held = corpus(shuffled).split()
    assert held.stems == tuple(s for s in shuffled if s in {"u09", "u19"})
    assert len(train) == 23 and not set(train.stems) & set(held.stems)
    assert (train.name, train.fps, train.channels) == ("c", 60.0, CHANNELS)
    again_train, again_held = corpus(shuffled).split()
    assert (again_train.stems, again_held.stems) == (train.stems, held.stems)


def test_split_uses_declared_heldout() -> None:
    train, held = corpus(["a", "b", "c"], heldout=("b",)).split()
    assert (train.stems, held.stems) == (("a", "c"), ("b",))


def test_small_corpus_has_no_default_heldout() -> None:
    train, held = corpus([f"s{k}" for k in range(9)]).split()
    assert len(train) == 9 and len(held) == 0


def test_subset() -> None:
    full = corpus(["a", "b", "c", "d"], heldout=("b", "d"))
    part = full.subset(["d", "a", "b"])
    assert part.stems == ("a", "b", "d")
    assert part.heldout == ("b", "d")
    with pytest.raises(CorpusError, match="zzz"):
        full.subset(["a", "zzz"])


@pytest.mark.parametrize(
    ("frames", "fps", "emotion", "fragment"),
    [
        (np.full((3, 2), np.nan), 60.0, "neutral", "NaN"),
        (np.zeros(3), 60.0, "neutral", "shape"),
        (np.zeros((3, 2)), 0.0, "neutral", "fps"),
        (np.zeros((3, 2)), 60.0, "furious", "emotion"),
    ],
)
def test_utterance_rejects_bad_fields(
    frames: np.ndarray, fps: float, emotion: str, fragment: str
) -> None:
    with pytest.raises(CorpusError, match=fragment):
        Utterance("x", frames, [], fps=fps, emotion=emotion)


def test_corpus_rejects_inconsistent_members() -> None:
    with pytest.raises(CorpusError, match="columns"):
        Corpus("c", 60.0, ("one",), [utterance("a")])
    with pytest.raises(CorpusError, match="fps"):
        Corpus("c", 30.0, CHANNELS, [utterance("a")])
    with pytest.raises(CorpusError, match="unique"):
        Corpus("c", 60.0, CHANNELS, [utterance("a"), utterance("a")])
    with pytest.raises(CorpusError, match="held-out"):
        Corpus("c", 60.0, CHANNELS, [utterance("a")], heldout=("b",))
