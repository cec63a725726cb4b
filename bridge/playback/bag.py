"""A ROS 2 MCAP bag, read with its index: Foxglove's ``mcap`` reader and the
``mcap-ros2-support`` decoder, built from each schema's text (``ros2msg``), so any bag
plays, ours, ``ros2 bag``'s or rosbags', whatever message types it holds.

Memory stays bounded for any bag length: messages come a chunk at a time, in log-time order
(`messages`), and the state at a time (`latest_before`) is read backwards from it through
the index, keeping one message per key.

Bad input is named, never fatal where something can still play:

* not an MCAP file, or no file: `BagError` at open;
* no summary (a recording cut short, truncated): the messages are read in one linear pass
  (seeks re-read from the start) up to where the file ends; `problems` says so;
* chunks of a compression this reader lacks, or whose data is corrupt: skipped, each named
  once in `problems` with its time range; the other chunks play;
* a channel whose schema is missing, not ``ros2msg``/``cdr``, or does not parse: skipped,
  named once (`decoder` returns None).
"""

from __future__ import annotations

import io
import logging
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, Optional

from mcap.exceptions import McapError
from mcap.reader import McapReader, NonSeekingReader, SeekingReader
from mcap.records import ChunkIndex
from mcap_ros2.decoder import DecoderFactory

__all__ = ["Bag", "BagError", "BagMessage", "Channel", "open_bag"]

log = logging.getLogger(__name__)

# What mcap's reader decompresses ("" is none); lz4 and zstd need their modules.
_COMPRESSIONS = ("", "lz4", "zstd")
# Errors a damaged file raises from the reader or the decoder while reading.
_READ_ERRORS = (McapError, EOFError, OSError, ValueError, KeyError, IndexError,
                RuntimeError)


class BagError(Exception):
    """The file cannot be played at all (missing, not an MCAP file, unreadable)."""


@dataclass(frozen=True)
class Channel:
    id: int
    topic: str
    type: str  # the schema's name: "sensor_msgs/msg/Image"
    encoding: str  # the messages' ("cdr")
    schema: Any  # mcap's Schema record, or None


@dataclass(frozen=True)
class BagMessage:
    channel: Channel
    log_time: int  # ns
    data: bytes


def _compression_works(name: str) -> bool:
    """Does mcap's reader decompress ``name`` here (its own optional modules, as it sees
    them)?"""
    from mcap import stream_reader

    available = {"": True, "lz4": getattr(stream_reader, "lz4", None) is not None,
                 "zstd": getattr(stream_reader, "zstandard", None) is not None}
    return available.get(name, False)


def _describe(error: BaseException) -> str:
    text = str(error)
    return f"{type(error).__name__}: {text}" if text else type(error).__name__


def _mcap_file(path: Path) -> Path:
    """``path`` itself, or the one .mcap file of a rosbag2 folder."""
    if path.is_dir():
        found = sorted(path.glob("*.mcap"))
        if len(found) != 1:
            raise BagError(f"{path}: expected a .mcap file, or a rosbag2 folder holding one; "
                           f"got a folder with {len(found)} .mcap files")
        return found[0]
    if not path.exists():
        raise BagError(f"{path}: no such file")
    return path


