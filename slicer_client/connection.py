"""A blocking OpenIGTLink connection to the bridge daemon, with a background receive thread.

Pure Python 3.9+ with numpy and `protocol` only, so it runs inside 3D Slicer's Python, in
scripts and in tests. Commands are matched to their replies by command id through a map of
pending requests; every other message goes to the `on_message` callback (in the receive
thread) and is kept as the latest value per device.
"""

from __future__ import annotations

import atexit
import itertools
import select
import socket
import ssl
import threading
import time
import weakref
from typing import Any, Callable, Dict, List, Mapping, Optional

from protocol import commands as c
from protocol.conversions import igtl_timestamp_now
from protocol.errors import FramingError, MessageError
from protocol.framing import Decoder, encode
from protocol.header import foreign_protocol
from protocol.liveness import socket_options
from protocol.messages import Command, Message, RtsCommand, Status

__all__ = [
    "BridgeClientError",
    "DaemonUnreachableError",
    "NotTheDaemonError",
    "ConnectionClosedError",
    "DeadLinkError",
    "CommandRefusedError",
    "CommandTimeoutError",
    "Connection",
]

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 18944


class BridgeClientError(Exception):
    """Base of the client's errors."""


class DaemonUnreachableError(BridgeClientError, ConnectionError):
    def __init__(self, host: str, port: int, reason: str) -> None:
        super().__init__(f"cannot reach the slicer-ros2-bridge daemon at {host}:{port}: "
                         f"{reason}. Is it running (`slicer-ros2-bridge run`, or `make demo`)?")
        self.host = host
        self.port = port


class NotTheDaemonError(DaemonUnreachableError):
    """Something else answers at host:port: another OpenIGTLink server (3D Slicer's own
    OpenIGTLinkIF server listens on 18944 too) or no OpenIGTLink at all (a web server)."""

    def __init__(self, host: str, port: int, peer: str) -> None:
        BridgeClientError.__init__(
            self, f"{host}:{port} is not the slicer-ros2-bridge daemon: {peer}. Start the "
            f"daemon on a free port (`slicer-ros2-bridge run --port N`) and connect to that "
            f"port.")
        self.host = host
        self.port = port
        self.peer = peer


# 3D Slicer's OpenIGTLinkIF announces header v2 on connect with a STATUS carrying this key
# (SlicerOpenIGTLink, vtkMRMLIGTLConnectorNode::ProcessIOConnectorEvents); the daemon never
# sends it, so it tells a Slicer server from the daemon at once.
_SLICER_ANNOUNCEMENT_KEY = "dummy"


def _describe_foreign_bytes(first: bytes) -> str:
    other = foreign_protocol(first)
    kind = f"{other} answers there" if other else "the peer does not speak OpenIGTLink"
    return f"{kind} (its first bytes: {first[:24]!r})"


class ConnectionClosedError(BridgeClientError, ConnectionError):
    """The daemon closed the connection (or it broke) while a request was waiting."""


class DeadLinkError(ConnectionClosedError):
    """Nothing came from the daemon for longer than its heartbeat allows: the link is down
    (a pulled cable, the daemon's host gone). The client reconnects by itself."""


class CommandRefusedError(BridgeClientError):
    """The daemon answered a command with an error; `error` says which field and why."""

    def __init__(self, op: str, error: c.ErrorInfo) -> None:
        where = f" (field {error.field!r})" if error.field else ""
        super().__init__(f"the daemon refused {op}{where}: {error.code.name}: {error.message}")
        self.op = op
        self.error = error

    @property
    def code(self) -> c.ErrorCode:
        return self.error.code

    @property
    def field(self) -> str:
        return self.error.field


class CommandTimeoutError(BridgeClientError, TimeoutError):
    def __init__(self, op: str, timeout: float, why: str = "") -> None:
        super().__init__(f"no reply to {op} within {timeout} s: " +
                         (why or "is the daemon busy or stalled? Its log says why."))
        self.op = op
        self.timeout = timeout


class _Pending:
    __slots__ = ("event", "reply")

    def __init__(self) -> None:
        self.event = threading.Event()
        self.reply: Optional[c.Reply] = None


MessageCallback = Callable[[Message], None]


