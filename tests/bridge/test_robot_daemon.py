"""Robots through the daemon: create_robot from a parameter, a topic or a file; meshes once
per connection; link transforms from tf; namespaces; reload; remove; the demo command.

Real processes only: the daemon, our state publisher (`slicer-ros2-bridge state-publisher`),
rclpy joint-state publishers, TCP clients. Expected values are computed here independently:
the Omni's binary STLs are parsed with struct, its forward kinematics written out by hand
from omni.urdf, primitive sizes and the DAE's positions read from the files.
"""

from __future__ import annotations

import json
import math
import re
import struct
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest

from bridge.robots.demo import DEMO_PACKAGE, demo_urdf_path
from protocol.messages import AttributeKind, Message, PolyData, Status, TrackingData
from protocol.polydata import RGBA_ATTRIBUTE
from protocol.naming import NameKey, device_name_for
from slicer_client.connection import CommandRefusedError, Connection
from support import (SHARED, Processes, RunningDaemon, assert_clean_exit, children_of,
                     pick_free_port, require_shared, spare_domain, start_daemon, wait_link_pose,
                     wait_until)

OMNI = SHARED / "robots" / "sensable_omni_model"
LOAD_TIMEOUT = 30.0  # discovery of a node that just started can take a few seconds

# ------------------------------------------------------------------ independent references

METAL = (0.4627450980392157, 0.4666666666666667, 0.4509803921568628, 1.0)
BLUE = (0.0, 0.0, 0.8, 1.0)
# link -> (mesh file, URDF material colour), from omni.urdf
OMNI_VISUALS = {
    "base": ("base.stl", METAL), "torso": ("torso.stl", BLUE),
    "upper_arm": ("upper_arm.stl", METAL), "lower_arm": ("lower_arm.stl", METAL),
    "wrist": ("wrist.stl", METAL), "tip": ("tip.stl", METAL), "stylus": ("stylus.stl", BLUE),
}
# The joint values the peer publishes: the waist at 90 degrees, the rest arbitrary.
OMNI_Q = {"waist": math.pi / 2, "shoulder": 0.5, "elbow": -0.2, "yaw": 4.5, "pitch": 0.7,
          "roll": 1.1}


