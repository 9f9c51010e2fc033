"""GRID's sentence grammar (Cooke, Barker, Cunningham & Shao 2006): a clip's file name is
its six words, one character each: command, colour, preposition, letter, digit, adverb."""

from __future__ import annotations

COMMANDS = {"b": "bin", "l": "lay", "p": "place", "s": "set"}
COLOURS = {"b": "blue", "g": "green", "r": "red", "w": "white"}
PREPOSITIONS = {"a": "at", "b": "by", "i": "in", "w": "with"}
DIGITS = {
    "z": "zero",
    "0": "zero",
    "1": "one",
    "2": "two",
    "3": "three",
    "4": "four",
    "5": "five",
    "6": "six",
    "7": "seven",
    "8": "eight",
    "9": "nine",
}
ADVERBS = {"a": "again", "n": "now", "p": "please", "s": "soon"}


def grid_words(stem: str) -> list[str]:
    """The six words a GRID file name encodes (``swwp2s`` -> set white with p two soon)."""
    if len(stem) != 6:
        raise ValueError(f"a GRID name has six characters, not {stem!r}")
    command, colour, preposition, letter, digit, adverb = tuple(stem)
    return [
        COMMANDS[command],
        COLOURS[colour],
        PREPOSITIONS[preposition],
        letter,
        DIGITS[digit],
        ADVERBS[adverb],
    ]
