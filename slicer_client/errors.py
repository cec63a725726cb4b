"""The client's errors, in one place (re-exported by `slicer_client`)."""

from __future__ import annotations

from protocol.auth import KeyFileError
from slicer_client.connection import (BridgeClientError, CommandRefusedError,
                                      CommandTimeoutError, ConnectionClosedError,
                                      DaemonUnreachableError, DeadLinkError,
                                      NotTheDaemonError)

__all__ = ["BridgeClientError", "CommandRefusedError", "CommandTimeoutError",
           "ConnectionClosedError", "DaemonUnreachableError", "DeadLinkError", "KeyFileError",
           "NotTheDaemonError", "ParameterRejectedError"]


class ParameterRejectedError(BridgeClientError):
    """The remote node refused a parameter value (its own reason is given)."""

    def __init__(self, node: str, name: str, reason: str) -> None:
        super().__init__(f"{node} refused parameter {name!r}: {reason or 'no reason given'}")
        self.node = node
        self.name = name
        self.reason = reason