class Bag:
    """One MCAP file, open for the player's lifetime (`close`)."""

    def __init__(self, path: Path) -> None:
        self.path = _mcap_file(Path(path))
        self.problems: list[str] = []  # named once each: what is skipped and why
        self._stream: BinaryIO = open(self.path, "rb")  # noqa: SIM115 - closed in close()
        try:
            self._open()
        except BaseException:
            self._stream.close()
            raise
        self._decoders = DecoderFactory()
        self._decoded: dict[int, Optional[Callable[[bytes], Any]]] = {}

    def _open(self) -> None:
        magic = self._stream.read(8)
        if magic != b"\x89MCAP0\r\n":
            raise BagError(f"{self.path}: not an MCAP file (its first bytes are "
                           f"{magic[:8]!r}, an MCAP file starts with b'\\x89MCAP0\\r\\n')")
        self._stream.seek(0)
        # Chunk CRCs checked (where the writer set them): a corrupt chunk is skipped, named,
        # rather than played as wrong poses or pixels.
        self._reader: McapReader = SeekingReader(self._stream, validate_crcs=True)
        try:
            summary = self._reader.get_summary()
        except _READ_ERRORS as error:  # no footer: cut short
            summary = None
            self.problems.append(f"{self.path.name}: no index (the file ends early, at "
                                 f"{self.path.stat().st_size} bytes: {_describe(error)}); "
                                 "its messages "
                                 "are read in one pass up to where it ends, and seeking "
                                 "re-reads from the start")
        self.indexed = summary is not None and bool(summary.chunk_indexes)
        self.channels: dict[int, Channel] = {}
        self._skipped_chunks: set[int] = set()  # chunk_start_offset
        if summary is not None and self.indexed:
            for channel in summary.channels.values():
                schema = summary.schemas.get(channel.schema_id)
                self.channels[channel.id] = Channel(channel.id, channel.topic,
                                                    schema.name if schema else "",
                                                    channel.message_encoding, schema)
            for chunk in summary.chunk_indexes:
                if not _compression_works(chunk.compression):
                    self._skip_chunk(chunk, f"compressed with {chunk.compression!r}, which "
                                     f"this reader does not decompress (it reads "
                                     f"{', '.join(repr(c) for c in _COMPRESSIONS)})")
            good = [c for c in summary.chunk_indexes
                    if c.chunk_start_offset not in self._skipped_chunks]
            self.start_ns = min((c.message_start_time for c in good), default=0)
            self.end_ns = max((c.message_end_time for c in good), default=0)
            summary.chunk_indexes[:] = good  # the reader then never opens a skipped one
        else:
            self._scan()

    def _skip_chunk(self, chunk: ChunkIndex, why: str) -> None:
        self._skipped_chunks.add(chunk.chunk_start_offset)
        self.problems.append(f"{self.path.name}: messages from {chunk.message_start_time} to "
                             f"{chunk.message_end_time} ns skipped: their chunk (at byte "
                             f"{chunk.chunk_start_offset}) is {why}")

    def _scan(self) -> None:
        """One linear pass over a bag without an index: its channels and time range."""
        self.start_ns = self.end_ns = 0
        first = True
        for message in self._linear(None, None):
            if first:
                self.start_ns, first = message.log_time, False
            self.start_ns = min(self.start_ns, message.log_time)
            self.end_ns = max(self.end_ns, message.log_time)

    def _linear(self, topics: Optional[set[str]], start_ns: Optional[int]
                ) -> Iterator[BagMessage]:
        """Messages in file order, up to where the file ends or breaks (said once). Each
        pass reads its own handle: a seek's look back may run while the playing pass waits."""
        with open(self.path, "rb") as stream:
            yield from self._linear_in(NonSeekingReader(stream, validate_crcs=True), topics,
                                       start_ns)

    def _linear_in(self, reader: NonSeekingReader, topics: Optional[set[str]],
                   start_ns: Optional[int]) -> Iterator[BagMessage]:
        try:
            for schema, channel, message in reader.iter_messages(log_time_order=False):
                known = self.channels.get(channel.id)
                if known is None:
                    known = self.channels[channel.id] = Channel(
                        channel.id, channel.topic, schema.name if schema else "",
                        channel.message_encoding, schema)
                if topics is not None and channel.topic not in topics:
                    continue
                if start_ns is not None and message.log_time < start_ns:
                    continue
                yield BagMessage(known, message.log_time, message.data)
        except _READ_ERRORS as error:
            self._said(f"{self.path.name}: read up to where it breaks off "
                       f"({_describe(error)}); the rest is lost")

    def _said(self, problem: str) -> None:
        if problem not in self.problems:
            self.problems.append(problem)
            log.warning("%s", problem)

    # ------------------------------------------------------------------ reading

    def topics(self) -> dict[str, str]:
        """topic -> type, of every channel."""
        return {c.topic: c.type for c in self.channels.values()}

    def messages(self, start_ns: int, topics: Optional[Iterable[str]] = None
                 ) -> Iterator[BagMessage]:
        """Messages from ``start_ns`` on, in log-time order, a chunk in memory at a time.
        A chunk that fails to read is skipped (named once) and reading goes on after it."""
        wanted = None if topics is None else set(topics)
        if not self.indexed:
            yield from self._linear(wanted, start_ns)
            return
        at = start_ns  # after a broken chunk, from the last time given, inclusive: a
        # message of that time may be given twice (harmless: the same value), none is lost
        while True:
            try:
                for _schema, channel, message in self._reader.iter_messages(
                        topics=wanted, starting_at=at, log_time_order=True):
                    at = message.log_time
                    yield BagMessage(self.channels[channel.id], message.log_time,
                                     message.data)
                return
            except _READ_ERRORS as error:
                if not self._skip_broken(at, error):
                    return

    def _skip_broken(self, at: int, error: BaseException) -> bool:
        """The chunk that failed reading from ``at`` on: skipped; False if none is left."""
        summary = self._reader.get_summary()
        assert summary is not None
        after = sorted((c for c in summary.chunk_indexes if c.message_end_time >= at),
                       key=lambda c: (c.message_start_time, c.chunk_start_offset))
        if not after:
            return False
        chunk = after[0]
        self._skip_chunk(chunk, f"unreadable ({type(error).__name__}: {error})")
        log.warning("%s", self.problems[-1])
        summary.chunk_indexes[:] = [c for c in summary.chunk_indexes if c is not chunk]
        return True

    def latest_before(self, t_ns: int, topics: Iterable[str],
                      key: Callable[[BagMessage], Iterable[Any]],
                      window_ns: int, keys: Optional[set[Any]] = None) -> list[BagMessage]:
        """For each key ``key(message)`` gives, the newest message at or before ``t_ns`` and
        within ``window_ns`` of it: the state at ``t_ns``. Read backwards through the index
        (a bag without one: forwards from the window's start), and no further once each of
        ``keys`` (if given) is found. Oldest first."""
        wanted = set(topics)
        found: dict[Any, BagMessage] = {}
        if not wanted:
            return []
        begin = max(t_ns - window_ns, 0)
        if not self.indexed:
            for message in self._linear(wanted, begin):
                if message.log_time > t_ns:
                    continue  # file order need not be time order
                for k in key(message):
                    old = found.get(k)
                    if old is None or old.log_time <= message.log_time:
                        found[k] = message
        else:
            self._latest_indexed(t_ns, wanted, key, begin, keys, found)
        unique = {id(m): m for m in found.values()}  # one message may be several keys' latest
        return sorted(unique.values(), key=lambda m: m.log_time)

    def _latest_indexed(self, t_ns: int, wanted: set[str],
                        key: Callable[[BagMessage], Iterable[Any]], begin: int,
                        keys: Optional[set[Any]], found: dict[Any, BagMessage]) -> None:
        try:
            for _schema, channel, record in self._reader.iter_messages(
                    topics=wanted, starting_at=begin, ending_before=t_ns + 1,
                    log_time_order=True, reverse=True):
                bag_message = BagMessage(self.channels[channel.id], record.log_time,
                                         record.data)
                for k in key(bag_message):
                    found.setdefault(k, bag_message)
                if keys is not None and keys <= found.keys():
                    break
        except _READ_ERRORS as error:
            self._said(f"{self.path.name}: the state before {t_ns} ns is partial: "
                       f"{_describe(error)}")

    def decoder(self, channel: Channel) -> Optional[Callable[[bytes], Any]]:
        """The decoder of ``channel``'s messages from its schema, or None (named once)."""
        if channel.id in self._decoded:
            return self._decoded[channel.id]
        decode: Optional[Callable[[bytes], Any]] = None
        schema = channel.schema
        if schema is None or not channel.type:
            why = "has no schema in the bag"
        elif schema.encoding != "ros2msg" or channel.encoding != "cdr":
            why = (f"is {channel.type} as {schema.encoding!r}/{channel.encoding!r}, not a "
                   "ROS 2 message (ros2msg schema, cdr encoding)")
        else:
            try:
                decode = self._decoders.decoder_for(channel.encoding, schema)
                why = "" if decode is not None else "has a schema no decoder reads"
            except Exception as error:  # noqa: BLE001 - the library's parse errors vary
                why = f"has a schema that does not parse ({type(error).__name__}: {error})"
        if decode is None:
            self._said(f"topic {channel.topic} skipped: it {why}")
        self._decoded[channel.id] = decode
        return decode

    def decode(self, message: BagMessage) -> Any:
        """The message decoded, or None (its channel skipped, or these bytes bad: named)."""
        decode = self.decoder(message.channel)
        if decode is None:
            return None
        try:
            return decode(message.data)
        except Exception as error:  # noqa: BLE001 - bad bytes: one line per topic
            self.skip_message(message, error)
            return None

    def skip_message(self, message: BagMessage, error: BaseException) -> None:
        """A message whose bytes do not read as its type: skipped, said once per topic."""
        self._said(f"topic {message.channel.topic}: a message that does not decode as "
                   f"{message.channel.type} skipped ({_describe(error)})")

    def attachments(self) -> Iterator[tuple[str, bytes]]:
        """(name, data) of every attachment (meshes a recording carried)."""
        try:
            if self.indexed:
                for attachment in self._reader.iter_attachments():
                    yield attachment.name, attachment.data
                return
            self._stream.seek(0, io.SEEK_SET)
            for attachment in NonSeekingReader(self._stream).iter_attachments():
                yield attachment.name, attachment.data
        except _READ_ERRORS as error:
            self._said(f"{self.path.name}: attachments read in part ({error})")

    def close(self) -> None:
        self._stream.close()


def open_bag(path: str | Path) -> Bag:
    """`Bag` of ``path`` (a .mcap file or a rosbag2 folder), or `BagError` saying why not."""
    try:
        return Bag(Path(path))
    except BagError:
        raise
    except _READ_ERRORS as error:
        raise BagError(f"{path}: not a readable MCAP file ({type(error).__name__}: "
                       f"{error})") from None
