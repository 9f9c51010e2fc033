"""Everything a session keeps for one active request, in one object.

Sketch: the ``ActiveRequest`` (the synthesis and its output) travels with what the
session adds around it: the engine's ``CallCost`` for the request's options, the
``WorkGuard`` that meters and cancels its engine work, the ``ResumeCursor`` of a
resumed request, the ``WordStream`` of a request fed a TTS's timings, the ``Holding``
that counts its audio input in the process's ledger, and the error its read-ahead
input earned (``too_large``, ended at its next message). The session keeps one
``RequestState`` per id, so forgetting a request is one ``pop`` and a ``release``.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..engines.base import CallCost
from ..engines.work import WorkGuard
from ..errors import LipstreamError
from ..frontends.word_stream import WordStream
from .held_input import Holding, InputLedger
from .request import ActiveRequest
from .resume import ResumeCursor


@dataclass
class RequestState:
    """One active request and the session's state about it."""

    active: ActiveRequest
    cost: CallCost
    guard: WorkGuard
    resume: ResumeCursor | None = None
    word_stream: WordStream | None = None
    holding: Holding | None = None
    too_large: LipstreamError | None = None

    def holding_in(self, ledger: InputLedger) -> Holding:
        """The request's holding in ``ledger``, opened at its first audio input."""
        if self.holding is None:
            self.holding = ledger.holding()
        return self.holding

    def words(self) -> WordStream:
        """The request's word stream, opened at its first ``words`` message."""
        if self.word_stream is None:
            self.word_stream = WordStream()
        return self.word_stream

    def release(self) -> None:
        """Give back the request's share of the input ledger (it has ended)."""
        if self.holding is not None:
            self.holding.release()
            self.holding = None
