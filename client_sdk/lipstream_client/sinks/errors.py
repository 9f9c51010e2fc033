"""The coded error the sinks and the bridge raise for bad input or an unusable target."""

from __future__ import annotations

from ..exceptions import LipstreamClientError


class BridgeError(LipstreamClientError):
    """A target, option or device the bridge cannot use: ``code`` is stable (scripts switch
    on it), ``where`` names the option or address at fault."""

    def __init__(self, code: str, message: str, where: str | None = None) -> None:
        self.code = code
        self.message = message
        self.where = where
        location = f"{where}: " if where else ""
        super().__init__(f"{location}{message} [{code}]")


INVALID_TARGET = "invalid_target"
"""The target address is malformed: unknown scheme, no host, a port outside 1-65535."""
TARGET_UNREACHABLE = "target_unreachable"
"""The target's host name does not resolve, or no route leads to it."""
PORT_IN_USE = "port_in_use"
"""The local address to send from is taken by another socket."""
NO_SOUND_DEVICE = "no_sound_device"
"""``play`` was asked for on a machine with no sound device or no player for it."""
NO_LIVELINK_CHANNELS = "no_livelink_channels"
"""The frames carry no channel Live Link Face knows (no ARKit name)."""
INVALID_AUDIO = "invalid_audio"
"""The speech changed sample rate within a request."""
SERVER_UNREACHABLE = "server_unreachable"
"""The lipstream server's URL is malformed or nothing answers there."""
MISSING_DEPENDENCY = "missing_dependency"
"""A sink needs a package of an extra that is not installed (``vmc``: python-osc)."""
