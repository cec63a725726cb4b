"""The transport behind a `Client`: one factory, `open_transport`, and one protocol.

A transport carries commands (blocking, matched by id) and messages, and tells its
listener about messages, connections and losses. Two implementations exist:

- `ReconnectingTransport` (here): a TCP `Connection` to the daemon that, when the daemon
  goes away, retries in a background thread (every `retry_interval` s, growing to
  `max_interval`) and, once back, lets the listener re-create its bridges *before* user
  commands are let through again;
- the 3D Slicer module's connector transport (slicer_module/ROS2Bridge), which sends the
  same commands through Slicer's OpenIGTLinkIF connector node.
"""

from __future__ import annotations

import logging
import ssl
import threading
from collections import deque
from typing import Any, Callable, Deque, Dict, Mapping, Optional, Protocol, TypeVar, overload

from protocol import commands as c
from protocol.messages import Message
from slicer_client.connection import (DEFAULT_HOST, DEFAULT_PORT, ConnectionClosedError,
                                      Connection, DaemonUnreachableError, NotTheDaemonError,
                                      close_at_exit, closed_before_exit)

__all__ = ["CommandFn", "ReconnectingTransport", "Transport", "TransportListener",
           "open_transport", "request_with"]

log = logging.getLogger(__name__)

CommandFn = Callable[..., Dict[str, Any]]  # (op, args=None, *, timeout=...) -> result
_R = TypeVar("_R", bound=c.Result)


@overload
def request_with(command: CommandFn, request: c.Answered[_R], *,
                 timeout: Optional[float] = None) -> _R: ...
@overload
def request_with(command: CommandFn, request: c.Op, *,
                 timeout: Optional[float] = None) -> Dict[str, Any]: ...
def request_with(command: CommandFn, request: Any, *, timeout: Optional[float] = None) -> Any:
    """Send a request built from the protocol's op classes through `command` (the raw
    ``(op, args)`` route). An op that declares its result (`c.Answered`) gets it typed;
    any other gets the reply's result object. No `timeout`: `command`'s own default."""
    result = command(request.op, request.to_args(),
                     **({} if timeout is None else {"timeout": timeout}))
    return request.parse_result(result) if isinstance(request, c.Answered) else result

# Bound on messages kept for a listener not attached yet: a whole robot's meshes and more.
_MAX_EARLY_MESSAGES = 10_000


class TransportListener(Protocol):
    def on_message(self, message: Message) -> None:
        """Any message that is not a command reply (receive thread)."""

    def on_connected(self, command: CommandFn, first: bool) -> None:
        """A (re)connection is up. Re-create state with `command`; user commands wait
        until this returns. `first` is True for the connection made by `connect()`."""

    def on_disconnected(self, reason: str) -> None:
        """The connection was lost; the transport is retrying."""


class Transport(Protocol):
    address: str
    # Does it take a heartbeat's silence for a dead link (`expect_data_within`)?
    watches_silence: bool
    # Does each stream value reach the client (which drops late ones by their stamps)?
    # 3D Slicer's connector puts values into the scene itself: it shows what arrives.
    drops_late_values: bool
    # Can it carry the daemon's whole-message streams (a JSON body)? 3D Slicer's connector
    # imports only OpenIGTLink's standard types: a subscriber then reads its native stream.
    carries_whole_messages: bool
    # Does what it gets go to a display (3D Slicer's scene)? Then the hello asks the
    # daemon for each stream's newest value this many times a second; None: every value.
    display_hz: Optional[float]

    @property
    def connected(self) -> bool: ...

    def set_listener(self, listener: TransportListener) -> None: ...

    def command(self, op: str, arguments: Optional[Mapping[str, Any]] = None, *,
                timeout: float = 10.0) -> Dict[str, Any]: ...

    def send(self, message: Message) -> None: ...

    def expect_data_within(self, seconds: float) -> None:
        """The daemon sends a heartbeat: `seconds` of silence mean a dead link."""

    def serve_other_threads(self) -> None:
        """Run what other threads handed to the thread that owns the transport (3D Slicer's
        connector is its main thread's); a call that waits for a reply calls it."""

    def close(self) -> None: ...


