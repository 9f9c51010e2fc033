"""``resume.seq`` near the protocol's bound, against a real server and the reference codec.

A ``resume.seq`` of 2^53 - 1 was accepted, and the server then numbered a
block 2^53, which the reference codec rejects. Now a ``seq`` past 2^31 - 1 is
refused by the schema (naming ``resume.seq``), one that leaves too little room
for the request's blocks is refused with ``resume_mismatch`` before ``ready``,
and a request resumed just within the bound streams blocks the codec accepts.
"""

from __future__ import annotations

import json
from pathlib import Path

from lipstream.config import ServerSettings
from lipstream_client import Done, End, ErrorMessage, Frames, PhonemeItem, Phonemes, Resume, Start
from lipstream_client.errors import RESUME_MISMATCH
from tests.lipstream.server.harness import client, serving

MAX_SEQ = 2**31 - 1  # stated independently of the codec's constant
MAX_FRAMES = 1000
# Blocks a request may send: one a frame up to the limit, one more for input ending on it,
# and an interrupt's return to rest of at most 10 s at 1000 fps, a block a row.
MOST_BLOCKS = MAX_FRAMES + 1 + 10_000 + 1
ITEMS = (PhonemeItem("HH", 0.0, 0.1), PhonemeItem("AY1", 0.1, 0.3), PhonemeItem("sil", 0.3, 0.5))


def start_json(seq: int) -> str:
    resume = {"frames": 0, "seq": seq}
    message = {"v": 1, "type": "start", "id": "a", "engine": "viseme-lerp", "character": "demo"}
    return json.dumps({**message, "resume": resume})


def test_resume_seq_is_bounded_by_the_schema_and_by_the_requests_room(lerp_dir: Path) -> None:
    settings = ServerSettings(max_request_frames=MAX_FRAMES)
    with serving(lerp_dir, settings) as served, client(served.ws, "json") as ws:
        for seq in (2**53 - 1, MAX_SEQ + 1):
            ws.send_raw(start_json(seq))
            error = ws.recv()  # the reference codec decodes every answer (harness)
            assert isinstance(error, ErrorMessage)
            assert (error.code, error.id) == ("invalid_message", "a")
            assert error.message.startswith("resume.seq: ")
            assert str(MAX_SEQ) in error.message
        for seq in (MAX_SEQ, MAX_SEQ + 2 - MOST_BLOCKS):
            ws.send_raw(start_json(seq))
            error = ws.recv()
            assert isinstance(error, ErrorMessage)
            assert (error.code, error.id, error.fatal) == (RESUME_MISMATCH, "a", True)
            assert error.message.startswith("resume.seq: ")
        last_fitting = MAX_SEQ + 1 - MOST_BLOCKS
        ws.send(Start("a", "viseme-lerp", "demo", resume=Resume(0, last_fitting)))
        ws.send(Phonemes("a", ITEMS), End("a"))
        answers = ws.until_done("a")
        assert isinstance(answers[-1], Done)
        seqs = [m.seq for m in answers if isinstance(m, Frames)]
        assert seqs == list(range(last_fitting, last_fitting + len(seqs)))
