"""The playback ops on the live daemon: refused, saying where they belong (no bag reader
is imported: the daemon runs without the play extra)."""

from __future__ import annotations

from typing import Any, NoReturn

from bridge.core.content_guards import ContentGuard
from bridge.core.dispatch import Handler
from protocol import commands as c
from protocol.commands import CommandFailedError, ErrorCode, Op

__all__ = ["LiveRefusals"]


class LiveRefusals:
    """The playback ops on the live daemon: refused, saying where they belong."""

    def handlers(self) -> dict[type[Op], Handler]:
        def refuse(request: Op, client: Any) -> NoReturn:
            raise CommandFailedError("op", "a player (slicer-ros2-bridge play BAG.mcap)",
                                     f"{request.op} sent to the live daemon, which plays ROS, "
                                     "not a bag", code=ErrorCode.NOT_SUPPORTED)
        return dict.fromkeys(c.player_ops(), refuse)

    def describe(self) -> list[dict[str, Any]]:
        return []

    def state(self, guard: ContentGuard) -> dict[str, Any]:
        return {}

    def close(self) -> None:
        pass