class ReconnectingTransport:
    """A TCP connection to the daemon that comes back by itself."""

    watches_silence = True
    drops_late_values = True
    carries_whole_messages = True
    display_hz: Optional[float] = None  # a script's callbacks see every value they keep up with

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                 reconnect: bool = True, retry_interval: float = 0.5,
                 max_interval: float = 5.0, connect_timeout: float = 3.0,
                 tls: Optional[ssl.SSLContext] = None) -> None:
        self.host = host
        self._tls = tls
        self.port = port
        self.address = f"{host}:{port}"
        self._reconnect = reconnect
        self._retry_interval = retry_interval
        self._max_interval = max_interval
        self._connect_timeout = connect_timeout
        self._listener: Optional[TransportListener] = None
        # Messages that came before the listener: the daemon sends its state (meshes once
        # per connection) as soon as the client announces header v2, so none may be lost.
        self._early: Deque[Message] = deque(maxlen=_MAX_EARLY_MESSAGES)
        self._delivery = threading.Lock()  # keeps early and later messages in order
        self._lock = threading.Lock()
        self._ready = threading.Event()  # set while a connection is up and re-synced
        self._stop = threading.Event()
        self._generation = 0
        self._retrier: Optional[threading.Thread] = None
        self._retrying = False  # guarded by _lock: one retry thread at a time
        self.reconnects = 0
        self.last_loss: str = ""
        self._conn = self._open()  # raises DaemonUnreachableError naming host:port
        close_at_exit(self)  # before its connection, which it would report lost

    # --- connections --------------------------------------------------------------------
    def _open(self) -> Connection:
        with self._lock:
            self._generation += 1
            generation = self._generation
        return Connection(self.host, self.port, connect_timeout=self._connect_timeout,
                          tls=self._tls,
                          on_message=self._on_message,
                          on_close=lambda reason: self._lost(generation, reason))

    def set_listener(self, listener: TransportListener) -> None:
        """Attach the listener, hand it what arrived before it, in order, and run its
        first `on_connected` (re-sync of nothing)."""
        with self._delivery:
            while self._early:
                listener.on_message(self._early.popleft())
            self._listener = listener
        listener.on_connected(self._conn.command, True)
        self._ready.set()

    def _on_message(self, message: Message) -> None:
        with self._delivery:
            if self._listener is None:
                if len(self._early) == self._early.maxlen:
                    log.warning("no listener yet for %s messages: the oldest is dropped",
                                self._early.maxlen)
                self._early.append(message)
                return
        self._listener.on_message(message)

    def _lost(self, generation: int, reason: Optional[BaseException]) -> None:
        # Reader thread of the lost connection. Old generations and close() are ignored.
        if isinstance(reason, NotTheDaemonError) and not self._ready.is_set():
            self.last_loss = str(reason)
            return  # the first connection reached something else: connect() raises that
        with self._lock:
            if self._stop.is_set() or generation != self._generation:
                return
            self._ready.clear()
            start = self._reconnect and not self._retrying
            self._retrying = self._retrying or start
        self.last_loss = str(reason) if reason else "the daemon closed the connection"
        log.warning("lost the daemon at %s (%s)%s", self.address, self.last_loss,
                    "; reconnecting" if self._reconnect else "")
        if self._listener is not None:
            self._listener.on_disconnected(self.last_loss)
        if start:
            self._retrier = threading.Thread(target=self._retry_loop,
                                             name="slicer-client-reconnect", daemon=True)
            self._retrier.start()

    def _retry_loop(self) -> None:
        interval = self._retry_interval
        while not self._stop.wait(interval):  # waits the retry interval, wakes on close()
            try:
                conn = self._open()
            except DaemonUnreachableError:
                interval = min(interval * 1.5, self._max_interval)
                continue
            self._conn = conn
            try:
                if self._listener is not None:
                    self._listener.on_connected(conn.command, False)
            except (ConnectionClosedError, DaemonUnreachableError) as error:
                log.warning("re-sync with %s interrupted: %s", self.address, error)
            except Exception:  # noqa: BLE001 - a refused re-create must not stop retrying
                log.exception("re-sync with %s failed", self.address)
            with self._lock:
                # A loss seen by _lost while we were re-syncing left the work to us.
                if conn.closed:
                    interval = self._retry_interval
                    continue
                self.reconnects += 1
                self._retrying = False
                self._ready.set()
            log.info("reconnected to the daemon at %s", self.address)
            return

    # --- use ----------------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        return self._ready.is_set() and not self._conn.closed

    @property
    def connection(self) -> Connection:
        """The current TCP connection (changes after a reconnect)."""
        return self._conn

    def wait_connected(self, timeout: float) -> bool:
        return self._ready.wait(timeout)

    def _current(self, timeout: float, what: str) -> Connection:
        if self._stop.is_set():
            raise ConnectionClosedError(f"{what}: the client was closed")
        if not self._ready.wait(timeout):
            retrying = ("still reconnecting every "
                        f"{self._retry_interval:g}-{self._max_interval:g} s"
                        if self._reconnect else "reconnection is off")
            raise ConnectionClosedError(
                f"{what}: the daemon at {self.address} is gone ({self.last_loss}); "
                f"{retrying}. Start it again (`slicer-ros2-bridge run --port {self.port}`).")
        return self._conn

    def command(self, op: str, arguments: Optional[Mapping[str, Any]] = None, *,
                timeout: float = 10.0) -> Dict[str, Any]:
        return self._current(timeout, op).command(op, arguments, timeout=timeout)

    def send(self, message: Message) -> None:
        self._current(0.0, f"sending {message.type_name} to {message.device_name!r}") \
            .send(message)

    def expect_data_within(self, seconds: float) -> None:
        self._conn.expect_data_within(seconds)

    def serve_other_threads(self) -> None:
        """Nothing: a socket's commands are safe from any thread."""

    def close(self) -> None:
        closed_before_exit(self)
        self._stop.set()
        self._ready.clear()
        self._conn.close()
        retrier = self._retrier
        if retrier is not None:
            retrier.join(timeout=self._connect_timeout + 1.0)


def open_transport(host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                   reconnect: bool = True, retry_interval: float = 0.5,
                   max_interval: float = 5.0, connect_timeout: float = 3.0,
                   tls: Optional[ssl.SSLContext] = None) -> Transport:
    """The one factory for socket transports (the Slicer module builds its own)."""
    return ReconnectingTransport(host, port, reconnect=reconnect,
                                 retry_interval=retry_interval, max_interval=max_interval,
                                 connect_timeout=connect_timeout, tls=tls)
