"""TTS-shaped timing inputs built from espeak-ng's own speech, and how far phonemes derived
from them land from the phonemes espeak-ng really spoke.

Sketch: espeak-ng's word and phoneme events on its own speech are the truth
(``speech.spoken_words``). From them this module writes what each TTS would have sent
for that speech, in that TTS's own shape and units: a generic word list (seconds),
ElevenLabs' character alignment (each character timed by the phonemes it spells, as a
character aligner would: ``character_times``; spaces over the pauses; rounded to the
millisecond), Azure's word boundary events (100-ns
ticks, punctuation as its own boundary) and viseme events, Polly's speech marks (word
marks with byte offsets, viseme marks, ms) and Cartesia's IPA phoneme timestamps.
``onset_errors`` aligns each word's derived phonemes with its true ones (edit distance,
a substitution costing as much as a deletion plus an insertion, so only equal labels
pair) and gives the onset error of every pair, in seconds. Used by the tests and by
``bench.word_timings``; never by the runtime.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from ..phonemes import SILENCE
from ..speech.spoken_words import SpokenUtterance, SpokenWord
from ..tables import pairs
from ..timeline import PhonemeSpan

PUNCTUATION = ".,;:!?\"'()"
TICKS_PER_S = 10_000_000
_AZURE_VISEME_IDS = pairs("""
    AE 1  AH 1  AA 2  AO 3  EH 4  UH 4  EY 4  ER 5  Y 6  IY 6
    IH 6  W 7  UW 7  OW 8  AW 9  OY 10  AY 11  HH 12  R 13
    L 14  S 15  Z 15  SH 16  CH 16  JH 16  ZH 16  TH 17  DH 17
    F 18  V 18  D 19  T 19  N 19  K 20  G 20  NG 20  P 21
    B 21  M 21  sil 0
""")
AZURE_VISEME_OF: dict[str, int] = {p: int(viseme) for p, viseme in _AZURE_VISEME_IDS.items()}
POLLY_VISEME_OF: dict[str, str] = pairs("""
    P p  B p  M p  F f  V f  TH T  DH T  T t
    D t  N t  L t  K k  G k  NG k  HH k  S s
    Z s  SH S  ZH S  CH S  JH S  R r  IY i  IH i
    Y i  UW u  UH u  W u  AH @  AA a  AE a  AY a
    AW a  EY e  EH e  ER E  OW o  AO O  OY O
    sil sil
""")
VOWEL_PHONEMES = frozenset("AA AE AH AO AW AY EH ER EY IH IY OW OY UH UW".split())
IPA_OF: dict[str, str] = pairs("""
    AA ɑ  AE æ  AH ʌ  AO ɔ  AW aʊ  AY aɪ  B b  CH tʃ
    D d  DH ð  EH ɛ  ER ɝ  EY eɪ  F f  G ɡ  HH h
    IH ɪ  IY i  JH dʒ  K k  L l  M m  N n  NG ŋ
    OW oʊ  OY ɔɪ  P p  R ɹ  S s  SH ʃ  T t  TH θ
    UH ʊ  UW u  V v  W w  Y j  Z z  ZH ʒ
