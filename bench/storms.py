"""The storms of issue 22, for bench/attacks.py: ROS peers and clients that load the daemon
while another client (bench/peers.py ``watch``, its own process) streams a 100 Hz tf
lookup and sends ``hello``. Each storm is bounded in time and size, on 127.0.0.1 only.

The ROS peers run as their own processes (``python bench/storms.py peer KIND ...``) and
sleep between messages; the client-side attacks run in the bench's process, on raw
sockets (bench/raw_client.py).

    marker_storm  a ROS peer re-sends 20 SPHERE_LIST markers of 1,250 random points each
                  (one MarkerArray, ~0.6 MB) every 0.3 s; a client shows that topic
    marker_bomb   a client publishes 12 SPHERE_LIST markers of the largest size allowed
                  (23,809 points, 0.8 MB of JSON each) to a topic it shows; then
                  list_markers
    marker_bomb_ros  a ROS peer sends 30 such markers to a topic a client shows
    polydata      a client sends four 60 MB POLYDATA bodies with mixed-size cells, to a
                  device no publisher receives, then to a shape_msgs/Mesh publisher's
    tf_frames     a ROS peer sends 300 transforms with 1 MB frame ids, then 100,000 new
                  frames; then list_bridges is asked 20 times in a row
    service_slots a client calls 64 absent services (120 s timeout each); another client
                  calls a live service meanwhile; the first one leaves
"""

from __future__ import annotations

import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Callable

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from bench.raw_client import CommandFailed, RawSession  # noqa: E402

__all__ = ["STORMS", "Peer", "peer_main"]

MARKER_STORM_TOPIC = "/storm_markers"
BOMB_TOPIC = "/bomb_markers"
BOMB_ROS_TOPIC = "/bomb_ros_markers"
MAX_LIST_POINTS = 23_809  # MAX_MODEL_POINTS // 42: the largest SPHERE_LIST a daemon meshes
SPHERE_LIST = 7
TRIGGER = "std_srvs/srv/Trigger"


