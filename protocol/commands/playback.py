"""Ops of the player (``slicer-ros2-bridge play BAG``): its clock, and pause, resume, seek
and rate. The live daemon refuses them (NOT_SUPPORTED: it plays no bag).

Pause, resume, seek and rate declare ``writes``: they change what every client of the
player sees (the one clock all streams follow), as a publish changes what ROS sees, so a
read-only client may read the clock (``playback_status``) but not move it.
"""

from __future__ import annotations

from dataclasses import dataclass

from protocol.commands.fields import Args, check_float
from protocol.commands.op import REQUEST_TYPES, Example, Op, Resource
from protocol.commands.results import Answered, Result
from protocol.commands.values import Stamp

__all__ = ["MAX_PLAYBACK_RATE", "MAX_SEEK_S", "PausePlayback", "PlaybackResult", "PlaybackStatus",
           "ResumePlayback", "SeekPlayback", "SetPlaybackRate", "player_ops"]

MAX_PLAYBACK_RATE = 1000.0
MAX_SEEK_S = 1e9  # beyond any bag: a seek past the end is clamped to it


@dataclass(frozen=True)
class PlaybackResult(Result):
    """The player's clock: the bag's first and last log times, where it plays now (bag
    time, and seconds from the start), its rate, and whether it is paused, loops, or has
    played to the end."""

    bag: str
    start: Stamp
    end: Stamp
    time: Stamp
    offset: float  # seconds from `start`
    duration: float  # seconds from `start` to `end`
    rate: float
    paused: bool
    loop: bool
    ended: bool

    @classmethod
    def read(cls, a: Args) -> PlaybackResult:
        return cls(bag=a.req_str("bag", max_len=4096, allow_empty=True),
                   start=_stamp(a, "start"), end=_stamp(a, "end"), time=_stamp(a, "time"),
                   offset=_seconds(a, "offset"), duration=_seconds(a, "duration"),
                   rate=check_float(a.raw("rate", True), a.path("rate"), 0.0,
                                    MAX_PLAYBACK_RATE, True),
                   paused=a.opt_bool("paused", False), loop=a.opt_bool("loop", False),
                   ended=a.opt_bool("ended", False))


def _stamp(a: Args, name: str) -> Stamp:
    value = a.raw(name, True)
    return Stamp.from_args(Args(value if isinstance(value, dict) else {}, a.path(name) + "."))


def _seconds(a: Args, name: str, high: float = float("inf")) -> float:
    return check_float(a.raw(name, True), a.path(name), 0.0, high, False)


@dataclass(frozen=True)
class PlaybackStatus(Op, Answered[PlaybackResult], op="playback_status", writes=False):
    """The player's clock and state."""

    examples = (Example({}),)

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> PlaybackStatus:
        return cls()


@dataclass(frozen=True)
class PausePlayback(Op, Answered[PlaybackResult], op="pause_playback", writes=True):
    """Hold the clock where it is (streams stop; lookups and meshes stay)."""

    examples = (Example({}),)

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> PausePlayback:
        return cls()


@dataclass(frozen=True)
class ResumePlayback(Op, Answered[PlaybackResult], op="resume_playback", writes=True):
    """Run the clock on from where it was held (from the start again if it had ended)."""

    examples = (Example({}),)

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> ResumePlayback:
        return cls()


@dataclass(frozen=True)
class SeekPlayback(Op, Answered[PlaybackResult], op="seek_playback", writes=True):
    """Move the clock to ``offset`` seconds from the bag's start (clamped to its end). The
    poses, images and values shown next are those at that time: each stream's last
    message at or before it. A paused player stays paused."""

    examples = (Example({"offset": 1.5}),)

    offset: float

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> SeekPlayback:
        return cls(offset=_seconds(a, "offset", MAX_SEEK_S))


@dataclass(frozen=True)
class SetPlaybackRate(Op, Answered[PlaybackResult], op="set_playback_rate", writes=True):
    """Play at ``rate`` times the bag's own speed (0 < rate <= 1000); the bag time shown
    does not jump."""

    examples = (Example({"rate": 2.0}),)

    rate: float

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> SetPlaybackRate:
        return cls(rate=check_float(a.raw("rate", True), a.path("rate"), 0.0,
                                    MAX_PLAYBACK_RATE, True))



def player_ops() -> tuple[type[Op], ...]:
    """The ops only a player serves: this module's (the live daemon refuses them)."""
    return tuple(cls for cls in REQUEST_TYPES.values() if cls.__module__ == __name__)