""")


def _ms(seconds: float) -> float:
    return round(seconds, 3)


def words_input(utterance: SpokenUtterance) -> list[dict[str, Any]]:
    return [
        {"word": word.text, "start": _ms(word.start), "end": _ms(word.end)}
        for word in utterance.words
    ]


def elevenlabs_input(utterance: SpokenUtterance, grid_s: float = 0.001) -> dict[str, Any]:
    """``grid_s``: the step every time is rounded to (1 ms, as ElevenLabs writes them; a
    coarser one mimics an aligner that works in audio frames)."""

    def _ms(seconds: float) -> float:
        return round(round(seconds / grid_s) * grid_s, 3)

    characters: list[str] = []
    starts: list[float] = []
    ends: list[float] = []
    for index, word in enumerate(utterance.words):
        if index:
            characters.append(" ")
            starts.append(_ms(ends[-1]))
            ends.append(_ms(word.start))
        for char, start, end in character_times(word):
            characters.append(char)
            starts.append(_ms(start))
            ends.append(_ms(end))
    alignment = {
        "characters": characters,
        "character_start_times_seconds": starts,
        "character_end_times_seconds": ends,
    }
    return {"audio_base64": "", "alignment": alignment, "normalized_alignment": alignment}


def character_times(word: SpokenWord) -> list[tuple[str, float, float]]:
    """Each character of ``word`` timed by the true phonemes it spells, as a character
    aligner would time it: letters and phonemes aligned by class alone (``_class_groups``),
    the letters of a group sharing its phonemes' time evenly."""
    phonemes = word.phonemes
    timed: list[tuple[str, float, float]] = []
    for letters, (first, last) in _class_groups(word.text, [p.phoneme for p in phonemes]):
        start, end = phonemes[first].start, phonemes[last - 1].end
        step = (end - start) / len(letters)
        timed += [(c, start + k * step, start + (k + 1) * step) for k, c in enumerate(letters)]
    return timed


def _class_groups(text: str, phonemes: Sequence[str]) -> list[tuple[str, tuple[int, int]]]:
    """``text`` cut into letter runs, each with the run of ``phonemes`` [first, last) it
    spells: a monotonic alignment scoring a vowel letter with a vowel phoneme and a
    consonant letter with a consonant +1, across classes -1, a letter left silent -0.4 (a
    character that is no letter is always silent, at no cost) and a phoneme no letter
    spells -0.6. Knowing no spelling, it is independent of the runtime's
    ``letter_alignment``. A silent letter or unspelt phoneme joins the run before it (the
    first run, at the word's start)."""
    n, m = len(text), len(phonemes)
    best = [[float("-inf")] * (m + 1) for _ in range(n + 1)]
    back: dict[tuple[int, int], tuple[int, int]] = {}
    best[0][0] = 0.0
    for i in range(n + 1):
        for j in range(m + 1):
            for di, dj in ((1, 1), (1, 0), (0, 1)):
                if i < di or j < dj or best[i - di][j - dj] == float("-inf"):
                    continue
                if di and dj and not text[i - 1].isalpha():
                    continue
                if di and dj:
                    vowel = text[i - 1].lower() in "aeiouy"
                    score = 1.0 if vowel == (phonemes[j - 1] in VOWEL_PHONEMES) else -1.0
                elif di:
                    score = -0.4 if text[i - 1].isalpha() else 0.0
                else:
                    score = -0.6
                if best[i - di][j - dj] + score > best[i][j]:
                    best[i][j] = best[i - di][j - dj] + score
                    back[(i, j)] = (di, dj)
    steps: list[tuple[int, int]] = []
    i, j = n, m
    while i or j:
        di, dj = back[(i, j)]
        steps.append((di, dj))
        i, j = i - di, j - dj
    runs: list[list[Any]] = []  # [letters, first phoneme, last phoneme]
    i = j = 0
    for di, dj in reversed(steps):
        if di and dj or not runs:
            runs.append(["", j, j])
        runs[-1][0] += text[i : i + di]
        runs[-1][2] = j + dj
        i, j = i + di, j + dj
    while len(runs) > 1 and not (runs[0][0] and runs[0][2] > runs[0][1]):
        head = runs.pop(0)  # silent letters or unspelt phonemes at the start
        runs[0] = [head[0] + runs[0][0], head[1], runs[0][2]]
    return [(letters, (first, last)) for letters, first, last in runs]


def azure_input(utterance: SpokenUtterance, *, visemes: bool = True) -> list[dict[str, Any]]:
    events: list[dict[str, Any]] = []
    offset = 0
    for word in utterance.words:
        bare = word.text.strip(PUNCTUATION) or word.text
        start = round(word.start * TICKS_PER_S)
        events.append(
            {
                "audioOffset": start,
                "duration": round(word.end * TICKS_PER_S) - start,
                "text": bare,
                "textOffset": utterance.text.index(bare, offset),
                "wordLength": len(bare),
                "boundaryType": "WordBoundary",
            }
        )
        offset = events[-1]["textOffset"] + len(bare)
        if bare != word.text and word.text[-1] in PUNCTUATION:
            events.append(
                {
                    "audioOffset": round(word.end * TICKS_PER_S),
                    "duration": 0,
                    "text": word.text[-1],
                    "textOffset": offset,
                    "wordLength": 1,
                    "boundaryType": "PunctuationBoundary",
                }
            )
    if visemes:
        events += azure_visemes(utterance)
    return events


