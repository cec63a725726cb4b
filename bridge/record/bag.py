"""A ROS 2 MCAP bag written by one thread of its own, fed from any thread.

What the ROS callbacks do is `BagWriter.offer`: stamp the messages and append them to a
queue bounded in bytes, nothing else. The writer thread takes what waits, all at once, and
hands it to Foxglove's `mcap` library (profile ``ros2``, schemas ``ros2msg``, messages
``cdr``: what rosbag2 writes), whose chunks go to disk as they fill, and at least once a
second: memory stays bounded whatever the bag's length. A message that would pass the
queue's bound is dropped and counted per topic (`BagStats.dropped`), never silently.

A write the disk refuses (full, or past RLIMIT_FSIZE) stops the recording with
`BagStats.error` saying so; the file is cut back to the last whole record and closed with
the library's own end records (a footer with no summary, which readers answer by scanning
the data), so what was written stays readable. If even those 50 bytes do not fit, records
are given up from the end until they do. The messages that did not reach the disk (those
of the chunk refused or given up, and those waiting) are counted as dropped: the counts
are the bag's.

No ROS import: the ROS side (`bridge.record.recorder`) feeds it bytes.
"""

from __future__ import annotations

import errno
import logging
import os
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional, Union

from bridge.core.threads import OnFailure, start_thread
from protocol.commands import BAG_SUFFIX, COMPRESSIONS, RecordingResult, bag_path_problem

try:  # a daemon installed without it serves on; recording says what to install
    from mcap.data_stream import RecordBuilder
    from mcap.opcode import Opcode
    from mcap.records import DataEnd, Footer
    from mcap.writer import MCAP0_MAGIC, CompressionType, Writer
    MCAP_MISSING = ""
except ImportError as missing:
    MCAP_MISSING = str(missing)

__all__ = ["BAG_SUFFIX", "COMPRESSIONS", "DEFAULT_QUEUE_BYTES", "MCAP_MISSING", "BagPathError",
           "BagStats", "BagWriter", "TopicStats", "check_bag_path"]

log = logging.getLogger(__name__)

# What may wait for the writer thread: 5 s of a 30 Hz VGA stream (27 MB/s) while a disk
# stalls. Past it, messages are dropped and counted.
DEFAULT_QUEUE_BYTES = 128 * 1024 * 1024
CHUNK_BYTES = 1024 * 1024  # mcap's default: a chunk is what one write puts on disk
FLUSH_EVERY_S = 1.0  # a chunk is written at least this often: a crash loses at most that
LIBRARY = "slicer-ros2-bridge record"
# Recent write boundaries kept to fall back on when even the end records do not fit.
_BOUNDARIES_KEPT = 64


class BagPathError(Exception):
    """The bag cannot be made at this path. ``reason``: ``missing`` (no such folder),
    ``exists`` (without overwrite), ``forbidden`` (not writable), ``invalid`` (not an
    absolute ``.mcap`` path), ``unavailable`` (the mcap package is not installed)."""

    def __init__(self, reason: str, expected: str, got: str) -> None:
        super().__init__(f"expected {expected}, got {got}")
        self.reason, self.expected, self.got = reason, expected, got


def check_bag_path(path: Union[str, Path], *, absolute: bool) -> Path:
    """The bag's path, if it names a ``.mcap`` file (an absolute one if ``absolute``)."""
    problem = bag_path_problem(str(path), absolute=absolute)
    if problem is not None:
        raise BagPathError("invalid", *problem)
    return Path(path)


def _open(path: Path, overwrite: bool) -> int:
    flags = os.O_WRONLY | os.O_CREAT | os.O_CLOEXEC | (os.O_TRUNC if overwrite else os.O_EXCL)
    try:
        return os.open(path, flags, 0o644)
    except FileExistsError:
        raise BagPathError("exists", "a new file (or overwrite)",
                           f"{path}, which exists") from None
    except FileNotFoundError:
        raise BagPathError("missing", "a path in an existing folder",
                           f"{path} (no folder {path.parent})") from None
    except IsADirectoryError:
        raise BagPathError("exists", "a file path", f"{path}, a folder") from None
    except PermissionError:
        raise BagPathError("forbidden", "a folder the recorder may write in",
                           f"{path} (permission denied)") from None
    except OSError as error:
        raise BagPathError("forbidden", "a path the recorder can create",
                           f"{path} ({error.strerror})") from None


