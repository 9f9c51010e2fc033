"""Suffix-automaton index over the corpus phoneme strings.

Sketch: the recordings' label strings are joined into one text
T = s_0 # s_1 # ... # s_n (``#`` never occurs in a query, so no match spans
two recordings) and its suffix automaton is built online (Blumer et al.
1985). Reading a query from the root follows one transition per phoneme, so
the longest corpus substring starting at query position i is found in
O(match length) lookups, whatever the corpus size. Every automaton state is
a set of substrings sharing their end positions; those end positions are the
state's subtree in the suffix-link tree, laid out contiguously by one
depth-first walk, so a match's occurrences are one slice ``ends[low:high]``.
The compiled search (``suffix_search``) reads these arrays itself; the same reads in
numpy are the tests' oracle (``tests/lipstream/engines/anime_graph/reference.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SuffixIndex:
    """``transitions`` (n_states, alphabet + 1) int32 (-1: none; the last column is the
    separator); state v's occurrences end at ``ends[low[v]:high[v]]``, text positions;
    ``text_anime`` (len(T),) maps a text position to its anime (-1 at separators)."""

    transitions: np.ndarray
    low: np.ndarray
    high: np.ndarray
    ends: np.ndarray
    text_anime: np.ndarray

    @classmethod
    def build(
        cls,
        labels: np.ndarray,
        utterance: np.ndarray,
        alphabet: int,
        members: np.ndarray | None = None,
    ) -> SuffixIndex:
        """Index the animes ``members`` (ascending ids; default all) with ``labels`` (n,) in
        [0, alphabet), grouped by ``utterance`` (n,)."""
        chosen = np.arange(len(labels)) if members is None else np.asarray(members)
        text, text_anime = join_text(
            np.asarray(labels)[chosen], np.asarray(utterance)[chosen], chosen, alphabet
        )
        automaton = _Automaton()
        for position, symbol in enumerate(text.tolist()):
            automaton.extend(symbol, position)
        low, high, ends = automaton.end_position_ranges()
        return cls(automaton.dense(alphabet + 1), low, high, ends, text_anime)

    @property
    def n_states(self) -> int:
        return int(self.transitions.shape[0])


def join_text(
    labels: np.ndarray, utterance: np.ndarray, animes: np.ndarray, alphabet: int
) -> tuple[np.ndarray, np.ndarray]:
    """The text T of ``animes`` with ``labels`` and ``utterance`` (n,), the symbol
    ``alphabet`` separating recordings: (T int64, the anime at each position int32, -1 at
    separators)."""
    owners = np.asarray(utterance)
    count = len(owners)
    starts = np.flatnonzero(owners[1:] != owners[:-1]) + 1
    positions = np.arange(count) + np.searchsorted(starts, np.arange(count), side="right")
    text = np.full(count + len(starts), alphabet, dtype=np.int64)
    text[positions] = labels
    text_anime = np.full(count + len(starts), -1, dtype=np.int32)
    text_anime[positions] = animes
    return text, text_anime


class _Automaton:
    """Online suffix automaton construction with dictionary transitions."""

    def __init__(self) -> None:
        self.link = [-1]
        self.length = [0]
        self.moves: list[dict[int, int]] = [{}]
        self.first_end = [-1]
        self.is_clone = [False]
        self.last = 0

    def _new_state(self, length: int, moves: dict[int, int], first_end: int, clone: bool) -> int:
        self.link.append(-1)
        self.length.append(length)
        self.moves.append(moves)
        self.first_end.append(first_end)
        self.is_clone.append(clone)
        return len(self.length) - 1

    def extend(self, symbol: int, position: int) -> None:
        current = self._new_state(self.length[self.last] + 1, {}, position, False)
        state = self.last
        while state != -1 and symbol not in self.moves[state]:
            self.moves[state][symbol] = current
            state = self.link[state]
        if state == -1:
            self.link[current] = 0
        else:
            target = self.moves[state][symbol]
            if self.length[state] + 1 == self.length[target]:
                self.link[current] = target
            else:
                clone = self._new_state(
                    self.length[state] + 1, dict(self.moves[target]), self.first_end[target], True
                )
                self.link[clone] = self.link[target]
                while state != -1 and self.moves[state].get(symbol) == target:
                    self.moves[state][symbol] = clone
                    state = self.link[state]
                self.link[target] = self.link[current] = clone
        self.last = current

    def dense(self, width: int) -> np.ndarray:
        table = np.full((len(self.moves), width), -1, dtype=np.int32)
        for state, moves in enumerate(self.moves):
            if moves:
                table[state, list(moves)] = list(moves.values())
        return table

    def end_position_ranges(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Preorder walk of the suffix-link tree: (low, high, ends)."""
        n_states = len(self.length)
        children: list[list[int]] = [[] for _ in range(n_states)]
        for state in range(1, n_states):
            children[self.link[state]].append(state)
        low = np.zeros(n_states, dtype=np.int32)
        high = np.zeros(n_states, dtype=np.int32)
        ends: list[int] = []
        stack: list[tuple[int, bool]] = [(0, False)]
        while stack:
            state, done = stack.pop()
            if done:
                high[state] = len(ends)
                continue
            low[state] = len(ends)
            if state != 0 and not self.is_clone[state]:
                ends.append(self.first_end[state])
            stack.append((state, True))
            stack.extend((child, False) for child in reversed(children[state]))
        return low, high, np.asarray(ends, dtype=np.int32)
