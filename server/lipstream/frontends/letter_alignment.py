"""A word's letters aligned to its phonemes, and the phoneme onsets its character times give.

Method: a monotonic alignment by dynamic programming, as many-to-many grapheme-phoneme
aligners do (Jiampojamarn et al. 2007), scored by a table of English spelling-sound
correspondences instead of learned probabilities. Each step takes a group of one to three
letters with one or two phonemes; a group and phonemes the table lists (``ph`` → F,
``igh`` → AY, ``x`` → K S) score ``TABLE_SCORE``, one letter with one phoneme not listed
scores by class alone (a vowel letter with a vowel, a consonant with a consonant, or
neither), a silent letter and a phoneme spelt by no letter cost a penalty, and a
character that is not a letter (an apostrophe) is silent for free. The best path splits
the word into groups of letters and phonemes. A silent letter is taken as the tail of
the group before it (a TTS's aligner gives it part of that sound's time) and, at the
start of a word, as the head of the first. Where a group came from the table, the
alignment is confident and its first phoneme starts when the group's first character
starts; every other phoneme is left to the duration model (``spreading``), which shares
the time between two anchors. An anchor out of order, or too close to the previous one
to give each phoneme between them time, is dropped.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache

from ..phonemes import PHONEME_INDEX, SILENCE
from .timings import TimedCharacter
from .word_durations import CLASSES, PHONEME_CLASS

Group = tuple[str, tuple[str, ...]]
TABLE_SCORE = 2.0
SAME_CLASS_SCORE = -0.5
OTHER_CLASS_SCORE = -2.5
SILENT_LETTER_COST = 1.0
UNSPELT_PHONEME_COST = 3.0
MAX_GROUP_LETTERS = 3
MIN_ANCHOR_GAP_S = 0.004
"""Each phoneme between two anchors gets at least this much time, or the later anchor goes."""
VOWEL_LETTERS = "aeiouy"

SPELLINGS = """
a AE EY AA AH AO EH IH ER
e EH IY IH AH ER EY
i IH AY IY AH ER Y
o AA OW AO AH UW UH ER W+AH
u AH UW UH Y+UW ER IH W
y IY IH AY Y
ai EY EH
ay EY
au AO AA
aw AO AA
ea IY EH EY
ee IY
ei EY IY AY
ey EY IY
eu UW Y+UW
ew UW Y+UW
ie IY AY
oa OW
oe OW
oi OY
oy OY
oo UW UH AH
ou AW UW AH OW AO UH
ow OW AW
ue UW
ui UW IH
igh AY
ar AA+R ER
er ER
ir ER
ur ER
or ER AO+R
ear ER IH+R
our AW+ER AO+R
re ER
b B
bb B
c K S CH SH
cc K
ch CH K SH
ck K
d D T JH
dd D
dg JH
f F
ff F
g G JH ZH
gg G
gh G F
gn N
h HH
j JH
k K
kn N
l L AH+L
le AH+L
ll L
m M AH+M
mb M
mm M
n N NG AH+N
ng NG
nk NG+K
nn N
p P
ph F
pp P
q K
qu K+W
r R ER
rr R
s S Z SH ZH
sh SH
ss S
t T SH CH D
tch CH
th TH DH
ti SH
tt T
v V
w W
wh W HH
wr R
x K+S G+Z Z
z Z
zz Z
"""
"""Letter groups, each with the phonemes (``+`` joins two) it commonly spells in English."""


@cache
def _table() -> dict[tuple[str, tuple[str, ...]], float]:
    return {
        (letters, tuple(option.split("+"))): TABLE_SCORE
        for letters, *options in (line.split() for line in SPELLINGS.strip().splitlines())
        for option in options
    }


def _class_score(letter: str, phoneme: str) -> float:
    vowel_phoneme = PHONEME_CLASS[PHONEME_INDEX[phoneme]] == CLASSES.index("vowel")
    return SAME_CLASS_SCORE if (letter in VOWEL_LETTERS) == vowel_phoneme else OTHER_CLASS_SCORE


def align_letters(letters: str, phonemes: Sequence[str]) -> list[tuple[int, int, bool]]:
    """The best monotonic alignment of ``letters`` (a written word, any case) to
    ``phonemes``: per phoneme group, (first letter index, first phoneme index,
    confident), in order; silent letters belong to no group."""
    word = letters.lower()
    n, m = len(word), len(phonemes)
    table = _table()
    worst = float("-inf")
    best = [[worst] * (m + 1) for _ in range(n + 1)]
    back: list[list[tuple[int, int, bool] | None]] = [[None] * (m + 1) for _ in range(n + 1)]
    best[0][0] = 0.0
    for i in range(n + 1):
        for j in range(m + 1):
            here = best[i][j]
            if here == worst:
                continue
            steps: list[tuple[int, int, float, bool]] = []
            if i < n:
                free = not word[i].isalpha()
                steps.append((1, 0, 0.0 if free else -SILENT_LETTER_COST, False))
            if j < m:
                steps.append((0, 1, -UNSPELT_PHONEME_COST, False))
            for size in range(1, MAX_GROUP_LETTERS + 1):
                group = word[i : i + size]
                if len(group) < size or not group.isalpha():
                    break
                for count in (1, 2):
                    spelt = tuple(phonemes[j : j + count])
                    if len(spelt) < count:
                        break
                    score = table.get((group, spelt))
                    if score is not None:
                        steps.append((size, count, score, True))
                    elif size == 1 and count == 1:
                        steps.append((1, 1, _class_score(group, spelt[0]), False))
            for size, count, score, confident in steps:
                if here + score > best[i + size][j + count]:
                    best[i + size][j + count] = here + score
                    back[i + size][j + count] = (size, count, confident)
    groups: list[tuple[int, int, bool]] = []
    i, j = n, m
    while i or j:
        step = back[i][j]
        assert step is not None
        size, count, confident = step
        i, j = i - size, j - count
        if size and count:
            groups.append((i, j, confident))
    return groups[::-1]


def letter_onsets(
    characters: Sequence[TimedCharacter], phonemes: Sequence[str]
) -> tuple[float | None, ...]:
    """Each phoneme's onset from its letters' times where the alignment is confident,
    None where the duration model places it; () when there is nothing to anchor."""
    if len(characters) < 2 or len(phonemes) < 2 or SILENCE in phonemes:
        return ()
    word = "".join(character.char for character in characters)
    groups = align_letters(word, phonemes)
    onsets: list[float | None] = [None] * len(phonemes)
    onsets[0] = characters[0].start
    last_anchor, last_index = characters[0].start, 0
    end = characters[-1].end
    for first_letter, first_phoneme, confident in groups[1:]:
        if not confident:
            continue
        onset = characters[first_letter].start
        before = MIN_ANCHOR_GAP_S * (first_phoneme - last_index)
        after = MIN_ANCHOR_GAP_S * (len(phonemes) - first_phoneme)
        if onset - last_anchor >= before and end - onset >= after:
            onsets[first_phoneme] = onset
            last_anchor, last_index = onset, first_phoneme
    return tuple(onsets) if any(onset is not None for onset in onsets[1:]) else ()