def azure_visemes(utterance: SpokenUtterance) -> list[dict[str, Any]]:
    return [
        {"audioOffset": round(span.start * TICKS_PER_S), "visemeId": AZURE_VISEME_OF[span.phoneme]}
        for span in utterance.spans
    ]


def polly_input(utterance: SpokenUtterance, *, words: bool = True) -> str:
    marks: list[dict[str, Any]] = []
    encoded_offset = 0
    text = utterance.text
    if words:
        for word in utterance.words:
            bare = word.text.strip(PUNCTUATION) or word.text
            at = text.index(bare, encoded_offset)
            first = len(text[:at].encode("utf-8"))
            marks.append(
                {
                    "time": round(word.start * 1000),
                    "type": "word",
                    "start": first,
                    "end": first + len(bare.encode("utf-8")),
                    "value": bare,
                }
            )
            encoded_offset = at + len(bare)
    for span in utterance.spans:
        viseme = POLLY_VISEME_OF[span.phoneme]
        marks.append({"time": round(span.start * 1000), "type": "viseme", "value": viseme})
    marks.sort(key=lambda mark: (mark["time"], mark["type"] != "word"))
    import json

    return "\n".join(json.dumps(mark) for mark in marks) + "\n"


def ipa_input(utterance: SpokenUtterance) -> dict[str, Any]:
    spoken = [span for span in utterance.spans if span.phoneme != SILENCE]
    return {
        "phonemes": [IPA_OF[span.phoneme] for span in spoken],
        "start": [_ms(span.start) for span in spoken],
        "end": [_ms(span.end) for span in spoken],
    }


def onset_errors(
    words: Sequence[SpokenWord], derived: Sequence[PhonemeSpan], *, inner: bool = False
) -> list[float]:
    """|derived onset - true onset| (s) of every phoneme pair matched within each word;
    ``inner``: only phonemes after a word's first (whose onset word timings give)."""
    errors: list[float] = []
    spoken = [span for span in derived if span.phoneme != SILENCE]
    for index, word in enumerate(words):
        until = words[index + 1].start if index + 1 < len(words) else float("inf")
        mine = [span for span in spoken if word.start - 1e-6 <= span.start < until - 1e-6]
        for true, guess in _matched(list(word.phonemes), mine):
            if not inner or true is not word.phonemes[0]:
                errors.append(abs(true.start - guess.start))
    return errors


def _matched(
    truth: list[PhonemeSpan], guess: list[PhonemeSpan]
) -> list[tuple[PhonemeSpan, PhonemeSpan]]:
    n, m = len(truth), len(guess)
    cost = [[0] * (m + 1) for _ in range(n + 1)]
    for i in range(n + 1):
        for j in range(m + 1):
            if i == 0 or j == 0:
                cost[i][j] = i + j
                continue
            same = truth[i - 1].phoneme == guess[j - 1].phoneme
            diagonal = cost[i - 1][j - 1] if same else cost[i - 1][j - 1] + 2
            cost[i][j] = min(diagonal, cost[i - 1][j] + 1, cost[i][j - 1] + 1)
    pairs = []
    i, j = n, m
    while i > 0 and j > 0:
        same = truth[i - 1].phoneme == guess[j - 1].phoneme
        if same and cost[i][j] == cost[i - 1][j - 1]:
            pairs.append((truth[i - 1], guess[j - 1]))
            i, j = i - 1, j - 1
        elif cost[i][j] == cost[i - 1][j] + 1:
            i -= 1
        else:
            j -= 1
    return pairs[::-1]
