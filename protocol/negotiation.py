"""Per-connection choice of the header version to send.

OpenIGTLink 1.x/2.x receivers (protocol 1-2, for example Debian's 1.11 library) lose
framing on a header-v2 message, so a connection starts with v1. 3D Slicer's OpenIGTLinkIF
announces v2 by sending a STATUS with metadata right after connecting (and sends v2 for
nodes with metadata), so the first v2 message seen from the peer switches the connection to
v2 for good: a v2-capable peer does not lose that ability.
"""

from __future__ import annotations

from protocol.messages import Message

__all__ = ["HeaderVersionNegotiator"]


class HeaderVersionNegotiator:
    """Tracks one connection: `outgoing_version` is 1 until the peer has sent a v2 message.

    ``max_version`` caps the result (1 forces v1 whatever the peer sends).
    """

    def __init__(self, *, max_version: int = 2) -> None:
        if max_version not in (1, 2):
            raise ValueError(f"max_version: expected 1 or 2, got {max_version!r}")
        self._max_version = max_version
        self._peer_version = 1

    @property
    def outgoing_version(self) -> int:
        """The header version to encode outgoing messages with."""
        return min(self._peer_version, self._max_version)

    @property
    def peer_speaks_v2(self) -> bool:
        return self._peer_version >= 2

    def observe(self, message: Message) -> int:
        """Note a message received from the peer; returns the (possibly new) outgoing version."""
        if message.header_version >= 2:
            self._peer_version = 2
        return self.outgoing_version

    def reset(self) -> None:
        """Forget what the peer showed (for a new connection on the same object)."""
        self._peer_version = 1