class _DiskError(Exception):
    def __init__(self, error: OSError, offset: int) -> None:
        super().__init__(error.strerror)
        self.error, self.offset = error, offset


class _Sink:
    """The file as the `mcap` writer sees it: every `write` lands whole or not at all (a
    refused one is cut back), so the file always ends on a record boundary."""

    def __init__(self, fd: int, on_chunk: Callable[[int], None]) -> None:
        self.fd = fd
        self.on_chunk = on_chunk  # a chunk is on disk at this offset, with what was added
        self.offset = 0
        self.boundaries: deque[int] = deque(maxlen=_BOUNDARIES_KEPT)

    def write(self, data: Union[bytes, bytearray, memoryview]) -> int:
        start = self.offset
        view = memoryview(data)
        try:
            while view:
                done = os.write(self.fd, view)
                view = view[done:]
                self.offset += done
        except OSError as error:
            self.cut(start)
            raise _DiskError(error, start) from None
        if len(data):
            self.boundaries.append(start)
            if data[0] == Opcode.CHUNK:  # the writer writes each chunk in one write
                self.on_chunk(start)
        return len(data)

    def cut(self, offset: int) -> None:
        os.ftruncate(self.fd, offset)
        os.lseek(self.fd, offset, os.SEEK_SET)
        self.offset = offset

    def tell(self) -> int:
        return self.offset

    def flush(self) -> None:
        pass  # unbuffered: os.write has handed it to the kernel


@dataclass
class TopicStats:
    topic: str
    ros_type: str
    messages: int = 0  # handed to the bag (written, or waiting to be)
    dropped: int = 0  # refused: the queue was full, or the bag had stopped

    def to_dict(self) -> dict[str, Any]:
        return {"topic": self.topic, "type": self.ros_type, "messages": self.messages,
                "dropped": self.dropped}


@dataclass
class BagStats:
    path: str
    started_ns: int  # wall clock
    elapsed_s: float
    messages: int
    dropped: int
    bytes: int  # on disk so far
    topics: list[TopicStats] = field(default_factory=list)
    attachments: int = 0
    error: str = ""  # why the recording stopped on its own (a full disk)
    running: bool = True

    def result(self, pending: dict[str, str]) -> RecordingResult:
        """These counts as a recording op answers them, with the topics still awaited."""
        return RecordingResult(
            self.path, self.started_ns, round(self.elapsed_s, 3), self.messages, self.dropped,
            self.bytes, self.attachments, self.running,
            tuple(t.to_dict() for t in self.topics), self.error or None,
            tuple({"topic": t, "why": why} for t, why in sorted(pending.items())))


# Queue items: a batch of one channel's messages, or work for the writer (a channel, an
# attachment, metadata).
_Batch = tuple[int, int, list[bytes]]  # channel id, first log time, messages


@dataclass(frozen=True)
class _Job:
    work: Callable[[Writer], None]
    size: int  # bytes it holds while it waits


