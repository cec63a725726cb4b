"""The client's errors, in one place (re-exported by `slicer_client`)."""

from __future__ import annotations

from typing import Any, Mapping, Optional, Sequence

from protocol.auth import KeyFileError
from slicer_client.connection import (BridgeClientError, CommandRefusedError,
                                      CommandTimeoutError, ConnectionClosedError,
                                      DaemonUnreachableError, DeadLinkError,
                                      NotTheDaemonError)

__all__ = ["BridgeClientError", "CommandRefusedError", "CommandTimeoutError",
           "ConnectionClosedError", "DaemonUnreachableError", "DeadLinkError", "KeyFileError",
           "IkFailedError", "NotTheDaemonError", "ParameterRejectedError", "PointsError",
           "RobotNotLoadedError"]


class ParameterRejectedError(BridgeClientError):
    """The remote node refused a parameter value (its own reason is given)."""

    def __init__(self, node: str, name: str, reason: str) -> None:
        super().__init__(f"{node} refused parameter {name!r}: {reason or 'no reason given'}")
        self.node = node
        self.name = name
        self.reason = reason


class RobotNotLoadedError(BridgeClientError, TimeoutError):
    """A robot's links and meshes did not all arrive in time; `state` and `reason` are
    what the daemon last said about its description ("waiting" and why, or "error");
    `unposed` the links loaded but with no transform (tf cannot place them) and
    `unposed_reason` why, as the daemon judged it."""

    def __init__(self, name: str, timeout: float, *, state: str, reason: str,
                 received: int, expected: Optional[int],
                 unposed: Sequence[str] = (), unposed_reason: str = "") -> None:
        count = f"{received} of {expected}" if expected is not None else f"{received}"
        said = f"{state}: {reason}" if reason else (state or "nothing yet")
        if unposed:
            said = (f"{said}, but {len(unposed)} link(s) have no transform "
                    f"({', '.join(unposed)}): {unposed_reason}")
        super().__init__(f"robot {name!r} not loaded within {timeout} s ({count} meshes "
                         f"received); the daemon says {said}")
        self.name = name
        self.state = state
        self.reason = reason
        self.unposed = tuple(unposed)
        self.unposed_reason = unposed_reason


class PointsError(BridgeClientError, ValueError):
    """Points given to send (a model's, markups') are not (N, 3) finite millimetres."""

    def __init__(self, expected: str, got: str) -> None:
        super().__init__(f"points: expected {expected}, got {got}")
        self.expected = expected
        self.got = got


class IkFailedError(BridgeClientError):
    """No joint positions put the tip at the target: ``reason`` is ``unreachable``,
    ``joint_limit`` (``joints`` past their limits) or ``collision`` (``link`` touching
    ``obstacle``); ``residual_mm`` / ``residual_deg`` and ``positions`` are the best
    attempt's. The robot did not move (solving is a read)."""

    def __init__(self, robot: str, tip: str, failure: Mapping[str, Any], *,
                 residual_mm: float, residual_deg: float,
                 positions: Mapping[str, float]) -> None:
        self.robot = robot
        self.tip = tip
        self.reason = str(failure.get("reason", ""))
        self.text = str(failure.get("text", ""))
        self.joints = tuple(str(j) for j in failure.get("joints", ()))
        self.link = str(failure.get("link", ""))
        self.obstacle = str(failure.get("obstacle", ""))
        self.residual_mm = residual_mm
        self.residual_deg = residual_deg
        self.positions = dict(positions)
        super().__init__(f"robot {robot!r}: no solution for {tip!r} ({self.reason}): "
                         f"{self.text}; best residual {residual_mm:.3f} mm, "
                         f"{residual_deg:.3f} deg")
