"""The demo's idle motion's hooks (`MotionHold`), for whatever else moves the demo joints.
Pure: no ROS.

* In-process movers hold the joints at positions they set (the FollowJointTrajectory
  controller, `bridge.robots.demo.trajectory`), then release them to blend back into the
  idle motion.
* Other publishers of ``joint_states`` (a client's sliders through ``set_robot_joints``)
  make the idle motion yield: it publishes nothing for ``yield_s`` seconds after their last
  message, and the robot follows them. An owner can also pause it by name.
"""

from __future__ import annotations

import math
import threading
from typing import Optional

__all__ = ["DEFAULT_YIELD_S", "MotionHold"]

_BLEND_S = 2.0  # from held positions back into the idle motion
DEFAULT_YIELD_S = 3.0


class MotionHold:
    """See the module docstring. Thread-safe where it must be: a subscription callback
    (`foreign_state`) and the motion's timer may run in different threads."""

    def __init__(self, yield_s: float = DEFAULT_YIELD_S) -> None:
        if not yield_s >= 0:
            raise ValueError(f"yield_s >= 0 expected, got {yield_s}")
        self.yield_s = yield_s
        self._held: dict[str, float] = {}
        self._holding = False
        self._released_at: Optional[float] = None
        self._owners: set[str] = set()
        self._until = -math.inf
        self._lock = threading.Lock()

    # --- an in-process mover holds positions ----------------------------------------------
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

    # --- another publisher drives the joints ----------------------------------------------
    def pause(self, owner: str) -> None:
        with self._lock:
            self._owners.add(owner)

    def resume(self, owner: str) -> None:
        with self._lock:
            self._owners.discard(owner)

    def foreign_state(self, now: float) -> bool:
        """Someone else published a joint state at `now` (seconds, any monotonic clock).
        True if this starts a yield (rather than prolonging one)."""
        with self._lock:
            starts = now >= self._until
            self._until = max(self._until, now + self.yield_s)
            return starts

    def yields(self, now: float) -> bool:
        """Whether the motion publishes nothing at `now`: paused by an owner, or within
        ``yield_s`` of a foreign joint state."""
        with self._lock:
            return bool(self._owners) or now < self._until
