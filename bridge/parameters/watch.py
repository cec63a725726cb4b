"""What the parameter capability offers the others (robots watch ``robot_description``):
a watch on one parameter, and the interface that makes one. Another capability imports this,
never the handlers (capability.py); the daemon hands it `ParameterBridges`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional, Protocol

from rclpy.client import Client

from protocol.commands import ParameterValue

__all__ = ["ParameterWatch", "ParameterWatcher"]


@dataclass(eq=False)
class ParameterWatch:
    """Another capability's interest in one parameter of one node (robots watch
    ``robot_description``); made by `ParameterBridges.watch_parameter`. Not a client-visible
    bridge: no device, nothing streamed."""

    node: str
    name: str
    on_change: Callable[[ParameterValue], None]
    # None for the daemon's own node: read in process, never through its own services.
    get_client: Optional[Client]
    ready: Optional[bool] = None  # None until the first check
    value: Optional[ParameterValue] = None  # the last value reported
    touched: int = 0  # serial of the last event that set `value`
    unanswered: str = ""  # why the last fetch got no answer ("" once one is answered)


class ParameterWatcher(Protocol):
    """Watches on parameters for another capability (`ParameterBridges` is one)."""

    async def watch_parameter(self, node: str, name: str,
                              on_change: Callable[[ParameterValue], None], *,
                              ready_wait_s: Optional[float] = None,
                              ) -> tuple[ParameterWatch, Optional[ParameterValue]]: ...

    def unwatch_parameter(self, watch: ParameterWatch) -> None: ...