class Connection:
    """One TCP connection to the daemon. Thread-safe: any thread may send and command."""

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                 on_message: Optional[MessageCallback] = None,
                 on_close: Optional[Callable[[Optional[BaseException]], None]] = None,
                 connect_timeout: float = 3.0,
                 tls: Optional[ssl.SSLContext] = None) -> None:
        self.host = host
        self.port = port
        self._on_message = on_message
        self._on_close = on_close
        self._dead_after = 0.0  # seconds of silence that mean a dead link (0: never)
        try:
            sock = socket.create_connection((host, port), timeout=connect_timeout)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            for level, option, value in socket_options():
                sock.setsockopt(level, option, value)
            if tls is not None:
                sock = tls.wrap_socket(sock, server_hostname=host)
        except ssl.SSLError as error:
            raise DaemonUnreachableError(host, port, f"TLS failed: {error.reason or error} "
                                         f"(is this the daemon's --tls-port, and does the "
                                         f"certificate match?)") from None
        except OSError as error:
            raise DaemonUnreachableError(host, port, error.strerror or str(error)) from None
        self._sock = sock
        self._sock.settimeout(None)
        self._send_lock = threading.Lock()
        self._state_lock = threading.Lock()
        self._pending: Dict[int, _Pending] = {}
        self._ids = itertools.count(1)
        self._latest: Dict[str, Message] = {}
        self._arrived = threading.Condition(self._state_lock)
        self._closed = False
        self._from_daemon = False  # a reply to a command came: the peer is the daemon
        self._foreign: Optional[NotTheDaemonError] = None
        self.close_reason: Optional[BaseException] = None
        self.errors: List[str] = []  # bad messages and STATUS errors the daemon sent
        # Announce header v2 at once (as 3D Slicer does): replies then carry metadata.
        self.send(Message(device_name="", body=Status(text="slicer_client"),
                          metadata={"client": "slicer_client"}))
        self._reader = threading.Thread(target=self._read_loop, name="igtl-receive",
                                        daemon=True)
        self._reader.start()
        close_at_exit(self)

    # --- sending ------------------------------------------------------------------------
    def send(self, message: Message) -> None:
        if not message.timestamp:
            message.timestamp = igtl_timestamp_now()
        data = encode(message, header_version=2)
        with self._send_lock:
            if self._closed:
                if self._foreign is not None:
                    raise self._foreign
                raise ConnectionClosedError("the connection to the daemon is closed")
            try:
                self._sock.sendall(data)
            except OSError as error:
                if self._foreign is not None:  # the reader closed on another protocol's bytes
                    raise self._foreign from None
                raise ConnectionClosedError(f"sending to the daemon failed: {error}") from None

    def command(self, op: str, arguments: Optional[Mapping[str, Any]] = None, *,
                timeout: float = 10.0) -> Dict[str, Any]:
        """Send one command and wait for its reply; returns the result object.
        Raises `CommandRefusedError`, `CommandTimeoutError` or `ConnectionClosedError`."""
        args = dict(arguments or {})
        args.setdefault("schema", c.SCHEMA_VERSION)
        command_id = next(self._ids)
        pending = _Pending()
        with self._state_lock:
            self._pending[command_id] = pending
        try:
            self.send(Message(device_name=c.COMMAND_DEVICE_NAME,
                              body=Command(command_id=command_id, name=op,
                                           text=c.dumps(args)),
                              metadata={"client": "slicer_client"}))
            if not pending.event.wait(timeout):
                if not self._from_daemon:
                    raise CommandTimeoutError(
                        op, timeout, f"{self.host}:{self.port} accepted the connection but "
                        f"has answered no command: another OpenIGTLink server there (3D "
                        f"Slicer's own listens on 18944 too), or a daemon that is stalled "
                        f"(its log says why)")
                raise CommandTimeoutError(op, timeout)
        finally:
            with self._state_lock:
                self._pending.pop(command_id, None)
        reply = pending.reply
        if reply is None and self._foreign is not None:
            raise self._foreign
        if reply is None:
            raise ConnectionClosedError(f"the connection closed before {op} was answered"
                                        f" ({self.close_reason})")
        if not reply.ok:
            assert reply.error is not None
            raise CommandRefusedError(op, reply.error)
        return reply.result

    # --- receiving ----------------------------------------------------------------------
    def expect_data_within(self, seconds: float) -> None:
        """From now on, `seconds` without a byte from the daemon (which then sends a
        heartbeat more often) close this connection as dead (`DeadLinkError`)."""
        self._dead_after = max(0.0, float(seconds))

    def _wait_readable(self) -> bool:
        """Wait for bytes within the dead-link bound; False if none came in time."""
        wait = self._dead_after
        if not wait or (isinstance(self._sock, ssl.SSLSocket) and self._sock.pending()):
            return True
        readable, _, _ = select.select([self._sock], [], [], wait)
        return bool(readable)

    def latest(self, device: str) -> Optional[Message]:
        with self._state_lock:
            return self._latest.get(device)

    def wait_for(self, device: str, predicate: Optional[Callable[[Message], bool]] = None,
                 timeout: float = 10.0) -> Message:
        """Wait until the latest message of `device` satisfies `predicate` (default: any)."""
        deadline = time.monotonic() + timeout
        with self._arrived:
            while True:
                message = self._latest.get(device)
                if message is not None and (predicate is None or predicate(message)):
                    return message
                remaining = deadline - time.monotonic()
                if remaining <= 0 or self._closed:
                    state = "closed" if self._closed else f"{timeout} s passed"
                    raise TimeoutError(f"no matching message on device {device!r} ({state}); "
                                       f"devices seen: {sorted(self._latest)}")
                self._arrived.wait(remaining)

    def devices(self) -> List[str]:
        with self._state_lock:
            return sorted(self._latest)

    def _read_loop(self) -> None:
        decoder = Decoder()
        reason: Optional[BaseException] = None
        first = b""  # the peer's first bytes, to name what it is if it is not OpenIGTLink
        received = False
        try:
            while True:
                if not self._wait_readable():
                    reason = DeadLinkError(
                        f"no data from the daemon at {self.host}:{self.port} for "
                        f"{self._dead_after:g} s: the link is down; reconnecting")
                    break
                data = self._sock.recv(1 << 20)
                if not data:
                    break
                if len(first) < 24:
                    first += data[:24 - len(first)]
                decoder.feed(data)
                while True:
                    try:
                        message = decoder.next_message()
                    except MessageError as error:
                        self.errors.append(str(error))
                        continue
                    if message is None:
                        break
                    received = True
                    self._dispatch(message)
                if self._foreign is not None:
                    reason = self._foreign
                    break
        except FramingError as error:
            reason = error
            if not received:
                self._foreign = NotTheDaemonError(self.host, self.port,
                                                  _describe_foreign_bytes(first))
                reason = self._foreign
        except (OSError, ValueError) as error:  # ValueError: select on a socket closed here
            if not self._closed:
                reason = error
        finally:
            self._finish(reason)

    def _dispatch(self, message: Message) -> None:
        body = message.body
        if (isinstance(body, Status) and not self._from_daemon
                and _SLICER_ANNOUNCEMENT_KEY in message.metadata):
            self._foreign = NotTheDaemonError(
                self.host, self.port, "3D Slicer's own OpenIGTLinkIF server answers there (it "
                "announced itself as Slicer does on connect)")
            return
        if isinstance(body, RtsCommand):
            with self._state_lock:
                pending = self._pending.get(body.command_id)
            if pending is not None:
                try:
                    pending.reply = c.Reply.from_json(body.text)
                    self._from_daemon = True
                except c.CommandError as error:
                    pending.reply = c.Reply.failure(body.name, c.ErrorCode.INTERNAL,
                                                    f"unreadable reply: {error}")
                pending.event.set()
            return
        if isinstance(body, Status) and body.code != 1:
            self.errors.append(f"{message.device_name}: {body.text}")
        with self._arrived:
            self._latest[message.device_name] = message
            self._arrived.notify_all()
        if self._on_message is not None:
            self._on_message(message)

    def _finish(self, reason: Optional[BaseException]) -> None:
        with self._arrived:
            self._closed = True
            self.close_reason = reason
            pending = list(self._pending.values())
            self._arrived.notify_all()
        for waiter in pending:
            waiter.event.set()  # reply stays None: the waiter raises ConnectionClosedError
        try:
            self._sock.close()
        except OSError:
            pass
        if self._on_close is not None:
            self._on_close(reason)

    # --- lifetime -----------------------------------------------------------------------
    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        closed_before_exit(self)
        with self._send_lock:
            self._closed = True
            try:
                self._sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        self._reader.join(timeout=5.0)

    def __enter__(self) -> Connection:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()



# Connections (and transports) a script left open: closed at its exit as close() does.
# The kernel would otherwise close the socket with unread stream data in it, which
# resets the connection (the daemon then logs "Connection reset by peer" for an ordinary
# end of a script).
_OPEN: "weakref.WeakSet[Any]" = weakref.WeakSet()


def close_at_exit(closable: Any) -> None:
    """Have ``closable.close()`` called at interpreter exit unless `closed_before_exit`."""
    _OPEN.add(closable)


def closed_before_exit(closable: Any) -> None:
    _OPEN.discard(closable)


@atexit.register
def _close_left_open() -> None:
    # Transports first: a connection closed under its transport would be reported lost.
    for closable in sorted(_OPEN, key=lambda item: isinstance(item, Connection)):
        closable.close()
