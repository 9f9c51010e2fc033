"""One connection's encoder of server messages, with direct paths for ``frames``.

Sketch: the SDK's ``codec.encode`` dispatches on the message type, builds the wire
map in two steps and packs it with ``msgpack.packb``, which makes a new ``Packer`` (and
its buffer) on every call; for a ``frames`` block that is most of the cost of
encoding. ``MessageEncoder`` keeps one ``Packer`` and packs a ``frames`` block's map
as the wire layer writes it (the same keys in the same order, so the same bytes:
the tests compare it with ``codec.encode``). In JSON the SDK writes each float32 as the
shortest decimal that reads back as the same float32, found by bisection over the digits
in Python, a few microseconds a value: a 1000 fps stream spent most of its server's CPU
there. ``json_rows`` writes the same text from numpy's shortest float32 repr
(``astype(str)``, in C), which equals Python's repr of that decimal except where numpy
writes an exponent Python would not (magnitudes from 1e6 up to 1e16); those few values take
Python's repr. Every other message goes through ``codec.encode``. A connection's messages
are encoded by one thread at a time (its event loop, or the pool job the connection is
waiting for), so each connection holds its own encoder and no lock is needed.
"""

from __future__ import annotations

import json
from typing import Any

import msgpack
import numpy as np

from lipstream_client import Encoding, Frames, ServerMessage, encode

JSON_SEPARATORS = (",", ":")
POSITIONAL_BELOW = 1e5  # numpy's float32 str stays positional below 1e6; kept clear of it


def json_rows(values: np.ndarray) -> str:
    """Float32 ``values`` (frames × channels) as JSON rows of the shortest decimals that read
    back as the same float32, joined by commas, without the enclosing list's brackets: the
    text ``json.dumps`` gives for the SDK's rows (``float32.shortest_float32``)."""
    texts = values.astype(str)
    for row, column in zip(*np.nonzero(np.abs(values) >= POSITIONAL_BELOW), strict=True):
        texts[row, column] = repr(float(texts[row, column]))
    return ",".join("[" + ",".join(row) + "]" for row in texts.tolist())


class MessageEncoder:
    """Encodes the server messages of one connection in its ``encoding``."""

    def __init__(self, encoding: Encoding) -> None:
        self.encoding = encoding
        self._packer = msgpack.Packer(use_bin_type=True) if encoding == "msgpack" else None

    def __call__(self, message: ServerMessage) -> bytes | str:
        packer = self._packer
        if packer is not None and type(message) is Frames:
            packed: bytes = packer.pack(frames_map(message, message.data))
            return packed
        if packer is None and type(message) is Frames and message.n_channels > 0:
            head = json.dumps(
                frames_map(message, []),
                ensure_ascii=False,
                allow_nan=False,
                separators=JSON_SEPARATORS,
            )
            values = np.frombuffer(message.data, "<f4").reshape(-1, message.n_channels)
            return head[: -len("]}")] + json_rows(values) + "]}"
        return encode(message, self.encoding, validate=False)


def frames_map(message: Frames, data: bytes | list[Any]) -> dict[str, Any]:
    """A ``frames`` block's wire map with ``data`` as given, in the wire layer's key order."""
    return {
        "v": message.v,
        "type": message.type,
        "id": message.id,
        "seq": message.seq,
        "first_frame": message.first_frame,
        "fps": message.fps,
        "n_channels": message.n_channels,
        "data": data,
    }
