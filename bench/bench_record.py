"""Recording 1 kHz PoseStamped + 30 Hz VGA images: the daemon's recording beside a plain
rclpy subscriber writing the same bag with the same library, in the same run.

What runs (each its own process): two publishers that sleep between messages
(bench/peers.py publish pose|image); the daemon (`slicer-ros2-bridge run`), serving both
topics to a client (this script, a slicer_client subscriber of each) and recording what it
bridges (``ros.record``, the ``start_recording`` op); the floor: this script's ``floor``
mode, a plain rclpy node whose raw subscriptions' callbacks write each message with
Foxglove's mcap Writer (the library the daemon uses), spun by rclpy.

Figures: messages in each bag / messages sent, per topic (read back from the bags'
summaries), drops the daemon counted, and the CPU seconds each process spent during the
run (the daemon's include serving the client and its own bridges); first, the same streams
through the daemon serving the client without recording: what recording adds is the
difference.

usage: python bench/bench_record.py [--seconds 20] [--pose-hz 1000] [--image-hz 30] [--tf]
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from bench_daemon import PEERS, Child, free_port, load  # noqa: E402

IMAGE_TOPIC = "/bench_record_image"
# The fast stream: PoseStamped on a topic of its own, or --tf: a TFMessage of 7 transforms
# on /tf (the daemon's tf buffer takes it too, and the client streams a lookup of it).
STREAMS = {"pose": ("/bench_record_pose", "geometry_msgs/msg/PoseStamped"),
           "tf": ("/tf", "tf2_msgs/msg/TFMessage")}


def types(kind: str) -> dict[str, str]:
    topic, ros_type = STREAMS[kind]
    return {topic: ros_type, IMAGE_TOPIC: "sensor_msgs/msg/Image"}


def floor(out: str, kind: str) -> None:
    """A plain rclpy recorder: raw subscriptions, each callback writes with mcap."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.qos import QoSProfile
    from mcap.writer import CompressionType, Writer

    from bridge.codecs.registry import message_class
    from bridge.record.definitions import full_definition

    rclpy.init()
    node = rclpy.create_node("bench_record_floor")
    stream = open(out, "wb")
    writer = Writer(stream, compression=CompressionType.NONE)
    writer.start(profile="ros2", library="bench floor")
    lock = threading.Lock()
    for topic, ros_type in types(kind).items():
        schema = writer.register_schema(ros_type, "ros2msg", full_definition(ros_type).encode())
        channel = writer.register_channel(topic, "cdr", schema)

        def write(data: bytes, channel: int = channel) -> None:
            now = time.time_ns()
            with lock:
                writer.add_message(channel, now, data, now)
        depth = 30 if topic == IMAGE_TOPIC else 1000
        node.create_subscription(message_class(ros_type), topic, write,
                                 QoSProfile(depth=depth), raw=True)

    def commands() -> None:
        for line in sys.stdin:
            if line.strip() == "QUIT":
                break
        rclpy.shutdown()
    threading.Thread(target=commands, daemon=True).start()
    print("READY", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    with lock:
        writer.finish()
    stream.close()
    print("FINISHED", flush=True)


def drain(child: Child) -> None:
    for _ in child.popen.stdout or ():  # the daemon's log, read so that it never blocks
        pass


def bag_counts(path: Path) -> dict[str, int]:
    from mcap.reader import make_reader

    with path.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and summary.statistics is not None
    channels = {cid: c.topic for cid, c in summary.channels.items()}
    return {channels[cid]: n for cid, n in summary.statistics.channel_message_counts.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--pose-hz", type=float, default=1000.0)
    parser.add_argument("--image-hz", type=float, default=30.0)
    parser.add_argument("--tf", action="store_true",
                        help="the fast stream is /tf (7 transforms a message), not poses")
    parser.add_argument("--floor", metavar="OUT", help=argparse.SUPPRESS)
    args = parser.parse_args()
    kind = "tf" if args.tf else "pose"
    if args.floor:
        floor(args.floor, kind)
        return
    import slicer_client

    folder = Path(tempfile.mkdtemp(prefix="bench-record-"))
    port = free_port()
    daemon = Child("daemon", [sys.executable, "-m", "bridge.cli", "run", "--port", str(port)],
                   "listening on")
    threading.Thread(target=drain, args=(daemon,), daemon=True).start()
    children = [daemon]
    try:
        fast, _ = STREAMS[kind]
        poses = Child(f"{kind} publisher", [sys.executable, str(PEERS), "publish", kind, fast])
        images = Child("image publisher", [sys.executable, str(PEERS), "publish", "image",
                                           IMAGE_TOPIC])
        children += [poses, images]
        received = {fast: 0, IMAGE_TOPIC: 0}
        ros = slicer_client.connect("127.0.0.1", port)

        def count(topic: str) -> Any:
            return lambda value: received.__setitem__(topic, received[topic] + 1)
        if kind == "tf":
            ros.tf_lookup("base", "link7", callback=count(fast))
        else:
            ros.subscribe(fast, STREAMS[kind][1], callback=count(fast))
        ros.subscribe(IMAGE_TOPIC, "Image", callback=count(IMAGE_TOPIC))
        # First the daemon serving the client alone, no recording: what recording adds.
        for publisher in (poses, images):  # the daemon's bridge (tf: its buffer)
            publisher.ask("WAIT 1", "MATCHED", 40)
        before = daemon.cpu_seconds()
        poses.say(f"RUN {args.pose_hz} {args.seconds}")
        images.say(f"RUN {args.image_hz} {args.seconds}")
        for publisher in (poses, images):
            publisher.expect("DONE", args.seconds + 60)
        time.sleep(1.0)
        serving = daemon.cpu_seconds() - before
        ours = folder / "daemon.mcap"
        rec = ros.record(str(ours))
        deadline = time.monotonic() + 30
        while set(types(kind)) - set(rec.counts) and time.monotonic() < deadline:
            time.sleep(0.1)  # the recorder subscribes once the publishers are in the graph
        theirs = folder / "floor.mcap"
        plain = Child("floor", [sys.executable, __file__, "--floor", str(theirs),
                                *(["--tf"] if args.tf else [])])
        children.append(plain)
        for publisher in (poses, images):  # the daemon's bridge and recorder, the floor
            publisher.ask("WAIT 3", "MATCHED", 40)
        cpu = {child.name: child.cpu_seconds() for child in (daemon, plain)}
        poses.say(f"RUN {args.pose_hz} {args.seconds}")
        images.say(f"RUN {args.image_hz} {args.seconds}")
        sent = {fast: int(poses.expect("DONE", args.seconds + 60).split()[1]),
                IMAGE_TOPIC: int(images.expect("DONE", args.seconds + 60).split()[1])}
        time.sleep(1.0)  # what is in flight lands (the bags are read after, not timed)
        spent = {name: child.cpu_seconds() - cpu[name] for name, child in
                 (("daemon", daemon), ("floor", plain))}
        final = rec.stop(timeout=60)
        plain.say("QUIT")
        plain.expect("FINISHED", 60)
        ros.close()
        counts = {"daemon": bag_counts(ours), "floor": bag_counts(theirs)}
        report(args, fast, sent, counts, spent, final, received, serving)
    finally:
        for child in reversed(children):
            child.stop()
        shutil.rmtree(folder, ignore_errors=True)  # two bags of ~0.6 GB each


def report(args: argparse.Namespace, fast: str, sent: dict[str, int],
           counts: dict[str, dict[str, int]], spent: dict[str, float], final: dict[str, Any],
           received: dict[str, int], serving: float) -> None:
    what = "tf (7 transforms)" if args.tf else "PoseStamped"
    print(f"\nrecording {args.pose_hz:g} Hz {what} + {args.image_hz:g} Hz VGA rgb8 for "
          f"{args.seconds:g} s (load {load()}):")
    print(f"{'recorder':<40}{fast + ' in bag':>22}{'images in bag':>18}{'CPU s':>8}"
          f"{'CPU %':>7}")
    for name, label in (("daemon", "daemon (ros.record, serving 1 client)"),
                        ("floor", "plain rclpy + mcap Writer")):
        got = counts[name]
        cells = [f"{got.get(t, 0)}/{sent[t]} ({100 * got.get(t, 0) / sent[t]:.1f}%)"
                 for t in (fast, IMAGE_TOPIC)]
        print(f"{label:<40}{cells[0]:>22}{cells[1]:>18}{spent[name]:>8.2f}"
              f"{100 * spent[name] / args.seconds:>6.0f}%")
    print(f"{'daemon serving the client, no recording (before)':<80}{serving:>8.2f}"
          f"{100 * serving / args.seconds:>6.0f}%")
    print(f"daemon's drops counted: {final['dropped']}; its client received "
          f"{received[fast]} {'lookups' if args.tf else 'poses'}, {received[IMAGE_TOPIC]} "
          f"images")
    print(json.dumps({"sent": sent, "bags": counts, "cpu_s": spent, "serving_cpu_s": serving,
                      "dropped": final["dropped"]}))


if __name__ == "__main__":
    main()