class Peer:
    """A ROS peer of this module (``peer KIND ARGS``) as a child process; its output in a
    log file; `wait_for` a line, `stop` it (and its process group)."""

    def __init__(self, env: dict[str, str], logs: Path, kind: str, *args: str) -> None:
        self.log = logs / f"peer-{kind}-{time.monotonic_ns()}.log"
        self.popen = subprocess.Popen([sys.executable, "-u", __file__, "peer", kind, *args],
                                      env=env, cwd=str(REPO), stdin=subprocess.DEVNULL,
                                      stdout=self.log.open("wb"), stderr=subprocess.STDOUT,
                                      start_new_session=True)

    def wait_for(self, word: str, timeout: float = 60.0) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            text = self.log.read_text(errors="replace")
            for line in text.splitlines():
                if line.startswith(word):
                    return line
            if self.popen.poll() is not None:
                raise RuntimeError(f"peer exited before {word}: {text[-2000:]}")
            time.sleep(0.05)
        raise TimeoutError(f"peer did not print {word} within {timeout} s")

    def stop(self) -> None:
        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGINT)
            try:
                self.popen.wait(10)
            except subprocess.TimeoutExpired:
                pass
        try:
            os.killpg(self.popen.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        self.popen.wait()


# ------------------------------------------------------------------------- storms


def marker_storm(port: int, env: dict[str, str], logs: Path, seconds: float,
                 started: Callable[[], None]) -> dict[str, Any]:
    shower = RawSession(port, name="marker shower")
    try:
        shower.command("create_marker_subscriber", {"topic": MARKER_STORM_TOPIC,
                                                    "type": "MarkerArray",
                                                    "fixed_frame": "world"})
        peer = Peer(env, logs, "marker-storm", MARKER_STORM_TOPIC, str(seconds))
        try:
            peer.wait_for("READY")
            started()
            sent = int(peer.wait_for("SENT", timeout=seconds + 60).split()[1])
        finally:
            peer.stop()
        listed = shower.command("list_markers", {"topic": MARKER_STORM_TOPIC})
        shower.command("remove_marker_subscriber", {"topic": MARKER_STORM_TOPIC})
        return {"arrays_sent": sent, "live_markers": len(listed["markers"]),
                "shower_got_mb": round(shower.received.bytes / 1e6, 1),
                "shower_connected": not shower.closed.is_set()}
    finally:
        shower.close()


def _sphere_list(marker_id: int, points: int, seed: int) -> dict[str, Any]:
    import numpy as np

    xyz = np.random.default_rng(seed).random((points, 3))
    return {"header": {"frame_id": "world"}, "ns": "bomb", "id": marker_id,
            "type": SPHERE_LIST, "action": 0, "pose": {"orientation": {"w": 1.0}},
            "scale": {"x": 0.01, "y": 0.01, "z": 0.01}, "color": {"r": 1.0, "a": 1.0},
            "points": [{"x": round(float(x), 4), "y": round(float(y), 4),
                        "z": round(float(z), 4)} for x, y, z in xyz]}


def marker_bomb(port: int, env: dict[str, str], logs: Path, seconds: float,
                started: Callable[[], None]) -> dict[str, Any]:
    bomber = RawSession(port, name="marker bomber")
    try:
        bomber.command("create_marker_subscriber", {"topic": BOMB_TOPIC, "type": "Marker",
                                                    "fixed_frame": "world"})
        bomber.command("create_publisher", {"topic": BOMB_TOPIC,
                                            "type": "visualization_msgs/msg/Marker"})
        # Built first (the bench's own CPU is not part of the attack): then sent, each
        # one as soon as the previous one is answered.
        commands = [_command_bytes(k + 1000, "publish", {
            "topic": BOMB_TOPIC, "value": _sphere_list(k, MAX_LIST_POINTS, k)})
            for k in range(12)]
        started()
        took = []
        for k, data in enumerate(commands):
            start = time.monotonic()
            bomber.send(data)
            reply = bomber.reply(k + 1000, timeout=120)
            if reply is None or not reply["ok"]:
                raise CommandFailed("publish", (reply or {}).get("error") or {"name": "none"})
            took.append(time.monotonic() - start)
        shown = _wait_listed(bomber, BOMB_TOPIC, 12, seconds)
        start = time.monotonic()
        bomber.command("list_markers", {"topic": BOMB_TOPIC}, timeout=60)
        listing = time.monotonic() - start
        bomber.command("remove_marker_subscriber", {"topic": BOMB_TOPIC})
        bomber.command("remove_publisher", {"topic": BOMB_TOPIC})
        return {"publish_s_max": round(max(took), 3), "live_markers": shown,
                "list_markers_s": round(listing, 3),
                "refusals": _marker_refusals(bomber)}
    finally:
        bomber.close()


def marker_bomb_ros(port: int, env: dict[str, str], logs: Path, seconds: float,
                    started: Callable[[], None]) -> dict[str, Any]:
    shower = RawSession(port, name="marker shower")
    try:
        shower.command("create_marker_subscriber", {"topic": BOMB_ROS_TOPIC,
                                                    "type": "Marker", "fixed_frame": "world"})
        peer = Peer(env, logs, "marker-bomb", BOMB_ROS_TOPIC, "30")
        try:
            peer.wait_for("READY")
            started()
            peer.wait_for("SENT", timeout=120)
        finally:
            peer.stop()
        shown = _wait_listed(shower, BOMB_ROS_TOPIC, 30, seconds)
        shower.command("remove_marker_subscriber", {"topic": BOMB_ROS_TOPIC})
        return {"markers_sent": 30, "live_markers": shown,
                "refusals": _marker_refusals(shower)}
    finally:
        shower.close()


def _wait_listed(session: RawSession, topic: str, want: int, seconds: float) -> int:
    """Live markers of ``topic`` once ``want`` are live or the count stops moving."""
    deadline = time.monotonic() + seconds
    last, since = -1, time.monotonic()
    while time.monotonic() < deadline:
        listed = session.command("list_markers", {"topic": topic}, timeout=60)
        count = len(listed["markers"]) + len(listed["errors"])
        if count >= want:
            return len(listed["markers"])
        if count != last:
            last, since = count, time.monotonic()
        elif time.monotonic() - since > 5:
            break
        time.sleep(0.5)
    return len(session.command("list_markers", {"topic": topic}, timeout=60)["markers"])


def _command_bytes(command_id: int, op: str, arguments: dict[str, Any]) -> bytes:
    import json

    from protocol.framing import encode
    from protocol.messages import Command, Message

    return encode(Message("bench", Command(command_id=command_id, name=op,
                                           text=json.dumps(arguments))), header_version=2)


def _marker_refusals(session: RawSession) -> list[str]:
    return sorted({text[:160] for _, _, text in session.received.statuses})[:3]


def _mixed_cells_polydata(device: str, body_bytes: int) -> bytes:
    """One POLYDATA of about ``body_bytes`` whose vertex cells alternate 1 and 2 indices."""
    import numpy as np

    from protocol.framing import encode
    from protocol.messages import Message, RawBody

    pairs = body_bytes // 20  # a 1-index cell (8 bytes) and a 2-index cell (12 bytes)
    cells = np.empty((pairs, 5), dtype=">u4")
    cells[:, 0], cells[:, 1], cells[:, 2], cells[:, 3], cells[:, 4] = 1, 0, 2, 0, 1
    points = np.zeros((2, 3), dtype=">f4")
    head = struct.pack(">10I", 2, 2 * pairs, cells.nbytes, 0, 0, 0, 0, 0, 0, 0)
    content = head + points.tobytes() + cells.tobytes()
    return encode(Message(device, RawBody("POLYDATA", content)), header_version=1)


def polydata(port: int, env: dict[str, str], logs: Path, seconds: float,
             started: Callable[[], None]) -> dict[str, Any]:
    sender = RawSession(port, name="polydata sender")
    try:
        device = sender.command("create_publisher", {"topic": "/storm_mesh",
                                                     "type": "shape_msgs/msg/Mesh"})["device"]
        out: dict[str, Any] = {}
        bodies = [(label, _mixed_cells_polydata(target, 60_000_000))
                  for label, target in (("unrouted", "nowhere"), ("publisher", device))]
        started()
        for label, body in bodies:
            before = len(sender.received.statuses)
            start = time.monotonic()
            for _ in range(4):
                sender.send(body)
            deadline = time.monotonic() + seconds
            while (len(sender.received.statuses) < before + (1 if label == "unrouted" else 4)
                   and time.monotonic() < deadline and not sender.closed.is_set()):
                time.sleep(0.05)
            told = sender.received.statuses[before:]
            out[label] = {"statuses": len(told), "told_s": round(time.monotonic() - start, 2),
                          "first": told[0][2][:120] if told else None}
        sender.command("remove_publisher", {"topic": "/storm_mesh"})
        return out
    finally:
        sender.close()


def tf_frames(port: int, env: dict[str, str], logs: Path, seconds: float,
              started: Callable[[], None]) -> dict[str, Any]:
    lister = RawSession(port, name="lister")
    try:
        peer = Peer(env, logs, "tf-frames")
        try:
            peer.wait_for("READY")
            started()
            peer.wait_for("SENT", timeout=300)
        finally:
            peer.stop()
        took = []
        for _ in range(20):
            start = time.monotonic()
            listed = lister.command("list_bridges", {}, timeout=120)
            took.append(time.monotonic() - start)
        frames = listed["tf_buffer"]["frames"]
        return {"frames_listed": len(frames), "longest_frame": max(map(len, frames)),
                "list_bridges_s_max": round(max(took), 3)}
    finally:
        lister.close()


def service_slots(port: int, env: dict[str, str], logs: Path, seconds: float,
                  started: Callable[[], None]) -> dict[str, Any]:
    server = Peer(env, logs, "trigger-server", "/storm_live")
    hog, other = RawSession(port, name="hog"), RawSession(port, name="other")
    try:
        server.wait_for("READY")
        started()
        ids = [hog.send_command("call_service", {"service": f"/absent_{i}", "type": TRIGGER,
                                                 "request": {}, "timeout": 120})
               for i in range(64)]
        refused = 0
        for command_id in ids:
            reply = hog.reply(command_id, timeout=0.5)
            refused += reply is not None and not reply["ok"]
        start = time.monotonic()
        try:
            other.command("call_service", {"service": "/storm_live/trigger", "type": TRIGGER,
                                           "request": {}, "timeout": 20}, timeout=30)
            answer = "ok"
        except CommandFailed as error:
            answer = str(error.error.get("name"))
        call_s = time.monotonic() - start
        hog.close()
        start = time.monotonic()
        waiting = -1
        while time.monotonic() - start < seconds:
            clients = other.command("list_bridges", {})["service_clients"]
            waiting = sum(c.get("waiting", 0) for c in clients)
            if waiting == 0:
                break
            time.sleep(0.2)
        return {"hog_refused": refused, "other_call": answer,
                "other_call_s": round(call_s, 3), "waiting_after_hog_left": waiting,
                "freed_s": round(time.monotonic() - start, 2)}
    finally:
        other.close()
        hog.close()
        server.stop()


Storm = Callable[[int, dict[str, str], Path, float, Callable[[], None]], dict[str, Any]]
STORMS: dict[str, Storm] = {
    "marker_storm": marker_storm, "marker_bomb": marker_bomb,
    "marker_bomb_ros": marker_bomb_ros, "polydata": polydata, "tf_frames": tf_frames,
    "service_slots": service_slots,
}


# ------------------------------------------------------------------------- ROS peers


def _node(name: str) -> Any:
    import rclpy

    rclpy.init()
    return rclpy.create_node(name)


def _ready_publisher(node_name: str, cls: Any, topic: str, depth: int) -> Any:
    """A publisher of a new node, once the daemon's subscription has matched it (then
    nothing is lost to discovery); says READY."""
    node = _node(node_name)
    publisher = node.create_publisher(cls, topic, depth)
    deadline = time.monotonic() + 30.0
    while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.02)
    print("READY", flush=True)
    return publisher


