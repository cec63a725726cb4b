"""The daemon's recordings: ``start_recording``, ``stop_recording``, ``recording_status``.

A recording is a `Recorder` on the daemon's node writing a bag on the daemon's machine.
Without topics it records what the daemon bridges, looked at again every
`bridge.record.recorder.POLL_S` (bridges made later are recorded from then on): the tf
topics its buffer reads (/tf, /tf_static), joint_states, each robot's joint states and
description topic, with its meshes attached,
every subscribed topic (streams and markers) and every topic clients publish on.

Opening the file and finishing the bag (the last chunk, the index) run in the client's
lane, off the event loop; recordings outlive the client that started them.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Optional, Protocol, Sequence

from bridge.core.content_guards import ContentGuard
from bridge.core.dispatch import Handler
from bridge.core.heavy import OffLoop
from bridge.record.bag import BagPathError, BagWriter
from bridge.record.recorder import Recorder
from protocol.commands import (JOINT_STATE_TYPE, CommandFailedError, ErrorCode, ForbiddenError, Op,
                               RecordingResult, RecordingStatus, StartRecording, StopRecording)

if TYPE_CHECKING:
    from bridge.ros.ros_node import RosNode


class RecordedTopics(Protocol):
    """A capability whose topics a recording without topics takes: what it bridges now,
    topic -> type (any thread). The daemon hands each to `RecordBridges`."""

    def recorded_topics(self) -> Mapping[str, Optional[str]]: ...


class MeshFiles(Protocol):
    """The robots' meshes, by their URI as the URDF writes it: a bag's attachments."""

    def mesh_files(self) -> dict[str, Path]: ...


__all__ = ["MeshFiles", "RecordBridges", "RecordedTopics"]

log = logging.getLogger(__name__)

FINISHED_KEPT = 16  # finished recordings whose last status stays asked for
_PATH_CODES = {"missing": ErrorCode.NOT_FOUND, "exists": ErrorCode.ALREADY_EXISTS,
               "unavailable": ErrorCode.NOT_SUPPORTED}


class RecordBridges:
    """Recordings by path (running, and the last `FINISHED_KEPT` finished)."""

    def __init__(self, ros: RosNode, *, sources: Sequence[RecordedTopics],
                 meshes: MeshFiles) -> None:
        self._ros = ros
        self._sources = tuple(sources)
        self._meshes = meshes
        self.running: dict[str, Recorder] = {}
        self._opening: set[str] = set()  # started, the file not open yet
        self._finished: dict[str, RecordingResult] = {}

    def bridged(self) -> dict[str, Optional[str]]:
        """What the daemon bridges now, topic -> type (any thread: copies of the dicts)."""
        # Joint states even before a robot is loaded; then what each capability bridges.
        wanted: dict[str, Optional[str]] = {
            self._ros.resolve_topic("joint_states"): JOINT_STATE_TYPE}
        for source in self._sources:
            wanted.update(source.recorded_topics())
        return wanted

    # ------------------------------------------------------------------ ops

    def start(self, request: StartRecording) -> OffLoop[RecordingResult]:
        path = str(Path(request.path))  # absolute and .mcap: checked by the schema
        if path in self.running or path in self._opening:
            raise CommandFailedError("path", "a path no recording writes to", f"{path} "
                                     "(being recorded: stop_recording first)",
                                     code=ErrorCode.ALREADY_EXISTS)
        self._opening.add(path)  # a second start of the same path is refused meanwhile

        def work() -> RecordingResult:
            try:
                return self._open(path, request)
            finally:
                self._opening.discard(path)
        return OffLoop(work)

    def _open(self, path: str, request: StartRecording) -> RecordingResult:
        """Open the bag and start recording (the client's lane)."""
        topics = request.topics
        try:
            bag = BagWriter(path, overwrite=request.overwrite, compression=request.compression)
        except BagPathError as error:
            if error.reason == "forbidden":
                raise ForbiddenError("path", error.expected, error.got) from None
            raise CommandFailedError("path", error.expected, error.got,
                                     code=_PATH_CODES.get(error.reason,
                                                          ErrorCode.OUT_OF_RANGE)) from None
        wanted = (lambda: dict.fromkeys(topics)) if topics else self.bridged
        recorder = Recorder(self._ros, bag, wanted,
                            attachments=(dict if topics else self._meshes.mesh_files))
        try:
            recorder.start()
        except BaseException:
            recorder.stop()
            raise
        self.running[path] = recorder
        self._finished.pop(path, None)
        log.info("recording into %s: %s", path,
                 ", ".join(topics) if topics else "what the daemon bridges")
        return recorder.status()

    def _find(self, path: str) -> Recorder:
        recorder = self.running.get(str(Path(path)))
        if recorder is None:
            raise CommandFailedError("path", "the path of a running recording",
                                     f"{path} ({self._known()})", code=ErrorCode.NOT_FOUND)
        return recorder

    def _known(self) -> str:
        running = list(self.running)
        return "running: " + ", ".join(running) if running else "none is running"

    def stop(self, request: StopRecording) -> OffLoop[RecordingResult]:
        recorder = self._find(request.path)
        path = str(recorder.bag.path)

        def work() -> RecordingResult:
            pending = {p["topic"]: p["why"] for p in recorder.status().pending}
            stats = recorder.stop().result(pending)
            self._remember(path, stats)
            log.info("recording into %s stopped: %d messages, %d dropped", path,
                     stats.messages, stats.dropped)
            return stats
        self.running.pop(path, None)
        return OffLoop(work)

    def status(self, request: RecordingStatus) -> RecordingResult:
        path = str(Path(request.path))
        if path in self._finished:
            return self._finished[path]
        return self._find(path).status()

    def _remember(self, path: str, stats: RecordingResult) -> None:
        self._finished[path] = stats
        while len(self._finished) > FINISHED_KEPT:
            del self._finished[next(iter(self._finished))]

    # ------------------------------------------------------------------ capability

    def handlers(self) -> Mapping[type[Op], Handler]:
        return {StartRecording: lambda request, _: self.start(request),
                StopRecording: lambda request, _: self.stop(request),
                RecordingStatus: lambda request, _: self.status(request)}

    def describe(self) -> list[dict[str, Any]]:
        return []

    def state(self, guard: ContentGuard) -> dict[str, Any]:
        return {"recordings": [{k: v for k, v in r.status().to_dict().items() if k != "topics"}
                               for r in tuple(self.running.values())]}

    def close(self) -> None:
        for path, recorder in tuple(self.running.items()):
            stats = recorder.stop()
            log.info("recording into %s finished at shutdown: %d messages", path,
                     stats.messages)
        self.running.clear()
