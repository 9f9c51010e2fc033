"""One connection's encoder of server messages, with a direct path for msgpack ``frames``.

Sketch: the SDK's ``codec.encode`` dispatches on the message type, builds the wire
map in two steps and packs it with ``msgpack.packb``, which makes a new ``Packer`` (and
its buffer) on every call; for a ``frames`` block that is most of the cost of
encoding. ``MessageEncoder`` keeps one ``Packer`` and packs a ``frames`` block's map
as the wire layer writes it (the same keys in the same order, so the same bytes:
the tests compare it with ``codec.encode``); every other message, and every message
in JSON, goes through ``codec.encode``. A connection's messages are encoded by one
thread at a time (its event loop, or the pool job the connection is waiting for), so
each connection holds its own encoder and no lock is needed.
"""

from __future__ import annotations

import msgpack

from lipstream_client import Encoding, Frames, ServerMessage, encode


class MessageEncoder:
    """Encodes the server messages of one connection in its ``encoding``."""

    def __init__(self, encoding: Encoding) -> None:
        self.encoding = encoding
        self._packer = msgpack.Packer(use_bin_type=True) if encoding == "msgpack" else None

    def __call__(self, message: ServerMessage) -> bytes | str:
        packer = self._packer
        if packer is not None and type(message) is Frames:
            packed: bytes = packer.pack(
                {
                    "v": message.v,
                    "type": message.type,
                    "id": message.id,
                    "seq": message.seq,
                    "first_frame": message.first_frame,
                    "fps": message.fps,
                    "n_channels": message.n_channels,
                    "data": message.data,
                }
            )
            return packed
        return encode(message, self.encoding, validate=False)