def _marker(marker_id: int, points: Any) -> Any:
    from geometry_msgs.msg import Point
    from visualization_msgs.msg import Marker

    marker = Marker(type=SPHERE_LIST, id=marker_id, ns="storm")
    marker.header.frame_id = "world"
    marker.pose.orientation.w = 1.0
    marker.scale.x = marker.scale.y = marker.scale.z = 0.01
    marker.color.r = marker.color.a = 1.0
    marker.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in points]
    return marker


def _peer_marker_storm(topic: str, seconds: float) -> None:
    import numpy as np
    from visualization_msgs.msg import MarkerArray

    publisher = _ready_publisher("storm_marker_peer", MarkerArray, topic, 10)
    rng = np.random.default_rng(1)
    start, sent = time.monotonic(), 0
    while time.monotonic() - start < seconds:
        due = start + sent * 0.3
        if due > time.monotonic():
            time.sleep(due - time.monotonic())
        publisher.publish(MarkerArray(markers=[_marker(i, rng.random((1250, 3)))
                                               for i in range(20)]))
        sent += 1
    print(f"SENT {sent}", flush=True)


def _peer_marker_bomb(topic: str, count: int) -> None:
    import numpy as np
    from visualization_msgs.msg import Marker

    publisher = _ready_publisher("storm_bomb_peer", Marker, topic, 50)
    rng = np.random.default_rng(2)
    for k in range(count):
        publisher.publish(_marker(k, rng.random((MAX_LIST_POINTS, 3))))
        time.sleep(0.2)
    print(f"SENT {count}", flush=True)
    time.sleep(2.0)  # a reliable writer resends what was lost before it goes


