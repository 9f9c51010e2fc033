"""Resuming a request that a lost connection cut off: send only the frames the client lacks.

Method: synthesis is deterministic and independent of how the input is
chunked, so a request started again with the same parameters and the same
input, on any worker or replica serving the same models, produces the same
frames; and espeak-ng speaks a ``text`` the same way every time (the same
voice, rate and text give the same samples and phoneme spans), so a request
that sent ``text`` speaks the same ``audio`` chunks. A resuming client sends
``start`` with ``resume`` (the frames, ``frames`` blocks and ``audio``
chunks it already holds, and the fidelity rung the first ``ready`` named),
then the request's whole input again. The server runs the request
from the beginning, on that rung rather than the one its own calibration
would choose for the budget (``pinned_rung``), and passes its output through
a ``ResumeCursor``: rows before ``resume.frames`` are dropped, blocks that
keep rows are numbered on from ``resume.seq`` (an interrupt's return to
rest supersedes frames and goes out whole), the first ``resume.audio``
``audio`` messages are dropped, and every other message (``ready``,
``done``, errors) goes out unchanged. The client thus receives every frame
and speech chunk once, in order, as an uninterrupted connection would have sent
them. Re-synthesizing the beginning costs the engine's time for input that
is already bounded by the request limits.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

from lipstream_client import AudioChunk, Frames, Resume
from lipstream_client.errors import RESUME_MISMATCH
from lipstream_client.float32 import FLOAT32_BYTES
from lipstream_client.messages import MAX_SEQ

from ..errors import LipstreamError
from .budget import CUSTOM_FIDELITY, RungEstimate
from .outgoing import Outgoing


class ResumeMismatch(LipstreamError):
    """The resumed request cannot reproduce the frames the client holds."""

    code = RESUME_MISMATCH


def pinned_rung(ladder: Sequence[RungEstimate], resume: Resume | None) -> RungEstimate | None:
    """The rung a resumed request keeps: the one its first ``ready`` named; None when the
    request is not resumed or named no rung of the ladder (``custom``: its options decide).
    ``ResumeMismatch`` when the engine here has no rung of that name."""
    if resume is None or resume.fidelity is None or resume.fidelity == CUSTOM_FIDELITY:
        return None
    for estimate in ladder:
        if estimate.rung.name == resume.fidelity:
            return estimate
    names = ", ".join(estimate.rung.name for estimate in ladder)
    raise ResumeMismatch(
        f"this server's model has no fidelity rung {resume.fidelity!r} (it has {names}), "
        f"so it cannot continue the request's frames; start the request anew",
        where="resume.fidelity",
    )


def check_seq_room(resume: Resume | None, most_blocks: int) -> None:
    """``ResumeMismatch`` when a request that may send ``most_blocks`` blocks, numbered from
    ``resume.seq``, could need a ``seq`` past ``MAX_SEQ``, the protocol's bound."""
    if resume is None or resume.seq + most_blocks - 1 <= MAX_SEQ:
        return
    raise ResumeMismatch(
        f"{resume.seq} leaves no room to number the up to {most_blocks} frames blocks this "
        f"request may send within the protocol's bound of {MAX_SEQ}; start the request anew",
        where="resume.seq",
    )


@dataclass
class ResumeCursor:
    """The frames a resumed request has still to send: from ``frames`` on, blocks from
    ``seq``, and its speech from ``audio`` message on. A block that starts before the end
    of the one before it (an interrupt's return to rest, which supersedes frames) goes out
    whole."""

    frames: int
    seq: int
    audio: int = 0
    produced: int = 0

    @classmethod
    def of(cls, resume: Resume) -> ResumeCursor:
        return cls(resume.frames, resume.seq, resume.audio)

    def filter(self, outgoing: list[Outgoing]) -> list[Outgoing]:
        """``outgoing`` without the rows and speech chunks the client holds, blocks
        renumbered."""
        kept: list[Outgoing] = []
        for item in outgoing:
            message = item.message
            if isinstance(message, AudioChunk) and self.audio > 0:
                self.audio -= 1
                continue
            if not isinstance(message, Frames):
                kept.append(item)
                continue
            block = self._unsent(message)
            if block is not None:
                kept.append(replace(item, message=block))
        return kept

    def _unsent(self, block: Frames) -> Frames | None:
        superseding = block.first_frame < self.produced  # an interrupt's return to rest
        self.produced = block.end_frame
        held = 0 if superseding else max(0, min(self.frames, block.end_frame) - block.first_frame)
        if held == block.n_frames:
            return None
        if self.seq > MAX_SEQ:
            raise ResumeMismatch(
                f"the request's next frames block would be numbered past the protocol's bound "
                f"of {MAX_SEQ}",
                where="resume.seq",
            )
        data = block.data[held * block.n_channels * FLOAT32_BYTES :]
        unsent = replace(block, seq=self.seq, first_frame=block.first_frame + held, data=data)
        self.seq += 1
        return unsent
