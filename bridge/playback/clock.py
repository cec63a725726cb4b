"""The player's clock: which bag time it is at a given monotonic time, at a rate, paused or
running, moved by seeks. Pure (times in, times out), so its rules are tested alone."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["PlayClock"]

_NS_PER_S = 1_000_000_000


@dataclass
class PlayClock:
    """Bag time ``anchor_bag_ns`` was shown at monotonic ``anchor_mono_ns``; since then it
    runs at ``rate`` unless paused. All times in ns."""

    start_ns: int  # the bag's first log time
    end_ns: int  # its last
    rate: float = 1.0
    paused: bool = False
    anchor_bag_ns: int = 0
    anchor_mono_ns: int = 0

    def __post_init__(self) -> None:
        if not self.anchor_bag_ns:
            self.anchor_bag_ns = self.start_ns

    def bag_time(self, mono_ns: int) -> int:
        """The bag time at monotonic ``mono_ns`` (held while paused, never past the end)."""
        if self.paused:
            return self.anchor_bag_ns
        ran = int((mono_ns - self.anchor_mono_ns) * self.rate)
        return min(self.anchor_bag_ns + max(ran, 0), self.end_ns)

    def due_mono(self, bag_ns: int) -> int:
        """The monotonic time at which bag time ``bag_ns`` is due (running clock)."""
        return self.anchor_mono_ns + int((bag_ns - self.anchor_bag_ns) / self.rate)

    def set_rate(self, rate: float, mono_ns: int) -> None:
        """Change the rate without a jump in bag time."""
        self.anchor_bag_ns = self.bag_time(mono_ns)
        self.anchor_mono_ns = mono_ns
        self.rate = rate

    def pause(self, mono_ns: int) -> None:
        self.anchor_bag_ns = self.bag_time(mono_ns)
        self.anchor_mono_ns = mono_ns
        self.paused = True

    def resume(self, mono_ns: int) -> None:
        self.anchor_mono_ns = mono_ns
        self.paused = False

    def seek(self, bag_ns: int, mono_ns: int) -> int:
        """Move to ``bag_ns`` (clamped to the bag); the time moved to."""
        self.anchor_bag_ns = min(max(bag_ns, self.start_ns), self.end_ns)
        self.anchor_mono_ns = mono_ns
        return self.anchor_bag_ns

    def offset_s(self, mono_ns: int) -> float:
        return (self.bag_time(mono_ns) - self.start_ns) / _NS_PER_S
