"""Cross-checks between a corpus's files, and the list of every problem found in one run.

Sketch: the readers reject malformed cells and rows themselves; these checks
cover what only shows once files are compared: phone intervals out of order,
phones running past the end of their frames, channel sets that differ
between utterances, and a ``corpus.json`` channel list naming channels the
frames do not have. Nothing is repaired. A check that finds several faults
(rows, cells, intervals) names each; ``Problems`` gathers them across files,
up to ``MAX_PROBLEMS``, so one run reports what a user must fix: one problem
raises its own ``CorpusError``, several a ``CorpusProblems`` listing each.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, ParamSpec, TypeVar

from ..errors import CorpusError, CorpusProblems, LipstreamError

if TYPE_CHECKING:
    from .intervals import LabelledInterval

MAX_PROBLEMS = 100
"""Problems one load reports at most (docs/reference/corpus-formats.md); then it stops looking."""

Arguments = ParamSpec("Arguments")
Result = TypeVar("Result")


class Problems:
    """Problems found so far, each a ``LipstreamError`` naming its file and line, in the
    order found, at most ``limit`` of them."""

    def __init__(self, limit: int = MAX_PROBLEMS) -> None:
        self.limit = limit
        self.found: list[LipstreamError] = []
        self.more = False

    @property
    def full(self) -> bool:
        return len(self.found) >= self.limit

    def add(self, error: LipstreamError) -> None:
        listed = error.problems if isinstance(error, CorpusProblems) else (error,)
        for problem in listed:
            if self.full:
                self.more = True
            else:
                self.found.append(problem)
        self.more = self.more or (isinstance(error, CorpusProblems) and error.more)

    def attempt(
        self,
        call: Callable[Arguments, Result],
        *args: Arguments.args,
        **kwargs: Arguments.kwargs,
    ) -> Result | None:
        """``call``'s result, or None with its ``LipstreamError`` added to the list."""
        try:
            return call(*args, **kwargs)
        except LipstreamError as error:
            self.add(error)
            return None

    def raise_any(self, where: str | None) -> None:
        """Raise what was found: one problem as itself, several as ``CorpusProblems``."""
        if len(self.found) == 1 and not self.more:
            raise self.found[0]
        if self.found:
            raise CorpusProblems(self.found, where=where, more=self.more)


def raise_each(problems: Sequence[LipstreamError], where: str | None) -> None:
    """Raise ``problems`` found in one file or check (nothing when there are none)."""
    found = Problems()
    for problem in problems:
        found.add(problem)
    found.raise_any(where)


def at_line(file_name: str, line: int) -> str:
    """The ``where`` of an error on a 1-based editor line: ``utt01.TextGrid:line 42``."""
    return f"{file_name}:line {line}"


def check_interval_order(intervals: Sequence[LabelledInterval]) -> None:
    """Intervals must be non-empty, start at or after 0, and follow each other without overlap;
    every interval that does not is named."""
    problems: list[LipstreamError] = []
    previous: LabelledInterval | None = None
    for interval in intervals:
        if interval.start < 0:
            problems.append(
                CorpusError(
                    f"interval starts at {interval.start:g} s, before 0",
                    where=interval.where_start,
                )
            )
        elif interval.end <= interval.start:
            problems.append(
                CorpusError(
                    f"interval ends at {interval.end:g} s, not after its start "
                    f"{interval.start:g} s",
                    where=interval.where_end,
                )
            )
        elif previous is not None and interval.start < previous.end:
            problems.append(
                CorpusError(
                    f"interval starts at {interval.start:g} s, before the previous interval "
                    f"(at {previous.where_start}) ends at {previous.end:g} s",
                    where=interval.where_start,
                )
            )
        previous = interval
    raise_each(problems, where=None)


def check_phones_within_frames(
    intervals: Sequence[LabelledInterval], frames_end: float, fps: float, frames_file: str
) -> None:
    """No interval may end more than one frame period after the last frame time; every one
    that does is named."""
    limit = frames_end + 1.0 / fps
    problems: list[LipstreamError] = [
        CorpusError(
            f"interval ends at {interval.end:g} s, more than one frame period "
            f"(1/{fps:g} s) past the end of the frames in {frames_file} at {frames_end:g} s",
            where=interval.where_end,
        )
        for interval in intervals
        if interval.end > limit + 1e-9
    ]
    raise_each(problems, where=None)


def check_same_channels(
    reference_file: str,
    reference: Sequence[str],
    other_file: str,
    other: Sequence[str],
) -> None:
    """Two utterances' frame files must carry the same set of channels."""
    reference_set, other_set = set(reference), set(other)
    only_reference = [name for name in reference if name not in other_set]
    only_other = [name for name in other if name not in reference_set]
    if only_reference or only_other:
        details = []
        if only_reference:
            details.append(f"only in {reference_file}: {', '.join(only_reference)}")
        if only_other:
            details.append(f"only in {other_file}: {', '.join(only_other)}")
        raise CorpusError(
            f"channels differ from {reference_file} ({'; '.join(details)})", where=other_file
        )


def check_channel_selection(selected: Sequence[str], available: Sequence[str], where: str) -> None:
    """Every channel named in ``corpus.json`` must exist in the frames."""
    available_set = set(available)
    unknown = [name for name in selected if name not in available_set]
    if unknown:
        raise CorpusError(
            f"unknown channels {', '.join(unknown)}; the frames have: {', '.join(available)}",
            where=where,
        )
