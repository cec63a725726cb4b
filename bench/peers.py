"""The benchmark's peers, each run as its own process by bench_daemon.py (never imported
by the daemon): a publisher that sleeps between messages, a plain rclpy subscriber (the
ROS floor), and a raw OpenIGTLink reader with any number of connections.

    peers.py publish KIND TOPIC      KIND: pose | image | tf | cloud
    peers.py floor KIND TOPIC
    peers.py read PORT CLIENTS [--setup JSON]
    peers.py watch PORT PARENT CHILD [--hello-hz HZ]
    peers.py facade PORT TOPIC [--cloud]
    peers.py callback PORT TOPIC
    peers.py naive-callback PORT DEVICE

Every peer prints READY when it can start, then obeys lines on stdin:

* publisher: ``RUN RATE SECONDS [BURST]`` publishes at RATE Hz for SECONDS, stamping each
  message with ``time.time_ns()`` just before ``publish()``, then prints ``DONE <count>``.
  It sleeps until each message is due (a publisher that spins would take the CPU the
  daemon needs on a 2-core machine) and catches up without sleeping when it is late. With
  BURST, messages go out BURST at a time, back to back, every BURST/RATE seconds (a driver
  that batches);
* floor and reader: ``RESET`` forgets what was received, ``REPORT`` prints one JSON line
  of figures (see `Recorder.report`), ``QUIT`` exits. A reader also takes ``PAUSE
  SECONDS``: it reads nothing for that long (a stalled GUI), then reads on; its report
  then says what it read first (``resumed``);
* facade: a subscriber node of TOPIC made through the CamelCase facade
  (``GetDefaultROS2Node().CreateAndAddSubscriberNode``, PoseStamped, or PointCloud2 with
  ``--cloud``), as a script in Slicer makes it, with a ModifiedEvent observer that counts
  (``received``) and reads ``GetLastMessage()`` (a pose's). ``REPORT`` prints ``received``
  and the node's ``GetNumberOfMessages()`` as ``messages``;
* callback: a Pythonic subscriber (``slicer_client.connect().subscribe``) of TOPIC
  (PoseStamped), a reader whose stream ``callback`` is publish -> its callback (the
  stamp of the newest message the client holds when the callback runs);
* naive-callback: the naive relay's user, pyigtl's client in a `wait_for_message` loop,
  a reader whose stream ``callback`` is publish -> the message returned to the loop;
* watcher (the other client of bench/attacks.py): one raw connection that streams the tf
  lookup PARENT <- CHILD (stream ``tf``) and sends ``hello`` at HZ, each one's round trip
  recorded as stream ``hello`` (stamp: when it was sent); a hello still unanswered at
  REPORT counts in ``hello_unanswered`` with its age.

Latency is ``arrival - stamp`` in one host clock (``time.time_ns``). The reader takes the
arrival time when `recv` returns the chunk that completes a message: for an image, its
last byte. It parses only the 58-byte OpenIGTLink header (timestamp, body size), so its
own cost is the same whichever relay it reads. It records TRANSFORM, IMAGE and POLYDATA
messages that carry a time stamp.

The reader also asks the kernel when that chunk's last segment reached its socket
(SO_TIMESTAMPNS): ``queued - stamp`` is the latency before the reader's own scheduling adds
to it (reported as ``queued_p50`` / ``queued_p99``). For a chunk that holds several
messages, each gets the last segment's time, and the kernel merges segments that wait for a
late reader, giving them the last one's time: never early, but late where the reader is.
"""

from __future__ import annotations

import argparse
import fcntl
import json
import os
import selectors
import socket
import struct
import sys
import termios
import threading
import time
from typing import Any, Callable

