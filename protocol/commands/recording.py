"""Recording ops: the daemon writes a ROS 2 bag (MCAP) on its own machine.

A recording writes a file on the daemon's host, so starting and stopping one writes
(``--read-only`` and the writers' key refuse it as any other write); the topics it names
are judged as topics read. Without topics it records what the daemon bridges (README,
"Recording a session").
"""

from __future__ import annotations

import posixpath
from dataclasses import dataclass, replace
from typing import Any, Optional

from protocol.commands.errors import OutOfRangeError
from protocol.commands.fields import MAX_TEXT, ROS_NAME, ROS_NAME_DESC, Args
from protocol.commands.op import Example, FileUse, NameResolver, Op, Resource, TopicUse
from protocol.commands.results import Result

__all__ = ["BAG_SUFFIX", "COMPRESSIONS", "RecordingResult", "RecordingStatus", "StartRecording",
           "StopRecording", "bag_path_problem"]

COMPRESSIONS = ("none", "zstd", "lz4")
BAG_SUFFIX = ".mcap"


def bag_path_problem(path: str, *, absolute: bool) -> Optional[tuple[str, str]]:
    """(expected, got) if ``path`` cannot name a bag: a file ending in ``.mcap``, absolute
    (on the daemon's machine) where ``absolute``; None if it can."""
    if not path.endswith(BAG_SUFFIX) or posixpath.basename(path) == BAG_SUFFIX:
        return f"a file name ending in {BAG_SUFFIX}", repr(path)
    if absolute and not posixpath.isabs(path):
        return "an absolute path on the daemon's machine", repr(path)
    return None


def _path(a: Args) -> str:
    path = a.req_str("path", max_len=MAX_TEXT)
    problem = bag_path_problem(path, absolute=True)
    if problem is not None:
        raise OutOfRangeError(a.path("path"), *problem)
    return path


@dataclass(frozen=True)
class RecordingResult(Result):
    """A recording's counts (every recording op answers them): messages and drops, in all
    and per topic (``topics``: topic, type, messages, dropped), bytes on disk, elapsed
    seconds, mesh files attached, whether it runs; ``error`` when it stopped on its own;
    ``pending``: the topics it waits for (topic, why)."""

    path: str
    started_ns: int
    elapsed_s: float
    messages: int
    dropped: int
    bytes: int
    attachments: int
    running: bool
    topics: tuple[dict[str, Any], ...]
    error: Optional[str] = None
    pending: tuple[dict[str, Any], ...] = ()


@dataclass(frozen=True)
class StartRecording(Op, op="start_recording", result=RecordingResult, writes=True):
    """Record into ``path`` (absolute, ``.mcap``, on the daemon's machine, inside one of
    its ``--record-dir`` folders; an existing file is refused with ``ALREADY_EXISTS``
    unless ``overwrite``) the ``topics`` given, or without any, what the daemon bridges:
    /tf, /tf_static, joint_states, each robot's joint states and description topic (its
    meshes as attachments), every subscribed topic and every topic clients publish on,
    those bridged later too. It lasts until `StopRecording` (any writer's) or the daemon
    stops."""

    examples = (Example(
        {"path": "/data/s.mcap", "topics": ["/a", "/b"]},
        {("file", "path", "/data/s.mcap"), ("topic", "topics", "/a"), ("topic", "topics", "/b")}),)

    path: str
    topics: tuple[str, ...] = ()
    overwrite: bool = False
    compression: str = "none"

    def with_names(self, resolve: NameResolver) -> StartRecording:
        return replace(self, topics=tuple(resolve(topic, f"topics[{i}]")
                                          for i, topic in enumerate(self.topics)))

    def resources(self) -> tuple[Resource, ...]:
        return (FileUse("path", self.path, writes=True),
                *(TopicUse("topics", topic) for topic in self.topics))

    @classmethod
    def from_args(cls, a: Args) -> StartRecording:
        return cls(path=_path(a),
                   topics=a.str_list("topics", pattern=ROS_NAME, desc=ROS_NAME_DESC,
                                     required=False),
                   overwrite=a.opt_bool("overwrite", False),
                   compression=a.choice("compression", COMPRESSIONS, "none"))


@dataclass(frozen=True)
class StopRecording(Op, op="stop_recording", result=RecordingResult, writes=True):
    """Stop the recording into ``path``: the bag is finished (index, summary) and closed;
    the reply is its last `RecordingStatus`."""

    examples = (Example({"path": "/data/s.mcap"}),)

    path: str

    def resources(self) -> tuple[Resource, ...]:
        return ()  # judged when it started

    @classmethod
    def from_args(cls, a: Args) -> StopRecording:
        return cls(path=_path(a))


@dataclass(frozen=True)
class RecordingStatus(Op, op="recording_status", result=RecordingResult, writes=False):
    """A recording's counts: messages and drops per topic, bytes on disk, elapsed time,
    topics wanted but not recorded yet (and why), and ``error`` if it stopped on its own
    (a full disk)."""

    examples = (Example({"path": "/data/s.mcap"}),)

    path: str

    def resources(self) -> tuple[Resource, ...]:
        return ()

    @classmethod
    def from_args(cls, a: Args) -> RecordingStatus:
        return cls(path=_path(a))