class BagWriter:
    """One bag being written (see the module). `close` finishes it; `stats` any time."""

    def __init__(self, path: Union[str, Path], *, overwrite: bool = False,
                 queue_bytes: int = DEFAULT_QUEUE_BYTES, compression: str = "none",
                 chunk_bytes: int = CHUNK_BYTES,
                 on_error: Optional[Callable[[str], None]] = None) -> None:
        self.path = Path(path)
        if MCAP_MISSING:
            raise BagPathError("unavailable", "the mcap package (pip install mcap==1.6.0)",
                               f"none installed ({MCAP_MISSING})")
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression: expected one of {', '.join(COMPRESSIONS)}, "
                             f"got {compression!r}")
        # Messages handed to the writer and not yet in a chunk on disk, per channel (the
        # writer thread's): lost if the disk refuses that chunk, and then counted so.
        self._unwritten: dict[int, int] = {}
        # The last chunks on disk: (offset, messages per channel), for what a cut loses.
        self._chunks: deque[tuple[int, dict[int, int]]] = deque(maxlen=_BOUNDARIES_KEPT)
        self._sink = _Sink(_open(self.path, overwrite), self._chunk_written)
        self._queue_bytes = queue_bytes
        self._on_error = on_error
        self._lock = threading.Condition()
        self._queue: deque[Union[_Batch, _Job]] = deque()
        self._queued = 0
        self._topics: list[TopicStats] = []
        self._last_ns = 0
        self._closing = False
        self._stopped = False  # no more messages taken: closed, or the disk refused one
        self._error = ""
        self._attachments = 0
        self.started_ns = time.time_ns()
        self._started = time.monotonic()
        self._ended: Optional[float] = None
        self._schemas: dict[str, int] = {}  # ros type -> schema id (writer thread)
        self._channels: dict[int, int] = {}  # our channel -> the writer's (writer thread)
        self._writer = Writer(self._sink, chunk_size=chunk_bytes,  # type: ignore[arg-type]
                              compression=getattr(CompressionType, compression.upper()))
        try:
            self._writer.start(profile="ros2", library=LIBRARY)
            self._writer.flush()  # the header on disk: never given up to make room
        except _DiskError as error:
            os.close(self._sink.fd)
            self.path.unlink(missing_ok=True)
            raise BagPathError("forbidden", "room for the bag", f"{self.path} "
                               f"({error.error.strerror})") from None
        self._floor = self._sink.offset
        # `_run` ends the bag itself on any failure: a thread that cannot die.
        self._thread = start_thread("bag-writer", self._run, OnFailure.RESTART)

    # ------------------------------------------------------------------ any thread

    def add_channel(self, topic: str, ros_type: str, definition: str,
                    qos_profiles: str = "") -> int:
        """A topic's channel (and its schema, once per type); its id for `offer`."""
        with self._lock:
            channel = len(self._topics)
            self._topics.append(TopicStats(topic, ros_type))

        def register(writer: Writer) -> None:
            schema = self._schemas.get(ros_type)
            if schema is None:
                schema = self._schemas[ros_type] = writer.register_schema(
                    ros_type, "ros2msg", definition.encode())
            metadata = {"offered_qos_profiles": qos_profiles} if qos_profiles else {}
            self._channels[channel] = writer.register_channel(topic, "cdr", schema, metadata)
        self._put(_Job(register, 0))
        return channel

    def offer(self, channel: int, messages: list[bytes]) -> None:
        """Messages of one topic, as received (a ROS callback: cheap, never blocks)."""
        if not messages:
            return
        size = sum(len(m) for m in messages)
        now = time.time_ns()
        with self._lock:
            stats = self._topics[channel]
            if self._stopped or self._queued + size > self._queue_bytes:
                stats.dropped += len(messages)
                return
            # Strictly increasing log times keep the order of arrival in any reader.
            first = max(now, self._last_ns + 1)
            self._last_ns = first + len(messages) - 1
            stats.messages += len(messages)
            self._queue.append((channel, first, messages))
            self._queued += size
            self._lock.notify()

    def attach(self, name: str, data: bytes, media_type: str = "application/octet-stream") -> None:
        """A file carried in the bag (a robot's mesh: ``name`` is its URI in the URDF)."""
        now = time.time_ns()

        def add(writer: Writer) -> None:
            writer.add_attachment(now, now, name, media_type, data)
            self._attachments += 1
        self._put(_Job(add, len(data)))

    def add_metadata(self, name: str, values: dict[str, str]) -> None:
        self._put(_Job(lambda writer: writer.add_metadata(name, values), 0))

    @property
    def running(self) -> bool:
        """Whether it still takes messages (not closed, no write refused)."""
        return not self._stopped

    def stats(self) -> BagStats:
        with self._lock:
            topics = [TopicStats(t.topic, t.ros_type, t.messages, t.dropped)
                      for t in self._topics]
            end = self._ended if self._ended is not None else time.monotonic()
            return BagStats(str(self.path), self.started_ns, end - self._started,
                            sum(t.messages for t in topics), sum(t.dropped for t in topics),
                            self._sink.offset, topics, self._attachments, self._error,
                            running=not self._stopped)

    def close(self) -> BagStats:
        """Write what waits, finish the bag (index, summary, footer) and close the file."""
        with self._lock:
            self._closing = True
            if self._ended is None:
                self._ended = time.monotonic()
            self._lock.notify()
        self._thread.join()
        return self.stats()

    def _put(self, job: _Job) -> None:
        with self._lock:
            if self._stopped:
                return
            self._queue.append(job)
            self._queued += job.size
            self._lock.notify()

    # ------------------------------------------------------------------ writer thread

    def _run(self) -> None:
        last_flush = time.monotonic()
        try:
            while True:
                with self._lock:
                    while not self._queue and not self._closing:
                        self._lock.wait(max(0.0, FLUSH_EVERY_S - (time.monotonic()
                                                                   - last_flush)))
                        if time.monotonic() - last_flush >= FLUSH_EVERY_S:
                            break
                    taken, self._queue = self._queue, deque()
                    closing = self._closing
                written = self._write(taken)
                with self._lock:
                    self._queued -= written
                if time.monotonic() - last_flush >= FLUSH_EVERY_S or closing:
                    self._writer.flush()
                    last_flush = time.monotonic()
                if closing:
                    self._writer.finish()
                    break
        except _DiskError as error:
            self._disk_full(error)
        except Exception as error:  # noqa: BLE001 - said, and the file still closed
            log.exception("the bag writer for %s failed", self.path)
            self._fail(f"the bag writer failed: {error}")
            self._end_readable()
        finally:
            with self._lock:
                self._stopped = True
                if self._ended is None:
                    self._ended = time.monotonic()
                self._queue.clear()
            os.close(self._sink.fd)

    def _write(self, taken: deque[Union[_Batch, _Job]]) -> int:
        try:
            return self._write_all(taken)
        except _DiskError:  # what was taken and not written yet is lost with it
            for channel, _, rest in (i for i in taken if isinstance(i, tuple)):
                self._unwritten[channel] = self._unwritten.get(channel, 0) + len(rest)
            raise

    def _write_all(self, taken: deque[Union[_Batch, _Job]]) -> int:
        size = 0
        add = self._writer.add_message
        unwritten = self._unwritten
        while taken:
            item = taken.popleft()
            if isinstance(item, tuple):
                channel, stamp, messages = item
                target = self._channels[channel]
                for index, data in enumerate(messages):
                    unwritten[channel] = unwritten.get(channel, 0) + 1
                    try:
                        add(target, stamp, data, stamp)
                    except _DiskError:
                        unwritten[channel] += len(messages) - index - 1
                        raise
                    stamp += 1
                    size += len(data)
            else:
                item.work(self._writer)
                size += item.size
        return size

    def _chunk_written(self, offset: int) -> None:
        self._chunks.append((offset, dict(self._unwritten)))
        self._unwritten.clear()

    def _fail(self, text: str) -> None:
        with self._lock:
            self._error = text
            self._stopped = True
            if self._ended is None:
                self._ended = time.monotonic()
            for channel, _, messages in (i for i in self._queue if isinstance(i, tuple)):
                self._topics[channel].messages -= len(messages)
                self._topics[channel].dropped += len(messages)
            self._queue.clear()
        if self._on_error is not None:
            self._on_error(text)

    def _disk_full(self, error: _DiskError) -> None:
        reasons = {errno.ENOSPC: "the disk is full",
                   errno.EFBIG: "the file size limit (RLIMIT_FSIZE) is reached",
                   errno.EDQUOT: "the disk quota is used up"}
        reason = reasons.get(error.error.errno or 0, error.error.strerror or "a write failed")
        kept = self._end_readable()
        with self._lock:
            for channel, lost in self._unwritten.items():
                self._topics[channel].messages -= lost
                self._topics[channel].dropped += lost
        self._fail(f"recording stopped: {reason} ({self.path}, {error.error.strerror}); "
                   f"the bag is closed and readable ({kept} bytes kept; the messages not on "
                   f"disk yet are counted as dropped)")
        log.error("%s", self._error)

    def _end_readable(self) -> int:
        """End the file after its last whole record with a footer without summary; if
        that does not fit, give up records from the end until it does."""
        builder = RecordBuilder()
        DataEnd(0).write(builder)
        Footer(0, 0, 0).write(builder)
        ending = bytes(builder.end()) + MCAP0_MAGIC
        sink = self._sink
        while True:
            try:
                start = sink.offset
                sink.write(ending)
                return start
            except _DiskError:
                pass
            earlier = [b for b in sink.boundaries if self._floor <= b < sink.offset]
            if not earlier:
                return sink.offset  # nothing to give up: the bare magic and header stay
            sink.cut(earlier[-1])
            sink.boundaries.pop()
            while self._chunks and self._chunks[-1][0] >= sink.offset:  # given up: lost
                for channel, lost in self._chunks.pop()[1].items():
                    self._unwritten[channel] = self._unwritten.get(channel, 0) + lost
