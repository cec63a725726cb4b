"""The demo's idle motion's pause/resume hook (`MotionHold`): whatever moves the demo joints
itself (the FollowJointTrajectory controller, `bridge.robots.demo.trajectory`) holds them,
and releases them to blend back into the idle motion. Pure: no ROS."""

from __future__ import annotations

from typing import Optional

__all__ = ["MotionHold"]

_BLEND_S = 2.0  # from held positions back into the idle motion


class MotionHold:
    """The idle motion's pause/resume hook: while held, the joint motion node publishes the
    held positions (for the joints given) instead of its idle motion; after `release`, it
    blends back into the idle motion over `_BLEND_S` seconds."""

    def __init__(self) -> None:
        self._held: dict[str, float] = {}
        self._holding = False
        self._released_at: Optional[float] = None

    @property
    def holding(self) -> bool:
        return self._holding

    @property
    def idle(self) -> bool:
        """Neither held nor blending back: the idle motion alone."""
        return not self._holding and self._released_at is None

    def hold(self, positions: dict[str, float]) -> None:
        """Pause the idle motion: publish `positions` for these joints."""
        self._held.update(positions)
        self._holding = True
        self._released_at = None

    def release(self, now: float) -> None:
        """Resume the idle motion (blending from the held positions, starting at `now`)."""
        self._holding = False
        self._released_at = now

    def apply(self, now: float, idle: dict[str, float]) -> dict[str, float]:
        """The positions to publish at `now`, given the idle motion's."""
        if self._holding:
            return {name: self._held.get(name, value) for name, value in idle.items()}
        if self._released_at is None or not self._held:
            return dict(idle)
        blend = (now - self._released_at) / _BLEND_S
        if blend >= 1.0:
            self._held.clear()
            self._released_at = None
            return dict(idle)
        return {name: self._held[name] + blend * (value - self._held[name])
                if name in self._held else value for name, value in idle.items()}
