"""Errors that carry a stable code and say what went wrong and where.

Every user-facing failure in lipstream is a ``LipstreamError``. The ``code`` is
stable (clients and scripts switch on it); ``where`` names the file, line,
column or message field that was at fault.
"""

from __future__ import annotations

from collections.abc import Sequence


class LipstreamError(Exception):
    """A user-facing error with a stable code and a location."""

    code: str = "error"

    def __init__(self, message: str, *, where: str | None = None, code: str | None = None) -> None:
        self.message = message
        self.where = where
        if code is not None:
            self.code = code
        super().__init__(self.__str__())

    def __str__(self) -> str:
        location = f"{self.where}: " if self.where else ""
        return f"{location}{self.message} [{self.code}]"


class UnknownPhonemeError(LipstreamError):
    code = "unknown_phoneme"


class UnmappedPhonemeError(UnknownPhonemeError):
    """A phoneme of language ``lang`` that no table of the phoneme set reads."""

    code = "unmapped_phoneme"

    def __init__(self, message: str, *, phoneme: str, lang: str, where: str | None = None) -> None:
        self.phoneme = phoneme
        self.lang = lang
        super().__init__(message, where=where)


class CorpusError(LipstreamError):
    code = "corpus_invalid"


class CorpusProblems(CorpusError):
    """Several problems found in one corpus in one run: ``problems``, each a ``LipstreamError``
    with its own code and ``where`` (file:line); the message lists them one per line.
    ``more``: the search stopped at its limit, so there may be others."""

    def __init__(
        self, problems: Sequence[LipstreamError], *, where: str | None, more: bool = False
    ) -> None:
        self.problems = tuple(problems)
        self.more = more
        stopped = f", stopped at the first {len(self.problems)}" if more else ""
        listed = "".join(f"\n  {problem}" for problem in self.problems)
        super().__init__(f"{len(self.problems)} problems{stopped}:{listed}", where=where)


class ModelStoreError(LipstreamError):
    code = "model_invalid"


class ModelCostError(LipstreamError):
    """A model that loads but costs too much to serve: its calibration ran past its CPU
    bound, or a session on one of its rungs would need too much of a core."""

    code = "model_too_costly"


class UnknownEngineError(LipstreamError):
    code = "unknown_engine"


class InvalidRequestError(LipstreamError):
    code = "invalid_request"


class SpeechError(LipstreamError):
    code = "speech_failed"