def rot(axis: str, a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
            "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


def pose(rotation: np.ndarray, xyz: tuple[float, float, float]) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = rotation
    m[:3, 3] = xyz
    return m


def rpy(r: float, p: float, y: float) -> np.ndarray:
    return rot("z", y) @ rot("y", p) @ rot("x", r)


def omni_link_poses_mm(q: dict[str, float]) -> dict[str, np.ndarray]:
    """Each Omni link in the base frame, translations in mm (written out from omni.urdf)."""
    chain = [  # child link, joint origin xyz (m), rpy, axis, joint
        ("torso", (0, 0, 0.09), (0, 0, 0), "z", "waist"),
        ("upper_arm", (-0.0075, 0, 0.035), (0, 0, 0), "x", "shoulder"),
        ("lower_arm", (0.0075, 0.134, 0), (-1.5, 0, 0), "x", "elbow"),
        ("wrist", (0, 0.08, 0), (0, 0, 0), "y", "yaw"),
        ("tip", (0, 0.0525, 0), (1.5707, 0, 0), "x", "pitch"),
        ("stylus", (0, -0.029, 0), (3.14159, 3.14159, 0), "y", "roll"),
    ]
    out = {"base": np.eye(4)}
    current = np.eye(4)
    for link, xyz, angles, axis, joint in chain:
        current = current @ pose(rpy(*angles), xyz) @ pose(rot(axis, q[joint]), (0, 0, 0))
        mm = current.copy()
        mm[:3, 3] *= 1000.0
        out[link] = mm
    return out


def stl_counts(path: Path) -> tuple[int, int]:
    """(distinct corner points, triangles) of a binary STL, parsed with struct."""
    raw = path.read_bytes()
    (count,) = struct.unpack_from("<I", raw, 80)
    assert len(raw) == 84 + 50 * count, f"{path} is not a binary STL"
    corners = {struct.unpack_from("<9f", raw, 84 + 50 * i + 12)[j:j + 3]
               for i in range(count) for j in (0, 3, 6)}
    return len(corners), count


def rgba_of(body: PolyData) -> np.ndarray:
    (attribute,) = [a for a in body.attributes if a.name == RGBA_ATTRIBUTE]
    assert attribute.kind == AttributeKind.SCALAR  # as every reader sizes it (4 components)
    return np.asarray(attribute.data)


def triangle_count(body: PolyData) -> int:
    return len(body.polygons) // 4  # [3, i, j, k] per triangle


def is_mesh(message: Message) -> bool:
    return isinstance(message.body, PolyData)


def matrix_close(expected: np.ndarray, atol: float = 1e-2) -> Any:
    return lambda matrix: np.allclose(np.asarray(matrix), expected, atol=atol)


def devices_of(result: dict[str, Any]) -> tuple[dict[str, str], dict[str, dict[str, Any]]]:
    """(link -> its device, the name of its element in the robot's TDATA; visual device
    -> its entry) of a create_robot result."""
    links = {item["link"]: item["device"] for item in result["links"]}
    visuals = {item["device"]: item for item in result["visuals"]}
    return links, visuals


def create_and_wait_loaded(client: Connection, arguments: dict[str, Any]) -> dict[str, Any]:
    """create_robot; if the source node is still being discovered ("waiting"), wait for
    the robot to load (list_robots) and return create_robot's (idempotent) result again."""
    result = client.command("create_robot", arguments, timeout=LOAD_TIMEOUT)
    if result["state"] != "loaded":
        assert result["state"] == "waiting", result
        wait_until(lambda: robot_summary(client, arguments["name"])["state"] == "loaded",
                   LOAD_TIMEOUT, f"robot {arguments['name']} to load")
        result = client.command("create_robot", arguments, timeout=LOAD_TIMEOUT)
        assert result["existed"] is True
    assert result["state"] == "loaded", result
    return result


def robot_summary(client: Connection, name: str) -> dict[str, Any]:
    (summary,) = [r for r in client.command("list_robots")["robots"] if r["name"] == name]
    return summary


def wait_discovered(client: Connection, service: str) -> None:
    """Until the daemon's graph lists `service` (a node just started is seen in time)."""
    wait_until(lambda: service in {s["service"] for s in client.command("list_services")[
        "services"]}, LOAD_TIMEOUT, f"the daemon to discover {service}")


def daemon_devices(client: Connection) -> set[str]:
    return set(client.command("list_bridges")["devices"])


# ------------------------------------------------------------------ small URDFs

def two_link_urdf(*, arm_visual: str = '<box size="0.02 0.04 0.2"/>',
                  extra_link: bool = True, joint_z: float = 0.1) -> str:
    extra = """
  <link name="tool"><visual><geometry><sphere radius="0.01"/></geometry></visual></link>
  <joint name="tool_joint" type="fixed"><parent link="arm"/><child link="tool"/>
    <origin xyz="0 0 0.2"/></joint>""" if extra_link else ""
    return f"""<?xml version="1.0"?>
<robot name="two_link">
  <link name="base"><visual><geometry><cylinder radius="0.05" length="0.02"/></geometry>
    <material name="red"><color rgba="1 0 0 1"/></material></visual></link>
  <link name="arm"><visual><origin xyz="0 0 0.1"/><geometry>{arm_visual}</geometry>
    <material name="green"><color rgba="0 1 0 1"/></material></visual></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="arm"/>
    <origin xyz="0 0 {joint_z}"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>{extra}
</robot>
"""


# ------------------------------------------------------------------ fixtures

@pytest.fixture(scope="module")
def demo_package() -> tuple[Path, dict[str, Path]]:
    return demo_urdf_path()


@pytest.fixture(scope="module")
def daemon(module_processes: Processes, demo_package: tuple[Path, dict[str, Path]],
           tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningDaemon]:
    """One daemon for the module, knowing the Omni's and the demo's packages; clients may
    load robot files from the tests' temporary folders."""
    args = ["--package-path", f"{DEMO_PACKAGE}={demo_package[1][DEMO_PACKAGE]}",
            "--robot-dir", str(tmp_path_factory.getbasetemp())]
    if OMNI.exists():
        args += ["--package-path", f"sensable_omni_model={OMNI}"]
    running = start_daemon(module_processes, *args)
    yield running
    assert_clean_exit(running)


@pytest.fixture(scope="module")
def omni(module_processes: Processes, daemon: RunningDaemon) -> dict[str, Any]:
    """The Omni's state publisher (default node /robot_state_publisher) and a joint-state
    peer with OMNI_Q, then the robot "omni" created from the parameter."""
    omni_dir = require_shared("robots/sensable_omni_model")
    publisher = module_processes.bridge("state-publisher", str(omni_dir / "urdf" / "omni.urdf"),
                                        "--package-path", f"sensable_omni_model={omni_dir}")
    publisher.wait_for_output("ready", timeout=30)
    joints = module_processes.python("omni-joints", "robot_joint_state_publisher.py",
                                     *[f"{name}={value!r}" for name, value in OMNI_Q.items()])
    joints.wait_for_output("READY", timeout=30)
    with daemon.connect() as connection:
        # The parameter name given is the one used (no source: the defaults).
        result = create_and_wait_loaded(connection, {
            "name": "omni", "source": {"kind": "parameter", "node": "/robot_state_publisher",
                                       "parameter": "robot_description"}})
        # The module's tests read it from connections of their own: kept past this one.
        connection.command("keep_bridge", {"kind": "robot", "name": "omni"})
        return result


# ------------------------------------------------------------------ the Omni, from a parameter

def check_omni(client: Connection, result: dict[str, Any]) -> None:
    links, visuals = devices_of(result)
    assert sorted(links) == sorted(OMNI_VISUALS)
    assert len(visuals) == 7 and result["warnings"] == []
    assert result["fixed_frame"] == "base" and result["root_link"] == "base"
    for device, entry in visuals.items():
        link = entry["link"]
        stl, colour = OMNI_VISUALS[link]
        points, triangles = stl_counts(OMNI / "meshes" / stl)
        message = client.wait_for(device, is_mesh, timeout=LOAD_TIMEOUT)
        body = message.body
        assert isinstance(body, PolyData)
        assert len(body.points) == points == entry["vertices"], link
        assert triangle_count(body) == triangles == entry["triangles"], link
        np.testing.assert_allclose(rgba_of(body), np.tile(colour, (points, 1)), atol=1e-6)
        meta = message.metadata
        assert meta["ros2.role"] == "robot_visual" and meta["ros2.robot"] == "omni"
        assert meta["ros2.link"] == link and meta["ros2.visual"] == "0"
        assert meta["ros2.parent_device"] == links[link]
        assert meta["ros2.units"] == "mm"
        assert tuple(float(v) for v in meta["ros2.color"].split()) == pytest.approx(colour)
    expected = omni_link_poses_mm(OMNI_Q)
    poses = result["poses_device"]
    assert poses == "poses:omni"
    for link, device in links.items():
        wait_link_pose(client, poses, device, matrix_close(expected[link]), LOAD_TIMEOUT)
    # One TDATA holds every link: its elements are the links' devices.
    message = client.latest(poses)
    assert isinstance(message.body, TrackingData)
    assert sorted(e.name for e in message.body.elements) == sorted(links.values())
    meta = message.metadata
    assert meta["ros2.role"] == "robot_poses" and meta["ros2.robot"] == "omni"
    assert meta["ros2.frame"] == "base" and meta["ros2.units"] == "mm"


def test_omni_from_the_parameter_meshes_colours_and_forward_kinematics(
        omni: dict[str, Any], client: Connection) -> None:
    check_omni(client, omni)
    # The waist at 90 degrees turns the shoulder offset (-7.5 mm along x) onto -y.
    upper = wait_link_pose(client, omni["poses_device"], devices_of(omni)[0]["upper_arm"])
    np.testing.assert_allclose(upper[:3, 3], (0, -7.5, 125), atol=1e-2)


def test_a_client_that_connects_later_gets_meshes_and_transforms(
        omni: dict[str, Any], daemon: RunningDaemon) -> None:
    with daemon.connect() as late:
        check_omni(late, omni)


def test_list_robots_and_list_bridges_describe_the_robot(omni: dict[str, Any],
                                                         client: Connection) -> None:
    summary = robot_summary(client, "omni")
    assert summary["state"] == "loaded" and summary["links"] == 7 and summary["visuals"] == 7
    assert summary["source"] == {"kind": "parameter", "node": "/robot_state_publisher",
                                 "parameter": "robot_description"}
    bridges = client.command("list_bridges")["bridges"]
    assert any(b.get("kind") == "robot" and b.get("name") == "omni" for b in bridges)
    # Same request again: nothing new (a reconnecting client re-creates what it had).
    again = client.command("create_robot", {"name": "omni"})
    assert again["existed"] is True and again["links"] == omni["links"]
    with pytest.raises(CommandRefusedError) as refused:
        client.command("create_robot", {"name": "omni", "tf_prefix": "other/"})
    assert refused.value.code.name == "ALREADY_EXISTS" and refused.value.field == "name"


# ------------------------------------------------------------------ from files

def test_from_a_file_primitives_a_dae_mesh_and_a_missing_mesh(
        client: Connection, tmp_path: Path, demo_package: tuple[Path, dict[str, Path]]) -> None:
    dae = demo_package[1][DEMO_PACKAGE] / "meshes" / "forearm.dae"
    urdf = tmp_path / "mixed.urdf"
    urdf.write_text(f"""<?xml version="1.0"?>
<robot name="mixed">
  <link name="root"><visual><origin xyz="0 0 0.15"/><geometry><box size="0.1 0.2 0.3"/>
    </geometry></visual></link>
  <link name="ball"><visual><geometry><sphere radius="0.025"/></geometry>
    <material name="c"><color rgba="0.1 0.2 0.3 0.5"/></material></visual></link>
  <link name="tube"><visual><geometry><cylinder radius="0.01" length="0.3"/></geometry>
    </visual></link>
  <link name="dae"><visual><geometry><mesh filename="package://{DEMO_PACKAGE}/meshes/forearm.dae"/>
    </geometry></visual></link>
  <link name="ghost"><visual><geometry><mesh filename="meshes/missing.stl"/></geometry>
    </visual></link>
  <joint name="a" type="fixed"><parent link="root"/><child link="ball"/></joint>
  <joint name="b" type="fixed"><parent link="root"/><child link="tube"/></joint>
  <joint name="c" type="fixed"><parent link="root"/><child link="dae"/></joint>
  <joint name="d" type="fixed"><parent link="root"/><child link="ghost"/></joint>
</robot>
""")
    result = client.command("create_robot", {"name": "mixed",
                                             "source": {"kind": "file", "path": str(urdf)}})
    try:
        assert result["state"] == "loaded"
        (warning,) = result["warnings"]
        assert "missing.stl" in warning and "'ghost'" in warning
        links, visuals = devices_of(result)
        assert sorted(links) == ["ball", "dae", "ghost", "root", "tube"]
        assert [v["link"] for v in visuals.values()] == ["root", "ball", "tube", "dae"]
        meshes = {v["link"]: client.wait_for(d, is_mesh).body for d, v in visuals.items()}
        # Box: 8 corners, 12 triangles, 100 x 200 x 300 mm, centred 150 mm up.
        box = meshes["root"]
        assert len(box.points) == 8 and triangle_count(box) == 12
        np.testing.assert_allclose(np.ptp(box.points, axis=0), (100, 200, 300), atol=1e-3)
        np.testing.assert_allclose(box.points.mean(axis=0), (0, 0, 150), atol=1e-3)
        # Sphere radius 25 mm; its URDF colour with alpha.
        radii = np.linalg.norm(meshes["ball"].points, axis=1)
        np.testing.assert_allclose(radii, 25.0, atol=1e-3)
        np.testing.assert_allclose(rgba_of(meshes["ball"])[0], (0.1, 0.2, 0.3, 0.5), atol=1e-6)
        np.testing.assert_allclose(np.ptp(meshes["tube"].points, axis=0), (20, 20, 300),
                                   atol=0.5)
        # DAE: positions in centimetres (unit meter="0.01") -> mm; its own diffuse colour.
        root = ET.parse(dae).getroot()
        ns = {"c": "http://www.collada.org/2005/11/COLLADASchema"}
        positions = np.array(root.find(".//c:float_array", ns).text.split(),
                             dtype=float).reshape(-1, 3)
        triangles = sum(int(t.get("count")) for t in root.iterfind(".//c:triangles", ns))
        diffuse = [float(v) for v in root.find(".//c:diffuse/c:color", ns).text.split()]
        assert triangle_count(meshes["dae"]) == triangles
        np.testing.assert_allclose(np.ptp(meshes["dae"].points, axis=0),
                                   np.ptp(positions, axis=0) * 10.0, atol=1e-3)
        # (the mesh reader keeps 8 bits per channel)
        np.testing.assert_allclose(rgba_of(meshes["dae"])[0], diffuse, atol=1 / 255)
        # The root link is the fixed frame: its TRANSFORM is the identity.
        wait_link_pose(client, result["poses_device"], links["root"],
                       matrix_close(np.eye(4), atol=1e-9))
    finally:
        client.command("remove_robot", {"name": "mixed"})


def test_a_package_uri_file_and_a_malformed_urdf(client: Connection, tmp_path: Path) -> None:
    result = client.command("create_robot", {"name": "demo_file", "source": {
        "kind": "file", "path": f"package://{DEMO_PACKAGE}/urdf/demo_arm.urdf"}})
    try:
        assert result["state"] == "loaded" and len(result["links"]) == 11
        assert len(result["visuals"]) == 14 and result["warnings"] == []
    finally:
        client.command("remove_robot", {"name": "demo_file"})
    broken = tmp_path / "broken.urdf"
    broken.write_text('<robot name="x"><link name="a"/><joint name="j" type="fixed">'
                      '<parent link="a"/><child link="nowhere"/></joint></robot>')
    with pytest.raises(CommandRefusedError) as refused:
        client.command("create_robot", {"name": "broken",
                                        "source": {"kind": "file", "path": str(broken)}})
    assert refused.value.field == "source.path"
    assert "nowhere" in str(refused.value)
    with pytest.raises(CommandRefusedError) as missing:
        client.command("create_robot", {"name": "absent", "source": {
            "kind": "file", "path": str(tmp_path / "absent.urdf")}})
    assert missing.value.field == "source.path" and "absent.urdf" in str(missing.value)
    # Nothing was left behind, and the daemon still serves.
    names = [r["name"] for r in client.command("list_robots")["robots"]]
    assert "broken" not in names and "absent" not in names
    assert not any(d.startswith(("broken", "urdf:broken")) for d in daemon_devices(client))


def test_a_robot_loads_without_the_mesh_extras_trimesh_would_import(
        daemon: RunningDaemon, client: Connection) -> None:
    """Issue 44: a daemon's first robot waited most of a second while trimesh imported
    scipy, shapely, rtree, embreex and manifold3d, none of which reading meshes uses.
    With the demo arm's STL, OBJ and DAE meshes sent, the daemon has mapped the compiled
    modules of those that did the work (lxml, Pillow), none of the others'."""
    result = client.command("create_robot", {"name": "demo_lean", "source": {
        "kind": "file", "path": f"package://{DEMO_PACKAGE}/urdf/demo_arm.urdf"}})
    try:
        assert result["state"] == "loaded" and result["warnings"] == []
        sources = [entry["source"] for entry in devices_of(result)[1].values()]
        assert {Path(s.split(" -> ")[0]).suffix for s in sources} >= {".stl", ".obj", ".dae"}
        for device in devices_of(result)[1]:
            client.wait_for(device, is_mesh)
        maps = Path(f"/proc/{daemon.child.pid}/maps").read_text()
        mapped = {line.split("/site-packages/", 1)[1].split("/", 1)[0]
                  for line in maps.splitlines() if "/site-packages/" in line}
        assert {"lxml", "PIL"} <= mapped, sorted(mapped)
        assert [name for name in mapped if name.startswith(
            ("scipy", "shapely", "rtree", "embreex", "manifold3d"))] == [], sorted(mapped)
    finally:
        client.command("remove_robot", {"name": "demo_lean"})


# ------------------------------------------------------------------ namespaces, reload, remove

def test_two_robots_under_namespaces_with_tf_prefixes(processes: Processes, client: Connection,
                                                      tmp_path: Path) -> None:
    urdf = tmp_path / "two_link.urdf"
    urdf.write_text(two_link_urdf())
    angles = {"PSM1": math.pi / 2, "PSM2": -0.25}
    for ns, angle in angles.items():
        processes.bridge("state-publisher", str(urdf), "--namespace", ns,
                         "--frame-prefix", f"{ns}/").wait_for_output("ready", timeout=30)
        processes.python(f"{ns}-joints", "robot_joint_state_publisher.py", "--topic",
                         f"/{ns}/joint_states", f"j1={angle!r}").wait_for_output("READY", 30)
    results = {ns: create_and_wait_loaded(client, {"name": ns, "namespace": ns,
                                                   "tf_prefix": f"{ns}/"})
               for ns in angles}
    try:
        for ns, result in results.items():
            assert result["source"]["node"] == f"/{ns}/robot_state_publisher"
            assert result["fixed_frame"] == f"{ns}/base"
            links, visuals = devices_of(result)
            assert links == {"base": f"{ns}:base", "arm": f"{ns}:arm", "tool": f"{ns}:tool"}
            for device in visuals:
                assert client.wait_for(device, is_mesh).metadata["ros2.robot"] == ns
            arm = pose(rot("z", angles[ns]), (0, 0, 100))
            poses = result["poses_device"]
            wait_link_pose(client, poses, links["arm"], matrix_close(arm), LOAD_TIMEOUT)
            wait_link_pose(client, poses, links["tool"],
                           matrix_close(arm @ pose(np.eye(3), (0, 0, 200))), LOAD_TIMEOUT)
            assert client.latest(poses).metadata["ros2.frame"] == f"{ns}/base"
    finally:
        for ns in angles:
            client.command("remove_robot", {"name": ns})


def test_reload_on_a_changed_description_and_remove(processes: Processes, client: Connection,
                                                    daemon: RunningDaemon,
                                                    tmp_path: Path) -> None:
    urdf = tmp_path / "first.urdf"
    urdf.write_text(two_link_urdf())
    processes.bridge("state-publisher", str(urdf), "--namespace", "reload",
                     "--frame-prefix", "reload/").wait_for_output("ready", timeout=30)
    processes.python("reload-joints", "robot_joint_state_publisher.py", "--topic",
                     "/reload/joint_states", "j1=0.0").wait_for_output("READY", 30)
    by_parameter = create_and_wait_loaded(client, {"name": "rl", "namespace": "reload",
                                                   "tf_prefix": "reload/"})
    by_topic = create_and_wait_loaded(client, {
        "name": "rl_topic", "namespace": "reload", "tf_prefix": "reload/",
        "source": {"kind": "topic", "topic": "robot_description"}})
    assert by_topic["source"] == {"kind": "topic", "topic": "/reload/robot_description"}
    for result in (by_parameter, by_topic):
        assert sorted(devices_of(result)[0]) == ["arm", "base", "tool"]
    old_links, old_visuals = devices_of(by_parameter)
    box = next(d for d, v in old_visuals.items() if v["link"] == "arm")
    client.wait_for(box, lambda m: is_mesh(m) and len(m.body.points) == 8)
    poses = by_parameter["poses_device"]
    wait_link_pose(client, poses, old_links["tool"], matrix_close(pose(np.eye(3), (0, 0, 300))),
                   LOAD_TIMEOUT)
    # A new description: the arm becomes a sphere, the tool link is gone, the joint higher.
    client.command("create_parameter_client", {"node": "/reload/robot_state_publisher"},
                   timeout=LOAD_TIMEOUT)
    new_urdf = two_link_urdf(arm_visual='<sphere radius="0.03"/>', extra_link=False,
                             joint_z=0.3)
    reply = client.command("set_parameters", {"node": "/reload/robot_state_publisher",
                                              "values": {"robot_description": {
                                                  "type": "string", "value": new_urdf}}},
                           timeout=LOAD_TIMEOUT)
    assert reply["results"]["robot_description"]["ok"], reply
    try:
        for name in ("rl", "rl_topic"):
            wait_until(lambda name=name: robot_summary(client, name)["loads"] == 2, LOAD_TIMEOUT,
                       f"{name} to reload")
            assert robot_summary(client, name)["links"] == 2
        # Same device name, new mesh (replaced); the tool's devices are forgotten.
        client.wait_for(box, lambda m: is_mesh(m) and len(m.body.points) > 8)
        wait_link_pose(client, poses, old_links["arm"],  # the joint moved up with the new URDF
                       matrix_close(pose(np.eye(3), (0, 0, 300))), LOAD_TIMEOUT)
        # The tool's mesh is forgotten, and its element left the robot's TDATA.
        wait_until(lambda: old_links["tool"] not in {
            e.name for e in client.latest(poses).body.elements}, LOAD_TIMEOUT,
            "the tool's element to leave the TDATA")
        devices = daemon_devices(client)
        assert "rl:tool:0" not in devices
        assert poses in devices and box in devices
        # Kept, it goes to every client (docs/security.md, "Who owns a bridge"): a new one
        # gets the new robot only.
        client.command("keep_bridge", {"kind": "robot", "name": "rl"})
        with daemon.connect() as late:
            late.wait_for(box, lambda m: is_mesh(m) and len(m.body.points) > 8)
        # A malformed description is refused by the state publisher itself, so the
        # daemon's view stays; a reload of the same text does nothing.
        assert robot_summary(client, "rl")["loads"] == 2
    finally:
        removed = client.command("remove_robot", {"name": "rl"})
        client.command("remove_robot", {"name": "rl_topic"})
        client.command("remove_parameter_client", {"node": "/reload/robot_state_publisher"})
    assert set(removed["devices"]) >= {old_links["arm"], old_links["base"], box, "urdf:rl"}
    devices = daemon_devices(client)
    assert not devices & set(removed["devices"])
    assert "rl" not in [r["name"] for r in client.command("list_robots")["robots"]]
    with pytest.raises(CommandRefusedError) as refused:
        client.command("remove_robot", {"name": "rl"})
    assert refused.value.code.name == "NOT_FOUND"


def test_a_robot_waits_for_its_node_and_loads_when_it_appears(
        processes: Processes, client: Connection, tmp_path: Path) -> None:
    result = client.command("create_robot", {"name": "late", "namespace": "late_ns"},
                            timeout=LOAD_TIMEOUT)
    try:
        assert result["state"] == "waiting" and result["links"] == []
        assert "/late_ns/robot_state_publisher" in result["reason"]
        status = client.wait_for("urdf:late", lambda m: isinstance(m.body, Status))
        assert status.body.code == 13 and "waiting" in status.body.text  # NOT_READY
        urdf = tmp_path / "late.urdf"
        urdf.write_text(two_link_urdf())
        processes.bridge("state-publisher", str(urdf), "--namespace", "late_ns",
                         "--frame-prefix", "late_ns/").wait_for_output("ready", timeout=30)
        client.wait_for("late:arm:0", is_mesh, timeout=LOAD_TIMEOUT)
        client.wait_for("urdf:late", lambda m: isinstance(m.body, Status) and m.body.code == 1,
                        timeout=LOAD_TIMEOUT)
        assert robot_summary(client, "late")["state"] == "loaded"
    finally:
        client.command("remove_robot", {"name": "late"})


def test_a_robot_whose_node_answers_late_waits_and_loads_on_a_later_try(
        processes: Processes, client: Connection, daemon: RunningDaemon,
        tmp_path: Path) -> None:
    """The node is discovered but answers nothing (until told to) for more than the 4 s
    request timeout: create_robot says "waiting" with the reason, and a later fetch loads
    the robot once the node answers."""
    go = tmp_path / "answer-now"
    node = processes.python("slow", "param_node.py", "robot_state_publisher",
                            "--namespace", "slow_ns", "--description", two_link_urdf(),
                            "--busy-until", str(go))
    node.wait_for_output("READY", timeout=30)
    wait_discovered(client, "/slow_ns/robot_state_publisher/get_parameters")
    result = client.command("create_robot", {"name": "slow", "namespace": "slow_ns"},
                            timeout=LOAD_TIMEOUT)
    try:
        assert result["state"] == "waiting" and result["links"] == []
        node_name = "/slow_ns/robot_state_publisher"
        # (Not yet available only if the daemon's new client took over 2 s to see it.)
        assert result["reason"] in (
            f"parameter robot_description of {node_name}: source.node: expected a response "
            f"from the parameter services of {node_name} within 4 s, got no response; asked "
            f"again while the node is up",
            f"parameter robot_description of {node_name}: node not available yet")
        daemon.child.wait_for_output(f"could not fetch robot_description of {node_name} "
                                     f"(tried again while the node is up)", timeout=30)
        assert robot_summary(client, "slow")["state"] == "waiting"
        go.touch()
        node.wait_for_output("NOT BUSY")
        arm = client.wait_for("slow:arm:0", is_mesh, timeout=LOAD_TIMEOUT)
        assert len(arm.body.points) == 8  # the arm's box
        # Each mesh goes out as it is made: the robot is loaded once all are.
        wait_until(lambda: robot_summary(client, "slow")["state"] == "loaded",
                   what="robot slow loaded")
    finally:
        client.command("remove_robot", {"name": "slow"})


def test_a_robot_whose_first_description_read_is_lost_loads_at_once(
        processes: Processes, client: Connection, daemon: RunningDaemon) -> None:
    """The node's first get_parameters is never answered (as when a request or its answer
    is lost while DDS still matches the endpoints): the read is sent again within the same
    fetch, which does not fail."""
    node = processes.python("forgetful", "param_node.py", "robot_state_publisher",
                            "--namespace", "forgetful_ns", "--description", two_link_urdf(),
                            "--lose-first-get")
    node.wait_for_output("READY", timeout=30)
    wait_discovered(client, "/forgetful_ns/robot_state_publisher/get_parameters")
    # Loaded at once, unless the daemon's new client took over 2 s to see the node.
    result = create_and_wait_loaded(client, {"name": "forgetful", "namespace": "forgetful_ns"})
    try:
        assert [link["link"] for link in result["links"]] == ["base", "arm", "tool"]
        assert node.wait_for_output("LOST ").endswith('LOST ["robot_description"]')
        assert node.wait_for_output("ANSWERED ").endswith('ANSWERED ["robot_description"]')
        assert "could not fetch robot_description of /forgetful_ns" not in daemon.child.output()
    finally:
        client.command("remove_robot", {"name": "forgetful"})


def test_a_robot_from_the_daemon_s_own_parameter_is_read_in_process(
        processes: Processes, client: Connection) -> None:
    """The daemon reads its own node's parameter without a service call to itself (such a
    call's reply can be lost while its own endpoints match: issue 25, item 12): loaded when
    create_robot answers, reloaded at once when the parameter changes, and no parameter
    client of its own node in the ROS graph."""
    client.command("server_declare_parameter", {"name": "own_urdf", "value": {
        "type": "string", "value": two_link_urdf()}})
    source = {"kind": "parameter", "node": "/slicer_bridge", "parameter": "own_urdf"}
    try:
        result = client.command("create_robot", {"name": "own", "source": source},
                                timeout=LOAD_TIMEOUT)
        assert result["state"] == "loaded", result
        assert sorted(devices_of(result)[0]) == ["arm", "base", "tool"]
        client.command("server_set_parameter", {"name": "own_urdf", "value": {
            "type": "string", "value": two_link_urdf(extra_link=False)}})
        wait_until(lambda: robot_summary(client, "own")["loads"] == 2, LOAD_TIMEOUT,
                   "the robot to reload its changed description")
        assert robot_summary(client, "own")["links"] == 2
        # A parameter client made after the robot: once the graph shows it, it shows every
        # client the daemon's node made before, and none reads the daemon's own parameters.
        client.command("create_parameter_client", {"node": "/graph_witness"})
        graph = processes.python("graph", "node_clients.py", "slicer_bridge", "/",
                                 "/graph_witness/get_parameters")
        clients = json.loads(graph.wait_for_output("CLIENTS ", timeout=LOAD_TIMEOUT)
                             .split("CLIENTS ", 1)[1])
        assert "/graph_witness/get_parameters" in clients
        assert not [c for c in clients if c.startswith("/slicer_bridge/")], clients
    finally:
        client.command("remove_parameter_client", {"node": "/graph_witness"})
        client.command("remove_robot", {"name": "own"})
        client.command("server_undeclare_parameter", {"name": "own_urdf"})


def test_device_names_are_the_registry_s(omni: dict[str, Any]) -> None:
    """Stable names: what a client computes from the scheme is what the daemon uses."""
    for item in omni["links"]:
        assert item["device"] == device_name_for(NameKey.robot_link("omni", item["link"]))
        for device in item["visuals"]:
            assert device == device_name_for(NameKey.robot_visual("omni", item["link"], 0))


# ------------------------------------------------------------------ the demo command

def test_the_demo_command(processes: Processes) -> None:
    port = pick_free_port()
    # A ROS domain of its own: the module's Omni is also a /robot_state_publisher.
    domain = spare_domain(1)
    demo = processes.bridge("demo", "--port", str(port), env={"ROS_DOMAIN_ID": domain})
    demo.wait_for_output("Stop with Ctrl-C", timeout=90)
    banner = demo.output()
    assert f"127.0.0.1:{port}" in banner and "OpenIGTLinkIF" in banner
    assert "robot 'demo': 11 links, 14 meshes" in banner
    helpers = [pid for pid, _, cmd in children_of(demo.pid)
               if "state_publisher" in cmd or "joint_motion" in cmd]
    assert len(helpers) == 2, children_of(demo.pid)
    urdf, _ = demo_urdf_path()
    visuals = ET.parse(urdf).getroot().findall("./link/visual")
    link_names = [link.get("name") for link in ET.parse(urdf).getroot().findall("./link")]
    with Connection("127.0.0.1", port) as connection:
        robot = connection.command("create_robot", {"name": "demo"})  # what the client does
        assert robot["existed"] is True and robot["state"] == "loaded"
        links, meshes = devices_of(robot)
        assert sorted(links) == sorted(link_names) and len(meshes) == len(visuals)
        for device in meshes:
            connection.wait_for(device, is_mesh)
        for device in links.values():
            wait_link_pose(connection, robot["poses_device"], device)
        # The arm moves: the tool flange's transform changes over time.
        flange = links["tool_flange"]
        first = wait_link_pose(connection, robot["poses_device"], flange).copy()
        wait_link_pose(connection, robot["poses_device"], flange,
                       lambda matrix: not np.allclose(matrix, first, atol=1.0), 10)
        # One message moves the whole arm: every link in it, none on a device of its own.
        moving = connection.latest(robot["poses_device"])
        assert sorted(e.name for e in moving.body.elements) == sorted(links.values())
        assert all(connection.latest(device) is None for device in links.values())
    code = demo.stop()
    output = demo.output()
    assert code == 0, output[-3000:]
    assert "Traceback" not in output and not re.search(r" (ERROR|CRITICAL) ", output), \
        output[-3000:]
    for pid in helpers:
        assert not _alive(pid), f"demo child {pid} left running"


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


# ------------------------------------------------------------------ start-up config

def test_a_robot_from_the_yaml_start_up_config(processes: Processes, tmp_path: Path) -> None:
    urdf = tmp_path / "cfg.urdf"
    urdf.write_text(two_link_urdf())
    config = tmp_path / "bridge.yaml"
    config.write_text(f"robots:\n  - {{name: cfg, source: {{kind: file, path: '{urdf}'}}}}\n"
                      f"  - {{name: cfg_waiting, namespace: nobody_here}}\n")
    running = start_daemon(processes, "--config", str(config))
    with running.connect() as connection:
        for device in ("cfg:base:0", "cfg:arm:0", "cfg:tool:0"):
            assert connection.wait_for(device, is_mesh).metadata["ros2.robot"] == "cfg"
        wait_link_pose(connection, "poses:cfg", "cfg:base", matrix_close(np.eye(4), atol=1e-9))
        states = {r["name"]: r["state"] for r in connection.command("list_robots")["robots"]}
        assert states == {"cfg": "loaded", "cfg_waiting": "waiting"}
    assert_clean_exit(running)