def _peer_tf_frames() -> None:
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage

    publisher = _ready_publisher("storm_tf_peer", TFMessage, "/tf", 100)

    def batch(names: list[str]) -> TFMessage:
        stamp = Time(sec=int(time.time()))
        out = []
        for name in names:
            t = TransformStamped(child_frame_id=name)
            t.header.frame_id, t.header.stamp = "world", stamp
            t.transform.rotation.w = 1.0
            out.append(t)
        return TFMessage(transforms=out)

    for k in range(30):  # 300 ids of 1 MB, ten a message
        publisher.publish(batch([f"{k * 10 + i:04d}" + "x" * 1_000_000 for i in range(10)]))
        time.sleep(0.1)
    for k in range(100):  # 100,000 new small ids, a thousand a message
        publisher.publish(batch([f"frame_{k}_{i}" for i in range(1000)]))
        time.sleep(0.02)
    print("SENT 100300", flush=True)
    time.sleep(2.0)


def _peer_trigger_server(namespace: str) -> None:
    import rclpy
    from std_srvs.srv import Trigger

    node = _node("storm_trigger_server")
    node.create_service(Trigger, f"{namespace}/trigger",
                        lambda request, response: Trigger.Response(success=True))
    print("READY", flush=True)
    rclpy.spin(node)


def peer_main(kind: str, args: list[str]) -> int:
    from rclpy.executors import ExternalShutdownException

    try:
        if kind == "marker-storm":
            _peer_marker_storm(args[0], float(args[1]))
        elif kind == "marker-bomb":
            _peer_marker_bomb(args[0], int(args[1]))
        elif kind == "tf-frames":
            _peer_tf_frames()
        elif kind == "trigger-server":
            _peer_trigger_server(args[0])
        else:
            raise SystemExit(f"unknown peer {kind!r}")
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    return 0


def run_storm(name: str, port: int, env: dict[str, str], logs: Path, seconds: float, *,
              started: Callable[[], None]) -> dict[str, Any]:
    """One storm (``started()`` is called once its set-up is done and the attack proper
    begins); a failure is a figure too (what broke, instead of a result)."""
    try:
        return STORMS[name](port, env, logs, seconds, started)
    except (OSError, TimeoutError, CommandFailed, RuntimeError) as error:
        return {"failed": f"{type(error).__name__}: {error}"}


if __name__ == "__main__":
    if sys.argv[1:2] == ["peer"]:
        sys.exit(peer_main(sys.argv[2], sys.argv[3:]))
    raise SystemExit(__doc__)
