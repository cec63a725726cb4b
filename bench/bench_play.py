"""`slicer-ros2-bridge play`, measured from outside (issue 45), each figure beside its
baseline in the same run:

1. the fastest rate it holds playing a long bag of 1 kHz /tf (rosbags-written) to a raw
   OpenIGTLink client with a tf lookup streaming: at each rate, after --window s of wall
   time, how far the stamps the client received trail the player's clock (held: by at most
   0.1 s of wall time); baselines: the library alone (mcap + mcap-ros2-support) reading and
   decoding every message of the bag as fast as it can, and mcap reading it without
   decoding, each as a multiple of real time;
2. the player's memory (VmRSS, and VmHWM its peak) after those runs; baseline: the peak of
   the library-alone process that read the whole bag;
3. time to the first robot: from starting `play` (the demo robot's bag) to a client holding
   every link's TRANSFORM and every mesh; baseline: a process that only opens the bag,
   reads the description and loads the robot model (no serving);
4. a seek to 90 % of the long bag, until its reply (sent once the state there is); baseline:
   the library reading the bag from its start up to there (what a seek without the index
   would cost).

usage: python bench/bench_play.py [--minutes 10] [--hz 1000] [--rates 1,2,5,10,20,50]
                                  [--window 3]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Optional

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))
sys.path.insert(0, str(REPO / "tests"))

from raw_client import RawSession  # noqa: E402

from protocol.conversions import igtl_timestamp_to_seconds  # noqa: E402

NS = 1_000_000_000
SEEK_FRACTION = 0.9  # the seek bench goes this far into the bag

LIBRARY_ALONE = """
import sys, time
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
start = time.perf_counter()
count = 0
decoders = {}
factory = DecoderFactory()
reached = None  # when the read got to the seek bench's target (a fraction of the bag)
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f)
    stats = reader.get_summary().statistics
    target = stats.message_start_time + float(sys.argv[2]) * (
        stats.message_end_time - stats.message_start_time)
    for schema, channel, message in reader.iter_messages(log_time_order=True):
        decode = decoders.get(channel.id)
        if decode is None:
            decode = decoders[channel.id] = factory.decoder_for(channel.message_encoding, schema)
        decode(message.data)
        count += 1
        if reached is None and message.log_time >= target:
            reached = time.perf_counter() - start
took = time.perf_counter() - start
start = time.perf_counter()  # the reading alone, no decoding: the player's own floor
with open(sys.argv[1], "rb") as f:
    for _ in make_reader(f).iter_messages(log_time_order=True):
        pass
read_only = time.perf_counter() - start
peak = [l for l in open("/proc/self/status") if l.startswith("VmHWM")][0].split()[1]
print(count, took, peak, reached, read_only)
"""

ROBOT_ALONE = """
import sys, time
start = time.perf_counter()
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from bridge.robots.model import load_robot
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f)
    for schema, channel, message in reader.iter_messages(topics=["/robot_description"]):
        text = DecoderFactory().decoder_for(channel.message_encoding, schema)(message.data).data
        break
