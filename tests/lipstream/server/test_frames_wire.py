"""The connection's encoder gives the bytes the SDK's codec gives, for every message."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.server.frames_wire import MessageEncoder, json_rows
from lipstream_client import (
    Done,
    DoneStats,
    Encoding,
    ErrorMessage,
    Frames,
    Ready,
    ServerMessage,
    decode,
    encode,
)


def _frames(rows: int, width: int, seed: int, identifier: str = "req-1") -> Frames:
    values = np.random.default_rng(seed).normal(size=(rows, width)).astype("<f4")
    return Frames(identifier, seed, 7 * seed, 59.94, width, values.tobytes())


@pytest.mark.parametrize("encoding", ["msgpack", "json"])
def test_frames_blocks_encode_to_the_codecs_bytes(encoding: Encoding) -> None:
    encoder = MessageEncoder(encoding)
    blocks = [
        _frames(0, 28, 0),
        _frames(1, 28, 1),
        _frames(5, 52, 2, "é-unicode-id"),
        _frames(600, 28, 3, "x" * 128),  # data past 65535 bytes: a bin32 header
        Frames("r", 2**40, 2**33, 30.0, 3, b""),
        Frames("r", 1, 2, 60, 1, np.float32(0.5).tobytes()),  # an int fps, as a client sent it
    ]
    for block in blocks:
        assert encoder(block) == encode(block, encoding, validate=False)
    for block in blocks[1:4]:  # the valid ones (no rows, or such a seq, the protocol refuses)
        assert decode(encoder(block), encoding) == block


def test_one_encoder_packs_block_after_block_without_carrying_bytes_over() -> None:
    encoder = MessageEncoder("msgpack")
    first = encoder(_frames(3, 28, 4))
    assert encoder(_frames(2, 28, 5)) == encode(_frames(2, 28, 5), "msgpack", validate=False)
    assert encoder(_frames(3, 28, 4)) == first


@pytest.mark.parametrize("encoding", ["msgpack", "json"])
def test_other_messages_go_through_the_codec(encoding: Encoding) -> None:
    encoder = MessageEncoder(encoding)
    messages: list[ServerMessage] = [
        Ready("r", "viseme-lerp", "demo", 60.0, ("jawOpen",), 0.0, "causal"),
        Done("r", DoneStats(frames=12), "end"),
        ErrorMessage("unknown_request", "no such request", "r", False),
    ]
    for message in messages:
        assert encoder(message) == encode(message, encoding, validate=False)


def test_json_rows_write_the_codecs_decimals_for_every_magnitude() -> None:
    """numpy writes an exponent from 1e6 up, Python's repr only from 1e16: the encoder must
    give the codec's text for both, and for the subnormal, tiny and signed-zero values."""
    rng = np.random.default_rng(7)
    bits = rng.integers(0, 2**32, 3000, dtype=np.uint64).astype(np.uint32).view(np.float32)
    special = np.array(
        [
            0.0,
            -0.0,
            1.0,
            0.1,
            999999.94,
            1e6,
            2.7811605e6,
            1e8,
            1e15,
            1e16,
            3.4e38,
            1e-4,
            1e-5,
            1.4e-45,
            -123456.79,
            16777216.0,
        ],
        dtype=np.float32,
    )
    values = np.concatenate([bits[np.isfinite(bits)][:2990], special])
    values = values[: len(values) // 6 * 6].reshape(-1, 6).astype("<f4")
    block = Frames("r", 1, 0, 60.0, 6, values.tobytes())
    assert MessageEncoder("json")(block) == encode(block, "json", validate=False)
    assert json_rows(values) == encode(block, "json", validate=False).split('"data":[', 1)[1][:-2]
