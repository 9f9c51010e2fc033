"""lipstream client SDK: the wire protocol (messages, codec, schemas) and clients; no numpy.

Sketch: ``messages`` holds one frozen dataclass per message of protocol
version 1, ``codec`` turns them into msgpack or JSON frame payloads and
back without I/O, ``errors`` lists every error and close code, and
``schema`` loads the JSON Schemas the codec enforces. ``client`` is the
asyncio client (``AsyncClient``, one ``Stream`` per request), ``sync`` its
blocking wrapper (``Client``), ``exceptions`` what they raise,
``frame_timeline`` assembles frames by index, ``items`` the phoneme shapes
the clients accept, and ``rest`` calls the HTTP endpoints with the standard
library.

Importing the package, ``messages`` or ``codec`` does no I/O and imports
neither ``websockets`` nor the asyncio client: the clients (``AsyncClient``,
``Client`` and their streams) are imported on first use, through the module
``__getattr__``, so a server can use the protocol core alone.
"""

from typing import TYPE_CHECKING, Any

from .channels import (
    OCULUS15_VISEMES,
    PRESTON_BLAIR_SHAPES,
    VISEME_CHANNELS,
    canonical_viseme,
    rename_channel,
)
from .codec import (
    DEFAULT_ENCODING,
    DEFAULT_MAX_SIZE,
    SUBPROTOCOL_JSON,
    SUBPROTOCOL_MSGPACK,
    SUBPROTOCOLS,
    decode,
    encode,
    encoding_for_subprotocol,
    select_subprotocol,
    subprotocol_for,
)
from .errors import (
    ERROR_CODES,
    RETRYABLE_CLOSE_CODES,
    CloseCode,
    EncodeError,
    ErrorCodeInfo,
    ProtocolError,
)
from .exceptions import (
    ConnectionClosed,
    HandshakeRejected,
    LipstreamClientError,
    LipstreamServerError,
    ProtocolViolation,
    ResumeFailed,
    ServerBusy,
    ServerGoingAway,
    retry_delay_s,
)
from .frame_timeline import FrameTimeline
from .messages import (
    PROTOCOL_VERSION,
    AudioChunk,
    Cancel,
    ChannelTransform,
    ClientMessage,
    Done,
    DoneStats,
    Encoding,
    End,
    ErrorMessage,
    Frames,
    Interrupt,
    Message,
    OutputProfile,
    PhonemeItem,
    Phonemes,
    Ready,
    Resume,
    ServerMessage,
    Start,
    Text,
    Words,
)
from .resume import ResumePolicy
from .schema import load_schema

if TYPE_CHECKING:
    from .client import AsyncClient, RequestOver, Stream, StreamResult
    from .sync import Client, SyncStream

_LAZY = {
    "AsyncClient": "client",
    "RequestOver": "client",
    "Stream": "client",
    "StreamResult": "client",
    "Client": "sync",
    "SyncStream": "sync",
}


def __getattr__(name: str) -> Any:
    """The clients, imported when first asked for (they need ``websockets``)."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from importlib import import_module

    value = getattr(import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


__all__ = [
    "DEFAULT_ENCODING",
    "DEFAULT_MAX_SIZE",
    "ERROR_CODES",
    "OCULUS15_VISEMES",
    "PRESTON_BLAIR_SHAPES",
    "VISEME_CHANNELS",
    "PROTOCOL_VERSION",
    "RETRYABLE_CLOSE_CODES",
    "SUBPROTOCOLS",
    "SUBPROTOCOL_JSON",
    "SUBPROTOCOL_MSGPACK",
    "AsyncClient",
    "AudioChunk",
    "Cancel",
    "ChannelTransform",
    "Client",
    "ClientMessage",
    "CloseCode",
    "ConnectionClosed",
    "Done",
    "DoneStats",
    "EncodeError",
    "Encoding",
    "End",
    "ErrorCodeInfo",
    "ErrorMessage",
    "FrameTimeline",
    "Frames",
    "HandshakeRejected",
    "Interrupt",
    "LipstreamClientError",
    "LipstreamServerError",
    "Message",
    "OutputProfile",
    "PhonemeItem",
    "Phonemes",
    "ProtocolError",
    "ProtocolViolation",
    "Ready",
    "RequestOver",
    "Resume",
    "ResumeFailed",
    "ResumePolicy",
    "ServerBusy",
    "ServerGoingAway",
    "ServerMessage",
    "Start",
    "Stream",
    "StreamResult",
    "SyncStream",
    "Text",
    "Words",
    "canonical_viseme",
    "decode",
    "encode",
    "encoding_for_subprotocol",
    "load_schema",
    "rename_channel",
    "retry_delay_s",
    "select_subprotocol",
    "subprotocol_for",
]
