"""A connected UDP socket that sends datagrams to one receiver and counts what bounced.

Sketch: UDP is fire-and-forget, so a receiver that is not (or no longer) listening
does not stop the sender. On a connected UDP socket the kernel reports the ICMP
"port unreachable" a receiver's host sends back as ``ECONNREFUSED`` on a later
``send``; ``UdpSender`` counts those (``refused``) and any other send failure
(``failed``, e.g. no route for a moment) and carries on. Resolving the host, binding
the local address and connecting happen once, in the constructor, and fail there with
a coded ``BridgeError``: ``target_unreachable`` (no such host, no route) or
``port_in_use`` (the local address to send from is taken).
"""

from __future__ import annotations

import errno
import socket

from .errors import INVALID_TARGET, PORT_IN_USE, TARGET_UNREACHABLE, BridgeError


class UdpSender:
    """Datagrams to ``host:port``, optionally from the local address ``bind``."""

    def __init__(
        self,
        host: str,
        port: int,
        bind: tuple[str, int] | None = None,
        where: str = "--to",
        bind_where: str = "--bind",
    ) -> None:
        self.address = (host, port)
        self.sent = 0
        self.refused = 0
        """Sends that reported an ICMP port unreachable: nothing listened there."""
        self.failed = 0
        """Sends that failed otherwise (the network went down for a moment)."""
        self.last_error: OSError | None = None
        family, remote = _resolve(host, port, where)
        self._socket = socket.socket(family, socket.SOCK_DGRAM)
        try:
            if bind is not None:
                self._bind(bind, bind_where)
            self._socket.connect(remote)
        except OSError as error:
            self._socket.close()
            raise BridgeError(
                TARGET_UNREACHABLE, f"cannot send to {host}:{port}: {error.strerror}", where
            ) from None
        except BaseException:
            self._socket.close()
            raise

    def _bind(self, bind: tuple[str, int], where: str) -> None:
        try:
            self._socket.bind(bind)
        except OSError as error:
            self._socket.close()
            if error.errno == errno.EADDRINUSE:
                raise BridgeError(
                    PORT_IN_USE, f"{bind[0]}:{bind[1]} is in use by another socket", where
                ) from None
            raise BridgeError(
                INVALID_TARGET, f"cannot send from {bind[0]}:{bind[1]}: {error.strerror}", where
            ) from None

    @property
    def local_address(self) -> tuple[str, int]:
        """The (host, port) the datagrams leave from."""
        name = self._socket.getsockname()
        return str(name[0]), int(name[1])

    def send(self, payload: bytes) -> bool:
        """Send one datagram; False (and counted) when the kernel reported a failure."""
        try:
            self._socket.send(payload)
        except ConnectionRefusedError as error:
            self.refused += 1
            self.last_error = error
            return False
        except OSError as error:
            self.failed += 1
            self.last_error = error
            return False
        self.sent += 1
        return True

    def close(self) -> None:
        self._socket.close()


def _resolve(host: str, port: int, where: str) -> tuple[socket.AddressFamily, tuple[str, int]]:
    try:
        found = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
    except socket.gaierror as error:
        raise BridgeError(
            TARGET_UNREACHABLE, f"cannot resolve {host!r}: {error.strerror}", where
        ) from None
    family, _, _, _, address = found[0]
    return family, (str(address[0]), int(address[1]))
