"""Display pacing (hello's ``display_hz``): a client that shows streams on a display gets
each stream's newest value once a frame, not every value.

3D Slicer's main thread imports every message its connector reads into the scene: a 1 kHz
pose stream costs it a thousand transform updates a second, of which a 60 Hz display shows
sixty. A paced client's session keeps, between two frames, the newest value of each device
the hub hands it (`hold`), and at each frame sends those and the newest value of each
native lane that moved (`Hub.lane_news`: the lanes do not write to a paced client). A value
waits at most one frame; what the display would never have shown is not sent.
"""

from __future__ import annotations

from bridge.core.outbox import Frame

__all__ = ["DisplayPacing"]


class DisplayPacing:
    """What a paced session holds between two frames (under its slot: other threads hand
    values over too)."""

    def __init__(self, hz: float) -> None:
        self.hz = hz
        self.interval_s = 1.0 / hz
        self._held: dict[str, Frame] = {}  # device -> its newest value since the last frame
        self.lanes_seen: dict[str, int] = {}  # lane device -> its count at the last frame
        self.replaced = 0  # values a newer one replaced before their frame

    def hold(self, device: str, frame: Frame) -> None:
        if device in self._held:
            self.replaced += 1
        self._held[device] = frame

    def forget(self, device: str) -> None:
        """Its bridge was removed: what it held must not bring the device back."""
        self._held.pop(device, None)
        self.lanes_seen.pop(device, None)

    def take(self, lanes: list[tuple[str, Frame]]) -> list[tuple[str, Frame]]:
        """What this frame sends: what was held, in the order the devices first changed,
        and the lanes' newest values (`Hub.lane_news`). A lane's value replaces what was
        held of its device: it is the newer (the Python path taking a later message
        clears the lane's)."""
        held, self._held = self._held, {}
        held.update(lanes)
        return list(held.items())