model = load_robot(text, package_paths={sys.argv[2]: sys.argv[3]})
print(len(model.links), len(model.visuals), time.perf_counter() - start)
"""


def kb(pid: int, key: str) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(key):
            return int(line.split()[1])
    return 0


def start_player(*args: str) -> tuple[subprocess.Popen[str], int, float]:
    """A player on a free port; (process, port, seconds from start to listening)."""
    began = time.perf_counter()
    child = subprocess.Popen([sys.executable, "-u", "-m", "bridge.console", "play", *args,
                              "--port", "0", "--log-level", "WARNING"],
                             cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                             text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    # WARNING level hides the "listening" line: ask the OS for the port instead.
    port = 0
    while not port:
        if child.poll() is not None:
            raise SystemExit(f"play exited: {child.stdout.read() if child.stdout else ''}")
        port = _listening_port(child.pid)
        time.sleep(0.005)
    return child, port, time.perf_counter() - began


def _listening_port(pid: int) -> int:
    inodes = set()
    try:
        for fd in Path(f"/proc/{pid}/fd").iterdir():
            target = os.readlink(fd)
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    except OSError:
        return 0
    for line in Path("/proc/net/tcp").read_text().splitlines()[1:]:
        parts = line.split()
        if parts[3] == "0A" and parts[9] in inodes:  # LISTEN
            return int(parts[1].split(":")[1], 16)
    return 0


def stop(child: subprocess.Popen[str]) -> None:
    child.send_signal(2)
    try:
        child.wait(20)
    except subprocess.TimeoutExpired:
        child.kill()
        child.wait()


def bag_seconds(status: dict[str, Any]) -> float:
    return status["time"]["sec"] + status["time"]["nanosec"] / NS


def rates_held(bag: Path, rates: list[float], window: float, seek_to: float
               ) -> tuple[list[tuple[float, float, int]], float, subprocess.Popen[str]]:
    """(rate, lag in wall seconds at the window's end, messages received) per rate; how
    long a seek to ``seek_to`` s took to be answered (the state there sent); and the player
    (still running: its memory is read after)."""
    child, port, _ = start_player(str(bag), "--paused")
    session = RawSession(port, name="bench-play")
    session.command("create_tf_lookup", {"parent": "world", "child": "base_link"})
    rows = []
    for rate in rates:
        session.command("seek_playback", {"offset": 1.0})
        session.command("set_playback_rate", {"rate": rate})
        before = session.received.messages.get("TRANSFORM", 0)
        session.command("resume_playback")
        time.sleep(window)  # a bench: the wall time is what is measured
        status = session.command("playback_status")
        session.command("pause_playback")
        clock = bag_seconds(status)
        stamp = session.received.stamps.get("tf:world:base_link") or next(
            (v for k, v in session.received.stamps.items() if "base_link" in k), 0)
        got = igtl_timestamp_to_seconds(stamp) if stamp else 0.0
        lag_wall = max(clock - got, 0.0) / rate
        rows.append((rate, lag_wall, session.received.messages.get("TRANSFORM", 0) - before))
    began = time.perf_counter()
    session.command("seek_playback", {"offset": seek_to})
    seek_s = time.perf_counter() - began
    session.close()
    return rows, seek_s, child


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--hz", type=float, default=1000.0)
    parser.add_argument("--rates", default="1,2,5,10,20,50")
    parser.add_argument("--window", type=float, default=3.0)
    args = parser.parse_args()
    rates = [float(r) for r in args.rates.split(",")]
    from bags import write_robot_bag, write_tf_bag
    from bridge.robots.demo import demo_urdf_path
    from bridge.robots.demo.urdf import DEMO_PACKAGE

    with tempfile.TemporaryDirectory(prefix="bench-play-") as tmp:
        folder = Path(tmp) / "tf"
        began = time.perf_counter()
        count = sum(1 for _ in write_tf_bag(folder, seconds=args.minutes * 60, hz=args.hz))
        bag = folder / "tf.mcap"
        print(f"wrote {count} /tf messages ({args.minutes:g} min at {args.hz:g} Hz, "
              f"{bag.stat().st_size / 1e6:.0f} MB) with rosbags in "
              f"{time.perf_counter() - began:.0f} s", flush=True)

        alone = subprocess.run([sys.executable, "-c", LIBRARY_ALONE, str(bag),
                                str(SEEK_FRACTION)], cwd=REPO,
                               capture_output=True, text=True, check=True).stdout.split()
        read, took, peak_kb = int(alone[0]), float(alone[1]), int(alone[2])
        scan_to_seek = float(alone[3])
        read_rate = read / float(alone[4]) / args.hz
        library_rate = read / took / args.hz

        rows, seek_s, child = rates_held(bag, rates, args.window,
                                         SEEK_FRACTION * args.minutes * 60)
        rss, hwm = kb(child.pid, "VmRSS"), kb(child.pid, "VmHWM")
        stop(child)
        held = [rate for rate, lag, _ in rows if lag <= 0.1]
        fastest = max(held) if held else 0.0

        urdf, packages = demo_urdf_path()
        robot_bag = write_robot_bag(Path(tmp) / "robot", urdf.read_text())
        package = f"{DEMO_PACKAGE}={packages[DEMO_PACKAGE]}"
        first_robot = time_to_first_robot(robot_bag.mcap, package)
        base = subprocess.run([sys.executable, "-c", ROBOT_ALONE, str(robot_bag.mcap),
                               DEMO_PACKAGE, str(packages[DEMO_PACKAGE])], cwd=REPO,
                              capture_output=True, text=True, check=True).stdout.split()
        # The baseline's own clock starts after the interpreter: add its start-up, measured.
        started = time.perf_counter()
        subprocess.run([sys.executable, "-c", "pass"], check=True)
        interpreter = time.perf_counter() - started
        robot_alone = float(base[2]) + interpreter

    print()
    print(f"{'rate':>6} | {'lag at end (wall s)':>19} | {'TRANSFORMs received':>19} | held")
    for rate, lag, received in rows:
        print(f"{rate:>6g} | {lag:>19.3f} | {received:>19} | {'yes' if lag <= 0.1 else 'no'}")
    print()
    print(f"{'figure':<44} | {'play':>12} | baseline")
    print(f"{'fastest rate held (1 kHz tf, x real time)':<44} | {fastest:>12g} | "
          f"{library_rate:.1f} (mcap + mcap-ros2-support alone: read + decode); "
          f"{read_rate:.1f} (mcap reading alone)")
    print(f"{'memory, MB (RSS / peak)':<44} | {rss / 1024:>5.0f} / {hwm / 1024:<4.0f} | "
          f"{peak_kb / 1024:.0f} peak (the library alone, whole bag read)")
    print(f"{'time to first robot, s':<44} | {first_robot:>12.2f} | {robot_alone:.2f} "
          f"(open bag + load the robot model, no serving)")
    print(f"{f'seek to {SEEK_FRACTION:.0%} of the bag, s (reply: state sent)':<44} | "
          f"{seek_s:>12.3f} | {scan_to_seek:.2f} (the library reading up to there from the "
          f"start)")
    print()
    print(f"command: python bench/bench_play.py --minutes {args.minutes:g} --hz {args.hz:g} "
          f"--rates {args.rates} --window {args.window:g}")


def time_to_first_robot(bag: Path, package: str) -> float:
    """From starting `play` to a client holding every link's pose and every mesh."""
    began = time.perf_counter()
    child, port, _ = start_player(str(bag), "--paused", "--start", "1.0",
                                  "--package-path", package)
    session: Optional[RawSession] = None
    try:
        session = RawSession(port, name="bench-first-robot")
        result = session.command("create_robot", {"name": "demo", "fixed_frame": "world"})
        devices = [link["device"] for link in result["links"]]
        devices += [visual["device"] for visual in result["visuals"]]
        while not all(device in session.received.stamps for device in devices):
            time.sleep(0.001)
        return time.perf_counter() - began
    finally:
        if session is not None:
            session.close()
        stop(child)


if __name__ == "__main__":
    main()