_HEADER = struct.Struct(">H12s20sQQQ")
# KEEP_LAST depth of every pose subscriber and publisher (floor, daemon, naive relay): half a
# second at 10 kHz, so that a reliable retransmission (rmw_fastrtps waits for the writer's
# next heartbeat, ~0.1 s) does not overflow the history of any of them.
POSE_DEPTH = 5000
_NS = 1_000_000_000
# Kinds of message a frame each (images, clouds): depth 10, as a camera driver's.
_BULK = ("image", "cloud")
# <asm-generic/socket.h> (x86_64 and aarch64 alike); the socket module does not name it.
# The kernel then hands each recvmsg the time its last segment arrived (a timespec).
_SO_TIMESTAMPNS = 35
_TIMESPEC = struct.Struct("@qq")
_ANCILLARY_SIZE = socket.CMSG_SPACE(_TIMESPEC.size)


# The message types a reader records (the first 5 bytes of the header's type).
_RECORDED = (b"TRANS", b"IMAGE", b"POLYD")


def _stamp_ns(igtl_timestamp: int) -> int:
    sec, frac = igtl_timestamp >> 32, igtl_timestamp & 0xFFFFFFFF
    return sec * _NS + (frac * _NS >> 32)


class Recorder:
    """Latencies and arrival order per stream, thread-safe enough for one writer."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.reset()

    def reset(self) -> None:
        with getattr(self, "lock", threading.Lock()):
            # stream -> list of (arrival_ns, stamp_ns)
            self.samples: dict[str, list[tuple[int, int]]] = {}
            # stream -> latencies (ms) to the reader's socket, where the kernel said
            self.queued: dict[str, list[float]] = {}
            # Messages published before the reset (a warm-up's, a reliable retransmission
            # after discovery) are not part of what is measured next.
            self.since = time.time_ns()
            self.resumed_at = 0  # when a PAUSE ended (ns), 0: no pause
            self.held_at_resume = 0  # bytes the reader's socket buffer held then
            self.held_values = 0  # stream values among those bytes
            self.read_since_resume = 0  # bytes
            self.after_resume: list[tuple[int, int]] = []  # (arrival, stamp), all streams

    def add(self, stream: str, arrival_ns: int, stamp_ns: int, queued_ns: int = 0) -> None:
        if stamp_ns < self.since:
            return
        samples = self.samples.get(stream)
        if samples is None:
            samples = self.samples[stream] = []
            self.queued[stream] = []
        samples.append((arrival_ns, stamp_ns))
        if queued_ns:
            self.queued[stream].append((queued_ns - stamp_ns) / 1e6)
        if self.resumed_at and arrival_ns >= self.resumed_at:
            self.after_resume.append((arrival_ns, stamp_ns))

    def report(self) -> dict[str, Any]:
        """Per stream: count, out-of-order arrivals, latency percentiles (ms) and the p50 of
        each second (lag over time); all streams together as "all"."""
        with self.lock:
            streams = {name: list(values) for name, values in self.samples.items()}
            queued = {name: list(values) for name, values in self.queued.items()}
        out: dict[str, Any] = {"streams": {}}
        every: list[float] = []
        for name, values in streams.items():
            latencies = [(a - s) / 1e6 for a, s in values]
            every.extend(latencies)
            stamps = [s for _, s in values]
            disorder = sum(1 for x, y in zip(stamps, stamps[1:]) if y <= x)
            out["streams"][name] = {"n": len(values), "out_of_order": disorder,
                                    **_percentiles(latencies), "per_second": _per_second(values)}
            if queued.get(name):
                in_socket = _percentiles(queued[name])
                out["streams"][name].update(queued_p50=in_socket["p50"],
                                            queued_p99=in_socket["p99"])
            if len(values) <= 2000:  # few (images): each one, to match with another party
                out["streams"][name]["arrivals"] = [[s, a] for a, s in values]
        out["all"] = _percentiles(every)
        out["all"]["n"] = len(every)
        with self.lock:
            after = list(self.after_resume)
        if after:
            # What the reader read once it read again: first what its own socket buffer held
            # (values that reached it on time), then what the relay had kept for it.
            ages = [(a - s) / 1e6 for a, s in after]
            fresh = next((i for i, age in enumerate(ages) if age < 100), len(ages))
            out["resumed"] = {"first_age_ms": ages[0], "read_before_fresh": fresh,
                              "held_bytes": self.held_at_resume,
                              "held_values": self.held_values,
                              "stale_after_fresh": sum(1 for age in ages[fresh:]
                                                       if age >= 100),
                              "fresh_after_ms": ((after[fresh][0] - after[0][0]) / 1e6
                                                 if fresh < len(after) else float("nan"))}
        return out


def _percentiles(values: list[float]) -> dict[str, float]:
    if not values:
        return {"p50": float("nan"), "p99": float("nan"), "max": float("nan")}
    ordered = sorted(values)

    def pick(q: float) -> float:
        return ordered[min(len(ordered) - 1, int(q * len(ordered)))]

    return {"p50": pick(0.50), "p99": pick(0.99), "max": ordered[-1]}


def _per_second(values: list[tuple[int, int]]) -> list[float]:
    if not values:
        return []
    first = values[0][1]
    buckets: dict[int, list[float]] = {}
    for arrival, stamp in values:
        buckets.setdefault((stamp - first) // _NS, []).append((arrival - stamp) / 1e6)
    return [round(_percentiles(buckets[k])["p50"], 3) for k in sorted(buckets)]


def _serve_commands(recorder: Recorder, quit_: Callable[[], None],
                    pause: Callable[[float], None] | None = None) -> None:
    for line in sys.stdin:
        word = line.strip()
        if word == "RESET":
            recorder.reset()
        elif word == "REPORT":
            print(json.dumps(recorder.report()), flush=True)
        elif word.startswith("PAUSE ") and pause is not None:
            pause(float(word.split()[1]))
        elif word == "QUIT":
            break
    quit_()


# ------------------------------------------------------------------------------ reader


def read(port: int, clients: int, setup: list[dict[str, Any]], v2: bool) -> None:
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    from protocol.framing import encode
    from protocol.messages import Message, Status

    if setup:
        from slicer_client.connection import Connection

        # Commands (tf lookups, then keep_bridge for each, so that the readers, other
        # clients, get their streams) on one extra connection that stays open.
        keeper = Connection("127.0.0.1", port)
        for command in setup:
            keeper.command(command["op"], command.get("arguments", {}))
    recorder = Recorder()
    selector = selectors.DefaultSelector()
    for index in range(clients):
        sock = socket.create_connection(("127.0.0.1", port), timeout=10)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        if v2:  # as 3D Slicer does: a STATUS in header v2 at once, then v2 with metadata
            sock.sendall(encode(Message("", Status(text="bench reader")), header_version=2))
        sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
        sock.setblocking(False)
        selector.register(sock, selectors.EVENT_READ, [index, bytearray()])
    stop = threading.Event()
    paused_until = [0.0]

    def pause(seconds: float) -> None:
        paused_until[0] = time.monotonic() + seconds
        recorder.resumed_at = time.time_ns() + int(seconds * _NS)
        print("PAUSED", flush=True)

    def held_bytes() -> int:
        """What the reader's own kernel holds for it, unread (the socket's buffer)."""
        held = 0
        for key in selector.get_map().values():
            unread = fcntl.ioctl(key.fileobj, termios.FIONREAD, b"\0\0\0\0")
            held += int.from_bytes(unread, sys.byteorder)
        return held

    threading.Thread(target=_serve_commands, args=(recorder, stop.set, pause),
                     daemon=True).start()
    print("READY", flush=True)
    unpack = _HEADER.unpack_from
    header_size = _HEADER.size
    while not stop.is_set():
        if paused_until[0]:
            if time.monotonic() < paused_until[0]:
                time.sleep(0.01)
                continue
            paused_until[0] = 0.0
            recorder.held_at_resume = held_bytes()
        for key, _ in selector.select(timeout=0.2):
            index, buffer = key.data
            try:
                chunk, ancillary, _, _ = key.fileobj.recvmsg(  # type: ignore[union-attr]
                    1 << 20, _ANCILLARY_SIZE)
            except BlockingIOError:
                continue
            arrival = time.time_ns()
            queued = 0  # none for the first segments: the kernel turns timestamps on lazily
            for level, kind, data in ancillary:
                if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS:
                    seconds, nanoseconds = _TIMESPEC.unpack_from(data)
                    queued = seconds * _NS + nanoseconds
            if not chunk:
                selector.unregister(key.fileobj)
                continue
            buffer += chunk
            offset = 0
            with recorder.lock:
                while len(buffer) - offset >= header_size:
                    _, type_raw, name_raw, stamp, size, _ = unpack(buffer, offset)
                    end = offset + header_size + size
                    if end > len(buffer):
                        break
                    offset = end
                    if stamp and type_raw[:5] in _RECORDED:
                        name = name_raw.rstrip(b"\0").decode()
                        recorder.add(f"{index}:{name}", arrival, _stamp_ns(stamp), queued)
                        if recorder.resumed_at and arrival >= recorder.resumed_at:
                            recorder.read_since_resume += header_size + size
                            if recorder.read_since_resume <= recorder.held_at_resume:
                                recorder.held_values += 1
            del buffer[:offset]


def watch(port: int, parent: str, child: str, hello_hz: float) -> None:
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    from protocol.framing import encode
    from protocol.messages import Command, Message, Status

    def command(command_id: int, op: str, arguments: dict[str, Any]) -> bytes:
        return encode(Message("bench", Command(command_id=command_id, name=op,
                                               text=json.dumps(arguments))), header_version=2)

    def connect() -> socket.socket:
        sock = socket.create_connection(("127.0.0.1", port), timeout=10)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.sendall(encode(Message("", Status(text="bench watcher")), header_version=2))
        sock.sendall(command(1, "create_tf_lookup", {"parent": parent, "child": child}))
        sock.settimeout(None)
        return sock

    recorder = Recorder()
    sent: dict[int, int] = {}  # hello command id -> time sent (ns)
    stop = threading.Event()
    # The daemon closed the connection: said in REPORT; the next RESET connects again.
    disconnected = threading.Event()
    again = threading.Event()
    lock = threading.Lock()
    current = [connect()]

    def hellos() -> None:
        next_id = 100
        period = 1.0 / hello_hz
        while not stop.wait(period):  # sleeps between hellos, never spins
            if disconnected.is_set():
                continue
            next_id += 1
            with lock:
                sent[next_id] = time.time_ns()
            try:
                current[0].sendall(command(next_id, "hello", {}))
            except OSError:
                pass

    def report() -> dict[str, Any]:
        out = recorder.report()
        out["disconnected"] = disconnected.is_set()
        now = time.time_ns()
        with lock:
            waiting = [now - t for t in sent.values() if t >= recorder.since]
        out["hello_unanswered"] = {"n": len(waiting),
                                   "oldest_ms": max(waiting, default=0) / 1e6}
        return out

    def commands() -> None:
        for line in sys.stdin:
            word = line.strip()
            if word == "RESET":
                if disconnected.is_set():
                    again.set()
                recorder.reset()
                with lock:
                    sent.clear()
            elif word == "REPORT":
                print(json.dumps(report()), flush=True)
            elif word == "QUIT":
                break
        stop.set()
        again.set()
        current[0].close()

    threading.Thread(target=commands, daemon=True).start()
    threading.Thread(target=hellos, daemon=True).start()
    print("READY", flush=True)
    while not stop.is_set():
        _watch_connection(current[0], recorder, sent, lock)
        disconnected.set()
        again.wait()
        again.clear()
        if not stop.is_set():
            current[0] = connect()
            disconnected.clear()


def _watch_connection(sock: socket.socket, recorder: Recorder, sent: dict[int, int],
                      lock: threading.Lock) -> None:
    """Read one watcher connection until the daemon closes it: tf arrivals and hello
    answers into ``recorder``."""
    buffer = bytearray()
    unpack = _HEADER.unpack_from
    size = _HEADER.size
    device = b""
    while True:
        try:
            chunk = sock.recv(1 << 20)
        except OSError:
            return
        arrival = time.time_ns()
        if not chunk:
            return
        buffer += chunk
        offset = 0
        while len(buffer) - offset >= size:
            version, type_raw, name_raw, stamp, body_size, _ = unpack(buffer, offset)
            end = offset + size + body_size
            if end > len(buffer):
                break
            body = offset + size
            offset = end
            if type_raw.startswith(b"TRANSFORM") and name_raw.rstrip(b"\0") == device:
                with recorder.lock:
                    recorder.add("tf", arrival, _stamp_ns(stamp))
            elif type_raw.startswith(b"RTS_COMMAND"):
                content = body + (12 if version == 2 else 0)  # extended header
                command_id = struct.unpack_from(">I", buffer, content)[0]
                if command_id == 1:
                    length = struct.unpack_from(">I", buffer, content + 134)[0]
                    text = bytes(buffer[content + 138:content + 138 + length])
                    device = json.loads(text)["result"]["device"].encode()
                    continue
                with lock:
                    started = sent.pop(command_id, None)
                if started is not None:
                    with recorder.lock:
                        recorder.add("hello", arrival, started)
        del buffer[:offset]


# ------------------------------------------------------------------------------ ROS side


def _ros_setup() -> Any:
    import rclpy

    rclpy.init()
    return rclpy.create_node(f"bench_peer_{os.getpid()}")


def _message(kind: str) -> tuple[Any, Any, Callable[[Any, int], None]]:
    """(message class, a template message, set_stamp(msg, n))."""
    from builtin_interfaces.msg import Time

    def header_stamp(msg: Any, now: int) -> None:
        msg.header.stamp = Time(sec=now // _NS, nanosec=now % _NS)

    if kind == "pose":
        from geometry_msgs.msg import PoseStamped

        pose = PoseStamped()
        pose.header.frame_id = "world"
        pose.pose.position.x = 0.0031415
        pose.pose.orientation.w = 1.0
        return PoseStamped, pose, header_stamp
    if kind == "image":
        import numpy as np
        from sensor_msgs.msg import Image

        image = Image(height=480, width=640, encoding="rgb8", step=640 * 3)
        image.header.frame_id = "camera"
        image.data = np.random.default_rng(0).integers(0, 255, 640 * 480 * 3,
                                                        dtype=np.uint8).tobytes()
        return Image, image, header_stamp
    if kind == "tf":
        from geometry_msgs.msg import TransformStamped
        from tf2_msgs.msg import TFMessage

        names = ["base"] + [f"link{i}" for i in range(1, 8)]
        message = TFMessage(transforms=[TransformStamped() for _ in range(7)])
        for t, parent, child in zip(message.transforms, names, names[1:]):
            t.header.frame_id, t.child_frame_id = parent, child
            t.transform.translation.z = 0.1
            t.transform.rotation.w = 1.0
        tick = [0]

        def tf_stamp(msg: Any, now: int) -> None:
            tick[0] += 1
            stamp = Time(sec=now // _NS, nanosec=now % _NS)
            for t in msg.transforms:  # every link moves 10 um a tick: every lookup changes
                t.header.stamp = stamp
                t.transform.translation.x = tick[0] * 1e-5

        return TFMessage, message, tf_stamp
    if kind == "cloud":
        from sensor_msgs.msg import PointCloud2

        return PointCloud2, organised_cloud(), header_stamp
    raise SystemExit(f"unknown kind {kind!r}: expected pose, image, tf or cloud")


# An organised depth-camera cloud: VGA, and the share of its pixels with no return.
CLOUD_WIDTH, CLOUD_HEIGHT = 640, 480
CLOUD_NAN_SHARE = 0.1


def organised_cloud() -> Any:
    """A 640x480 organised PointCloud2 as a depth camera's driver publishes it through PCL:
    x, y, z and a packed ``rgb`` float32 (0x00RRGGBB in its bytes), point_step 16, not
    dense: a tenth of the pixels (edges and scattered ones) have no return, x = y = z = NaN."""
    import numpy as np
    from sensor_msgs.msg import PointCloud2, PointField

    h, w = CLOUD_HEIGHT, CLOUD_WIDTH
    rng = np.random.default_rng(0)
    v, u = np.mgrid[0:h, 0:w].astype(np.float32)
    depth = 1.0 + 0.5 * rng.random((h, w), dtype=np.float32)  # m
    table = np.zeros((h, w), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])
    fx = fy = 525.0  # a VGA depth camera's focal length, pixels
    table["x"] = (u - w / 2) * depth / fx
    table["y"] = (v - h / 2) * depth / fy
    table["z"] = depth
    colour = rng.integers(0, 256, (h, w, 3), dtype=np.uint32)
    table["rgb"] = (colour[..., 0] << 16) | (colour[..., 1] << 8) | colour[..., 2]
    holes = rng.random((h, w)) < CLOUD_NAN_SHARE
    for name in ("x", "y", "z"):
        table[name][holes] = np.nan
    cloud = PointCloud2(height=h, width=w, is_bigendian=False, point_step=16,
                        row_step=16 * w, is_dense=False)
    cloud.header.frame_id = "camera_depth_optical_frame"
    cloud.fields = [PointField(name=name, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                    for i, name in enumerate(("x", "y", "z", "rgb"))]
    cloud.data.frombytes(table.tobytes())
    return cloud


def publish(kind: str, topic: str) -> None:
    node = _ros_setup()
    cls, message, set_stamp = _message(kind)
    depth = 10 if kind in _BULK else POSE_DEPTH
    publisher = node.create_publisher(cls, topic, depth)
    print("READY", flush=True)
    for line in sys.stdin:
        parts = line.split()
        if parts and parts[0] == "WAIT":  # WAIT N: until N subscribers matched
            deadline = time.monotonic() + 30
            while (publisher.get_subscription_count() < int(parts[1])
                   and time.monotonic() < deadline):
                time.sleep(0.01)
            print(f"MATCHED {publisher.get_subscription_count()}", flush=True)
        elif parts and parts[0] == "RUN":
            rate, seconds = float(parts[1]), float(parts[2])
            burst = int(parts[3]) if len(parts) > 3 else 1
            count = int(rate * seconds)
            period = 1.0 / rate
            start = time.monotonic()
            for n in range(count):
                if n % burst == 0:  # the next burst is due (every message, without BURST)
                    delay = start + n * period - time.monotonic()
                    if delay > 0:
                        time.sleep(delay)
                set_stamp(message, time.time_ns())
                publisher.publish(message)
            print(f"DONE {count}", flush=True)
        elif parts and parts[0] == "QUIT":
            break
    node.destroy_node()


def floor(kind: str, topic: str) -> None:
    import rclpy
    from rclpy.executors import ExternalShutdownException

    node = _ros_setup()
    cls, _, _ = _message(kind)
    recorder = Recorder()

    def on_message(msg: Any) -> None:
        arrival = time.time_ns()
        if kind == "tf" and (not msg.transforms or msg.transforms[0].child_frame_id != "link1"):
            return  # another publisher's /tf (a storm's): not the stream measured
        stamp = msg.header.stamp if kind != "tf" else msg.transforms[0].header.stamp
        with recorder.lock:
            recorder.add(kind, arrival, stamp.sec * _NS + stamp.nanosec)

    node.create_subscription(cls, topic, on_message, 10 if kind in _BULK else POSE_DEPTH)
    # QUIT ends the spin through the context: the participant is then destroyed, and Fast
    # DDS removes its shared-memory segment (an exit that skips it leaves 0.5 MB in /dev/shm).
    threading.Thread(target=_serve_commands, args=(recorder, rclpy.shutdown),
                     daemon=True).start()
    print("READY", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    node.destroy_node()
    rclpy.try_shutdown()


def facade(port: int, topic: str, cloud: bool = False) -> None:
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import slicer_client

    received = [0]
    ros = slicer_client.connect("127.0.0.1", port)
    # As a script in Slicer would: the reference's CamelCase API, an observer that reads
    # the node's last message each time it is told of one.
    node = ros.GetDefaultROS2Node().CreateAndAddSubscriberNode(
        "sensor_msgs/msg/PointCloud2" if cloud else "PoseStamped", topic)

    def on_modified(caller: Any, event: str) -> None:
        received[0] += 1
        if not cloud:
            node.GetLastMessage()

    node.AddObserver("ModifiedEvent", on_modified)
    print("READY", flush=True)
    for line in sys.stdin:
        word = line.strip()
        if word == "REPORT":
            print(json.dumps({"received": received[0],
                              "messages": node.GetNumberOfMessages()}), flush=True)
        elif word == "QUIT":
            break
    ros.close()


def callback(port: int, topic: str) -> None:
    """A Pythonic subscriber whose callback records publish -> callback latency: the stamp
    of the newest message the client holds when the callback runs."""
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import slicer_client

    recorder = Recorder()
    ros = slicer_client.connect("127.0.0.1", port)
    pose = ros.subscribe(topic, "PoseStamped")

    def on_pose(value: Any) -> None:
        arrival = time.time_ns()
        message = pose.last_message
        if message is not None:
            with recorder.lock:
                recorder.add("callback", arrival, _stamp_ns(message.timestamp))

    pose.add_callback(on_pose)
    stop = threading.Event()
    print("READY", flush=True)
    _serve_commands(recorder, stop.set)
    ros.close()


def naive_callback(port: int, device: str) -> None:
    """The naive relay's user: pyigtl's client, a loop on `wait_for_message` (which polls
    every 10 ms while nothing waits), recording publish -> the message in the user's hands."""
    import pyigtl

    recorder = Recorder()
    client = pyigtl.OpenIGTLinkClient(port=port)
    stop = threading.Event()

    def receive() -> None:
        while not stop.is_set():
            message = client.wait_for_message(device, timeout=0.5)
            if message is not None:
                arrival = time.time_ns()
                with recorder.lock:
                    recorder.add("callback", arrival, int(message.timestamp * _NS))

    threading.Thread(target=receive, daemon=True).start()
    print("READY", flush=True)
    _serve_commands(recorder, stop.set)
    client.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="role", required=True)
    for role in ("publish", "floor"):
        p = sub.add_parser(role)
        p.add_argument("kind", choices=("pose", "image", "tf", "cloud"))
        p.add_argument("topic")
    p = sub.add_parser("read")
    p.add_argument("port", type=int)
    p.add_argument("clients", type=int)
    p.add_argument("--setup", default="[]", help="JSON list of {op, arguments} to run first")
    p.add_argument("--v1", action="store_true", help="do not announce header v2 (pyigtl)")
    p = sub.add_parser("watch")
    p.add_argument("port", type=int)
    p.add_argument("parent")
    p.add_argument("child")
    p.add_argument("--hello-hz", type=float, default=10.0)
    p = sub.add_parser("facade")
    p.add_argument("port", type=int)
    p.add_argument("topic")
    p.add_argument("--cloud", action="store_true",
                   help="a PointCloud2 subscriber node (else PoseStamped)")
    p = sub.add_parser("callback")
    p.add_argument("port", type=int)
    p.add_argument("topic")
    p = sub.add_parser("naive-callback")
    p.add_argument("port", type=int)
    p.add_argument("device")
    args = parser.parse_args()
    if args.role == "publish":
        publish(args.kind, args.topic)
    elif args.role == "floor":
        floor(args.kind, args.topic)
    elif args.role == "watch":
        watch(args.port, args.parent, args.child, args.hello_hz)
    elif args.role == "facade":
        facade(args.port, args.topic, args.cloud)
    elif args.role == "callback":
        callback(args.port, args.topic)
    elif args.role == "naive-callback":
        naive_callback(args.port, args.device)
    else:
        read(args.port, args.clients, json.loads(args.setup), not args.v1)


if __name__ == "__main__":
    main()
