"""Robot load end to end, as a user sees it: request -> every link's mesh and TRANSFORM.

    .venv/bin/python bench/bench_robot_e2e.py [--links 130] [--repeat 5]

Every party is a process of its own, as in real use: the daemon (`bridge.console run`,
the installed command: its mesh reader processes import its main module, which is small), a
robot state publisher (`bridge.robots.state_publisher`: the URDF as a parameter and a
latched topic, /tf_static, /tf from joint states), the demo's joint motion node publishing
joint states at 50 Hz, and a client process (`slicer_client.connect(...)`,
``ros.robot(name)``, callbacks) that times, from the moment it asks:

- reply: ``ros.robot`` returns (the daemon's create_robot reply);
- meshes: every link visual's POLYDATA has reached the client's callback;
- poses: every link's TRANSFORM has;
- CPU: what the daemon process, and its mesh reader processes (`bridge.robots.mesh_readers`,
  with their forkserver), spent from the request to the last callback (user + system, from
  /proc). Unlike the times above these hardly depend on what else runs on the machine: on
  two idle cores the daemon and the readers run side by side.

Robots: the demo arm (``bridge.robots.demo``: 11 links, 14 meshes) and a generated robot
of ``--links`` links (a trunk with arms, 3/4 of its joints revolute), one mesh file per
link, each its own shape of 2,000-5,000 triangles, written as binary STL, COLLADA and OBJ
in turn into a package folder (about what a real robot package holds).

Cases (each daemon started for the bench and waited for until it sees the state
publishers' nodes, as a daemon that has been running does; the robots' joint motion runs
throughout):
- first robot of a new daemon: the mesh libraries (trimesh, yourdfpy) are imported and
  every mesh file parsed (an empty mesh cache folder);
- new daemon, mesh cache folder: the same request to a daemon started again, whose mesh
  cache folder (~/.cache/slicer-ros2-bridge/meshes) holds the robot's meshes;
- second robot (meshes unread): the libraries loaded by an earlier robot, this robot's
  meshes never read;
- again: the robot removed and asked for again (median of ``--repeat``): meshes from the
  daemon's memory.

Baselines in the same run: a plain rclpy process asking the state publisher for
``robot_description`` (GetParameters), from a new process (finding the node) and again
(the ROS floor for any way of doing this); yourdfpy's ``URDF.load`` with its meshes
(trimesh) in a new process and again, the usual way to get a URDF's meshes in Python (no
network, no poses).

The load average is printed before each daemon: on the 2-core machine latency depends on it.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Optional

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

PACKAGE = "bench_robot"


# ------------------------------------------------------------------------------ the robot


def make_robot(folder: Path, links: int, seed: int = 7) -> Path:
    """A `links`-link robot package in ``folder`` (package.xml, urdf/, meshes/), one mesh
    file per link, formats in turn STL, DAE, OBJ; returns the URDF's path."""
    import numpy as np
    import trimesh

    rng = np.random.default_rng(seed)
    (folder / "meshes").mkdir(parents=True, exist_ok=True)
    (folder / "urdf").mkdir(exist_ok=True)
    (folder / "package.xml").write_text(
        f'<?xml version="1.0"?><package format="3"><name>{PACKAGE}</name>'
        '<version>0.0.0</version><description>bench</description>'
        '<maintainer email="n@example.com">bench</maintainer><license>MIT</license>'
        '</package>')
    formats = ("stl", "dae", "obj")
    link_xml, joint_xml = [], []
    for i in range(links):
        # A capsule of 2,000-5,000 triangles, stretched and bumped: every link its own shape.
        count = int(rng.integers(32, 51))
        mesh = trimesh.creation.capsule(height=0.08 + 0.1 * rng.random(),
                                        radius=0.02 + 0.02 * rng.random(), count=[count, count])
        mesh.vertices = mesh.vertices * (1 + 0.3 * rng.random(3)) \
            + 0.002 * rng.standard_normal(mesh.vertices.shape)
        kind = formats[i % len(formats)]
        name = f"link_{i}.{kind}"
        if kind == "dae":
            mesh.visual.face_colors = (rng.integers(60, 255, 3).tolist() + [255])
        data = mesh.export(file_type=kind)
        (folder / "meshes" / name).write_bytes(data.encode() if isinstance(data, str) else data)
        colour = "" if kind == "dae" else \
            f'<material name="m{i}"><color rgba="{rng.random():.3f} 0.5 0.6 1"/></material>'
        link_xml.append(
            f'<link name="l{i}"><visual><origin xyz="0 0 0.05"/><geometry><mesh '
            f'filename="package://{PACKAGE}/meshes/{name}"/></geometry>{colour}</visual></link>')
        if i:
            # A trunk of 10, then arms of 10 hanging off it: a realistic depth (<= 20).
            parent = i - 1 if i < 10 or i % 10 else (i // 10) % 10
            kind_j = "fixed" if i % 4 == 0 else "revolute"
            limit = '' if kind_j == "fixed" else \
                '<axis xyz="0 1 0"/><limit lower="-1.5" upper="1.5" effort="1" velocity="1"/>'
            joint_xml.append(
                f'<joint name="j{i}" type="{kind_j}"><parent link="l{parent}"/>'
                f'<child link="l{i}"/><origin xyz="0.02 0 0.1" rpy="0 0 0.3"/>{limit}</joint>')
    urdf = folder / "urdf" / "robot.urdf"
    urdf.write_text(f'<?xml version="1.0"?>\n<robot name="bench_{links}">\n'
                    + "\n".join(link_xml + joint_xml) + "\n</robot>\n")
    return urdf


# ------------------------------------------------------------------------------ processes


# One child-process harness for the robot benches (bench_robot_stream's).
from bench_robot_stream import CLK_TCK, Child, free_port  # noqa: E402


def run_json(argv: list[str], timeout: float = 300) -> dict[str, Any]:
    """Run a helper process of this file; its last stdout line is JSON."""
    done = subprocess.run(argv, capture_output=True, text=True, cwd=str(REPO),
                          timeout=timeout)
    if done.returncode != 0:
        raise RuntimeError(f"{argv[3:]} failed:\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


# ------------------------------------------------------------------------------ client side


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of process `pid` so far (0 once it is gone)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def descendants(pid: int) -> list[int]:
    parents: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, ValueError, IndexError):
                continue
            parents.setdefault(ppid, []).append(int(entry.name))
    found, todo = [], [pid]
    while todo:
        for child in parents.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return found


def time_one_load(ros: Any, name: str, node: str, tf_prefix: str,
                  daemon: int) -> dict[str, Any]:
    """Ask for robot `name` once: seconds to the reply, the last mesh and the last pose,
    and the CPU seconds the daemon (process `daemon`) and its children spent meanwhile."""
    import threading

    changed = threading.Condition()
    meshes: list[float] = []
    poses: dict[str, float] = {}

    def on_change(kind: str, link: str, value: Any) -> None:
        now = time.perf_counter()
        with changed:
            if kind == "mesh":
                meshes.append(now)
            elif kind == "transform":
                poses.setdefault(link, now)
            changed.notify_all()

    cpu_before = {pid: cpu_s(pid) for pid in [daemon, *descendants(daemon)]}
    start = time.perf_counter()
    robot = ros.robot(name, node=node, tf_prefix=tf_prefix, callback=on_change, timeout=60)
    reply = time.perf_counter()
    robot.wait_until_loaded(120)
    # What the callbacks were told (they run on the client's dispatcher thread, a little
    # after the data is in the robot): what a user's code can act on.
    links = sum(1 for _, index in robot._devices.values() if index is None)
    visuals = sum(1 for _, index in robot._devices.values() if index is not None)
    with changed:
        if not changed.wait_for(lambda: len(poses) >= links and len(meshes) >= visuals, 60):
            raise SystemExit(f"callbacks: {len(poses)}/{links} poses, "
                             f"{len(meshes)}/{visuals} meshes")
        result = {"reply": reply - start, "meshes": sorted(meshes)[visuals - 1] - start,
                  "poses": max(poses.values()) - start, "links": links, "visuals": visuals}
    used = {pid: cpu_s(pid) - cpu_before.get(pid, 0.0) for pid in [daemon, *descendants(daemon)]}
    result["cpu_daemon"] = used.pop(daemon)
    result["cpu_readers"] = sum(used.values())
    robot.remove()
    time.sleep(0.3)  # the removal reaches the daemon before the next request
    return result


def client_main(port: int, daemon: int, plan: list[dict[str, Any]]) -> int:
    """The user: connect, then for each robot of `plan` (name, node, tf_prefix, loads) ask
    for it `loads` times in turn, timing its meshes and poses."""
    import slicer_client

    ros = slicer_client.connect("127.0.0.1", port)
    out = [[time_one_load(ros, step["name"], step["node"], step["tf_prefix"], daemon)
            for _ in range(step["loads"])] for step in plan]
    ros.close()
    print(json.dumps(out))
    return 0


def fetch_main(node: str) -> int:
    """Baseline: a plain rclpy process asks `node` for robot_description (GetParameters)."""
    import rclpy
    from rcl_interfaces.srv import GetParameters

    rclpy.init()
    ros_node = rclpy.create_node("bench_description_fetch")
    client = ros_node.create_client(GetParameters, f"{node}/get_parameters")
    times = []
    for _ in range(2):
        start = time.perf_counter()
        while not client.wait_for_service(timeout_sec=0.01):
            rclpy.spin_once(ros_node, timeout_sec=0)
        future = client.call_async(GetParameters.Request(names=["robot_description"]))
        rclpy.spin_until_future_complete(ros_node, future, timeout_sec=30)
        text = future.result().values[0].string_value
        times.append(time.perf_counter() - start)
        assert "<robot" in text
    ros_node.destroy_node()
    rclpy.shutdown()
    print(json.dumps({"first": times[0], "again": times[1], "bytes": len(text)}))
    return 0


def naive_main(urdf: str, package: str, folder: str) -> int:
    """Baseline: yourdfpy loads the URDF with its meshes (trimesh), in a fresh process."""
    import yourdfpy

    def handler(fname: str) -> str:
        prefix = f"package://{package}/"
        return folder + "/" + fname[len(prefix):] if fname.startswith(prefix) else fname

    start = time.perf_counter()
    model = yourdfpy.URDF.load(urdf, load_meshes=True, build_scene_graph=True,
                               filename_handler=handler)
    first = time.perf_counter() - start
    start = time.perf_counter()
    yourdfpy.URDF.load(urdf, load_meshes=True, build_scene_graph=True,
                       filename_handler=handler)
    again = time.perf_counter() - start
    print(json.dumps({"first": first, "again": again, "geometries": len(model.scene.geometry)}))
    return 0


# ------------------------------------------------------------------------------ the bench


class Robot:
    """One robot of the bench: its URDF and package, and the ROS names it is served under."""

    def __init__(self, label: str, urdf: Path, package: str, folder: Path,
                 namespace: str) -> None:
        self.label, self.urdf, self.package, self.folder = label, urdf, package, folder
        self.namespace = namespace
        self.node = f"/{namespace}/robot_state_publisher" if namespace else \
            "/robot_state_publisher"
        self.tf_prefix = f"{namespace}/" if namespace else ""

    def step(self, loads: int) -> dict[str, Any]:
        return {"name": "r" + self.label.replace(" ", "_"), "node": self.node,
                "tf_prefix": self.tf_prefix, "loads": loads}


def serve(robots: list[Robot], log_dir: Path, children: list[Child]) -> None:
    """A state publisher and a joint motion node (50 Hz) per robot, as a robot runs."""
    py = [sys.executable, "-u"]
    for robot in robots:
        tag = robot.label.replace(" ", "-")
        publisher = Child(f"state-publisher-{tag}", [
            *py, "-m", "bridge.robots.state_publisher", str(robot.urdf),
            f"--package-path={robot.package}={robot.folder}", "--namespace", robot.namespace,
            "--frame-prefix", robot.tf_prefix], log_dir)
        children.append(publisher)
        publisher.wait_for("ready", 90.0)
        motion = Child(f"joint-motion-{tag}", [
            *py, "-m", "bridge.robots.demo.joint_motion", str(robot.urdf), "--rate", "50",
            "--namespace", robot.namespace, "--no-trajectory-action"], log_dir)
        children.append(motion)
        motion.wait_for("joint motion ready", 90.0)


def with_daemon(tag: str, robots: list[Robot], mesh_home: Path, plan: list[dict[str, Any]],
                log_dir: Path, profile: Optional[Path]) -> list[list[dict[str, Any]]]:
    """Start a daemon (its mesh cache folder under `mesh_home`), wait until it has seen the
    robots' state publishers (the parameter nodes, as a long-running daemon has), run the
    client's `plan`, stop it."""
    py = [sys.executable, "-u"]
    port = free_port()
    argv = [*py, "-m", "bridge.console", "run", "--port", str(port), "--log-level", "INFO"]
    for robot in robots:
        argv += ["--package-path", f"{robot.package}={robot.folder}"]
    if profile is not None:
        argv = ["py-spy", "record", "-o", str(profile), "-f", "speedscope", "--threads", "--",
                *argv]
    env_home = os.environ.get("XDG_CACHE_HOME")
    os.environ["XDG_CACHE_HOME"] = str(mesh_home)
    try:
        daemon = Child(f"daemon-{tag}", argv, log_dir)
    finally:
        if env_home is None:
            os.environ.pop("XDG_CACHE_HOME")
        else:
            os.environ["XDG_CACHE_HOME"] = env_home
    try:
        daemon.wait_for("listening on", 90.0)
        run_json([*py, __file__, "--graph", str(port),
                  json.dumps([robot.node for robot in robots])])
        return run_json([*py, __file__, "--client", str(port), str(daemon.popen.pid),  # type: ignore[return-value]
                         json.dumps(plan)])
    finally:
        daemon.stop()


def graph_main(port: int, nodes: list[str]) -> int:
    """Wait until the daemon sees these nodes on the ROS graph (not part of any timing)."""
    import slicer_client

    ros = slicer_client.connect("127.0.0.1", port)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        services = {s["service"] for s in ros.list_services()}
        if all(f"{node}/get_parameters" in services for node in nodes):
            break
        time.sleep(0.1)
    else:
        raise SystemExit(f"the daemon did not see {nodes}")
    ros.close()
    print("{}")
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--links", type=int, default=130)
    parser.add_argument("--repeat", type=int, default=5, help="warm loads per robot")
    parser.add_argument("--profile", type=Path, default=None,
                        help="run the first daemon under py-spy, its profile here")
    parser.add_argument("--client", nargs=3, metavar=("PORT", "DAEMON_PID", "PLAN"),
                        help=argparse.SUPPRESS)
    parser.add_argument("--graph", nargs=2, metavar=("PORT", "NODES"), help=argparse.SUPPRESS)
    parser.add_argument("--fetch", metavar="NODE", help=argparse.SUPPRESS)
    parser.add_argument("--naive", nargs=3, metavar=("URDF", "PACKAGE", "DIR"),
                        help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.client:
        return client_main(int(args.client[0]), int(args.client[1]), json.loads(args.client[2]))
    if args.graph:
        return graph_main(int(args.graph[0]), json.loads(args.graph[1]))
    if args.fetch:
        return fetch_main(args.fetch)
    if args.naive:
        return naive_main(*args.naive)

    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.setdefault("ROS_LOG_DIR", tempfile.mkdtemp(prefix="bench-roslog-"))
    log_dir = Path(tempfile.mkdtemp(prefix="bench-robot-e2e-"))
    from bridge.robots import MeshCache, load_robot_file
    from bridge.robots.demo import DEMO_PACKAGE, demo_urdf_path

    demo_urdf, demo_packages = demo_urdf_path(log_dir / "demo")
    demo = Robot("demo arm", demo_urdf, DEMO_PACKAGE, demo_packages[DEMO_PACKAGE], "demo")
    folder = log_dir / PACKAGE
    big = Robot(f"{args.links} links", make_robot(folder, args.links), PACKAGE, folder, "")
    triangles = {}
    for robot in (demo, big):
        model = load_robot_file(robot.urdf, package_paths={robot.package: robot.folder},
                                cache=MeshCache())
        triangles[robot.label] = sum(len(v.triangles) for v in model.visuals)
    py = [sys.executable, "-u"]
    children: list[Child] = []
    rows: list[tuple[str, str, dict[str, float]]] = []
    try:
        serve([demo, big], log_dir, children)
        print(f"load average {os.getloadavg()[0]:.2f}: daemon 1, the demo arm first, "
              f"then the {big.label} (logs in {log_dir})", flush=True)
        home1 = log_dir / "cache-1"
        first = with_daemon("1", [demo, big], home1,
                            [demo.step(args.repeat + 1), big.step(args.repeat + 1)],
                            log_dir, args.profile)
        print(f"load average {os.getloadavg()[0]:.2f}: daemon 2, the {big.label} first",
              flush=True)
        fresh = with_daemon("2", [demo, big], log_dir / "cache-2", [big.step(1)], log_dir,
                            None)
        print(f"load average {os.getloadavg()[0]:.2f}: daemon 3, daemon 1's mesh cache "
              f"folder", flush=True)
        again = with_daemon("3", [demo, big], home1, [big.step(1)], log_dir, None)
        print(f"load average {os.getloadavg()[0]:.2f}: baselines", flush=True)
        fetch = run_json([*py, __file__, "--fetch", big.node])
        naive = {robot.label: run_json([*py, __file__, "--naive", str(robot.urdf),
                                        robot.package, str(robot.folder)])
                 for robot in (demo, big)}
    finally:
        for child in reversed(children):
            child.stop()

    def median(loads: list[dict[str, Any]]) -> dict[str, float]:
        return {k: statistics.median(load[k] for load in loads)
                for k in ("reply", "meshes", "poses", "cpu_daemon", "cpu_readers")}

    rows = [
        (demo.label, "first robot of a new daemon", first[0][0]),
        (demo.label, f"again (median of {args.repeat})", median(first[0][1:])),
        (big.label, "first robot of a new daemon", fresh[0][0]),
        (big.label, "new daemon, mesh cache folder", again[0][0]),
        (big.label, "second robot (meshes unread)", first[1][0]),
        (big.label, f"again (median of {args.repeat})", median(first[1][1:])),
    ]
    ms = 1000.0
    print(f"\nrobot load, request -> last item at a client's callbacks (ms); load average "
          f"now {os.getloadavg()[0]:.2f}")
    print(f"{'robot':<10} {'links':>5} {'meshes':>6} {'triangles':>9}  {'case':<30} "
          f"{'reply':>6} {'meshes':>7} {'poses':>6}  {'CPU: daemon':>11} {'readers':>7}")
    for label, case, row in rows:
        loads = first[0][0] if label == demo.label else first[1][0]
        print(f"{label:<10} {loads['links']:>5} {loads['visuals']:>6} "
              f"{triangles[label]:>9}  {case:<30} {row['reply'] * ms:>6.0f} "
              f"{row['meshes'] * ms:>7.0f} {row['poses'] * ms:>6.0f}  "
              f"{row['cpu_daemon'] * ms:>11.0f} {row['cpu_readers'] * ms:>7.0f}")
    print("\nbaselines, same run (ms):")
    print(f"  plain rclpy GetParameters of {big.node}'s robot_description "
          f"({fetch['bytes']:,} bytes): {fetch['first'] * ms:.0f} from a new process "
          f"(finding the node), {fetch['again'] * ms:.1f} again")
    for label, result in naive.items():
        print(f"  yourdfpy URDF.load with meshes, {label}: {result['first'] * ms:.0f} "
              f"(a new process), {result['again'] * ms:.0f} again; no network, no poses")
    return 0


if __name__ == "__main__":
    sys.exit(main())
