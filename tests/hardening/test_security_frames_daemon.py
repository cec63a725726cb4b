"""Frame globs, robot sources and --frame-prefix on a running daemon: real TCP clients,
real rclpy peers (tests/peers/tf_chain_publisher.py publishes the frames, echo_subscriber.py
witnesses what reaches /tf)."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest

from hardening_tools import RawClient, transform_bytes
from protocol.commands import ErrorCode
from protocol.messages import Message, StatusCode, Transform
from protocol.naming import DeviceNameRegistry, NameKey
from slicer_client.connection import CommandRefusedError, Connection
from support import (Child, Processes, RunningDaemon, assert_clean_exit, pick_free_port,
                     scaled, start_daemon, wait_link_pose)

pytestmark = pytest.mark.ros

# tf_chain_publisher.py: base -> link1 (0, 0, 0.5) m, 90 deg about z; link1 -> tool
# (0.25, 0, 0) m, 90 deg about x. Composed by hand, in mm.
BASE_LINK1 = np.array([[0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 1, 500], [0, 0, 0, 1]], float)
LINK1_TOOL = np.array([[1, 0, 0, 250], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]], float)
BASE_TOOL = BASE_LINK1 @ LINK1_TOOL
assert np.allclose(BASE_TOOL[:3, 3], [0, 250, 500])


def refusal(client: Connection, op: str, args: dict[str, Any]) -> CommandRefusedError:
    with pytest.raises(CommandRefusedError) as refused:
        client.command(op, args)
    return refused.value


def is_matrix(expected: np.ndarray):
    def check(message: Message) -> bool:
        return isinstance(message.body, Transform) and np.allclose(
            message.body.matrix, expected, atol=1e-3)
    return check


def ros_transforms(echo: Child) -> list[dict[str, Any]]:
    """Every TransformStamped the echo peer printed so far."""
    return [t for line in echo.lines() if line.startswith("MSG ")
            for t in json.loads(line[4:])["transforms"]]


@pytest.fixture(scope="module")
def guarded(module_processes: Processes,
            tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningDaemon]:
    """The PSM1 daemon of a two-arm setup, locked to PSM1's frames and parameters."""
    running = start_daemon(module_processes, "--frame-prefix", "PSM1/",
                           "--allow-frame", "PSM1/*", "--allow-frame", "world",
                           "--deny-frame", "PSM1/secret*",
                           "--allow-parameter", "/PSM1/*", "--allow-topic", "/PSM1/*",
                           "--robot-dir", str(tmp_path_factory.getbasetemp()))
    yield running
    assert_clean_exit(running)


@pytest.fixture(scope="module")
def echo(module_processes: Processes) -> Child:
    child = module_processes.python("echo", "echo_subscriber.py", "/tf",
                                    "tf2_msgs/msg/TFMessage")
    child.wait_for_output("READY")
    return child


# ---------------------------------------------------------------------------- frame globs


def test_lookups_of_denied_frames_are_forbidden_naming_the_field(guarded: RunningDaemon,
                                                                 ) -> None:
    with guarded.connect() as client:
        # Relative names take the prefix, and are judged with it.
        assert client.command("create_tf_lookup", {"parent": "base", "child": "tool"}
                              )["parent"] == "PSM1/base"
        for op in ("create_tf_lookup", "lookup_transform"):
            error = refusal(client, op, {"parent": "base", "child": "secret_tool"})
            assert error.code == ErrorCode.FORBIDDEN and error.field == "child"
            assert "PSM1/secret_tool" in str(error) and "'PSM1/secret*'" in str(error)
            # The other arm's frames, asked for absolutely: not in the allow list.
            error = refusal(client, op, {"parent": "/PSM2/base", "child": "tool"})
            assert error.code == ErrorCode.FORBIDDEN and error.field == "parent"
            assert "PSM2/base" in str(error) and "PSM1/*" in str(error)
            # A leading / does not slip past a glob.
            assert refusal(client, op, {"parent": "/PSM1/secret_base",
                                        "child": "tool"}).field == "parent"
        names = [(b.get("parent"), b.get("child"))
                 for b in client.command("list_bridges")["bridges"]]
        assert ("PSM1/base", "PSM1/tool") in names
        assert not any("secret" in str(pair) or "PSM2" in str(pair) for pair in names)


def test_broadcasters_of_denied_frames_never_reach_ros(guarded: RunningDaemon,
                                                       echo: Child) -> None:
    identity = np.eye(4).tolist()
    with guarded.connect() as client:
        for op, extra in (("create_tf_broadcaster", {}),
                          ("broadcast_transform", {"matrix": identity})):
            error = refusal(client, op, {"parent": "world", "child": "secret_needle", **extra})
            assert error.code == ErrorCode.FORBIDDEN and error.field == "child"
            assert "PSM1/secret_needle" in str(error)
            error = refusal(client, op, {"parent": "/map", "child": "needle", **extra})
            assert error.code == ErrorCode.FORBIDDEN and error.field == "parent"
        created = client.command("create_tf_broadcaster", {"parent": "/world",
                                                           "child": "needle"})
        assert (created["parent"], created["child"]) == ("world", "PSM1/needle")
        # (The broadcaster is the client's: it lives while the client is connected.)
        # TRANSFORMs: to the allowed broadcaster's device they reach /tf; to the device the
        # denied one would have had, they find nothing (the broadcaster was never created).
        denied_device = DeviceNameRegistry().register(
            NameKey.tf_broadcaster("world", "PSM1/secret_needle"))
        assert denied_device != created["device"]
        raw = RawClient(guarded.port)
        try:
            raw.send(transform_bytes([1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0], denied_device))
            status = raw.read_until(lambda m: m.type_name == "STATUS"
                                    and m.device_name == denied_device)
            assert status.body.code == StatusCode.NOT_FOUND
            deadline = time.monotonic() + scaled(20)
            while time.monotonic() < deadline and not any(
                    t["child_frame_id"] == "PSM1/needle" for t in ros_transforms(echo)):
                raw.send(transform_bytes([1, 0, 0, 0, 1, 0, 0, 0, 1, 10, 20, 30],
                                         created["device"]))
                time.sleep(0.1)
        finally:
            raw.close()
    sent = [t for t in ros_transforms(echo) if t["child_frame_id"] == "PSM1/needle"]
    assert sent and sent[0]["header"]["frame_id"] == "world", echo.output()[-2000:]
    assert not any("secret" in t["child_frame_id"] or "map" in t["header"]["frame_id"]
                   for t in ros_transforms(echo))


def test_start_up_tf_bridges_are_judged_by_the_frame_globs(processes: Processes,
                                                           tmp_path: Path) -> None:
    path = tmp_path / "bridge.yaml"
    path.write_text("security: {deny_frames: ['*secret*']}\n"
                    "tf_lookups:\n  - {parent: world, child: tool}\n"
                    "tf_broadcasters:\n  - {parent: world, child: /secret}\n")
    child = processes.bridge("run", "--port", str(pick_free_port()), "--config", str(path))
    assert child.popen.wait(60) == 2, child.output()
    assert "tf_broadcasters[0]: child: expected a tf frame this daemon exposes" in \
        child.output(), child.output()


# ---------------------------------------------------------------------------- robots


def test_robot_sources_are_judged_by_the_parameter_and_topic_globs(
        guarded: RunningDaemon, tmp_path: Path) -> None:
    with guarded.connect() as client:
        # The form the policy judges is the one get_parameters is judged by.
        error = refusal(client, "get_parameters", {"node": "/PSM2/robot_state_publisher",
                                                   "names": ["robot_description"]})
        assert "/PSM2/robot_state_publisher.robot_description" in str(error)
        for args, field, got in (
                ({"name": "psm2", "namespace": "PSM2"}, "source.parameter",
                 "/PSM2/robot_state_publisher.robot_description"),
                ({"name": "plain"}, "source.parameter",
                 "/robot_state_publisher.robot_description"),
                ({"name": "abs", "namespace": "PSM1",
                  "source": {"kind": "parameter", "node": "/PSM2/rsp"}},
                 "source.parameter", "/PSM2/rsp.robot_description"),
                ({"name": "psm2t", "namespace": "PSM2", "source": {"kind": "topic"}},
                 "source.topic", "/PSM2/robot_description")):
            error = refusal(client, "create_robot", args)
            assert error.code == ErrorCode.FORBIDDEN and error.field == field, args
            assert got in str(error) and "/PSM1/*" in str(error), str(error)
        assert client.command("list_robots")["robots"] == []
        # Allowed ones: the daemon reads exactly the names the policy judged.
        for args, source in (
                ({"name": "psm1", "namespace": "PSM1"},
                 {"kind": "parameter", "node": "/PSM1/robot_state_publisher",
                  "parameter": "robot_description"}),
                ({"name": "psm1x", "namespace": "PSM2",
                  "source": {"kind": "parameter", "node": "/PSM1/robot_state_publisher"}},
                 {"kind": "parameter", "node": "/PSM1/robot_state_publisher",
                  "parameter": "robot_description"}),
                ({"name": "psm1t", "namespace": "PSM1", "source": {"kind": "topic"}},
                 {"kind": "topic", "topic": "/PSM1/robot_description"})):
            assert client.command("create_robot", args, timeout=30)["source"] == source
        # A file robot reads no parameter and no topic: the globs do not apply.
        urdf = tmp_path / "one_link.urdf"
        urdf.write_text("<robot name='one'><link name='base'/></robot>")
        loaded = client.command("create_robot", {"name": "from_file", "tf_prefix": "PSM1/",
                                                 "source": {"kind": "file",
                                                            "path": str(urdf)}}, timeout=60)
        assert loaded["robot"] == "one" and loaded["root_link"] == "base", loaded
        assert loaded["fixed_frame"] == "PSM1/base", loaded
        for name in ("psm1", "psm1x", "psm1t", "from_file"):
            client.command("remove_robot", {"name": name})


def test_robot_links_are_judged_by_the_frame_globs(guarded: RunningDaemon,
                                                  tmp_path: Path) -> None:
    """A link whose frame is denied is withheld (no transform, no mesh); a robot whose fixed
    frame is denied is refused, before loading when the request names it."""
    urdf = tmp_path / "arm.urdf"
    box = "<visual><geometry><box size='0.01 0.02 0.03'/></geometry></visual>"
    urdf.write_text(
        "<robot name='arm'>"
        f"<link name='base'>{box}</link><link name='arm'>{box}</link>"
        f"<link name='secret_tool'>{box}</link>"
        "<joint name='j1' type='fixed'><parent link='base'/><child link='arm'/></joint>"
        "<joint name='j2' type='fixed'><parent link='arm'/><child link='secret_tool'/>"
        "</joint></robot>")
    source = {"kind": "file", "path": str(urdf)}
    names = DeviceNameRegistry()
    with guarded.connect() as client:
        loaded = client.command("create_robot", {"name": "sec", "tf_prefix": "PSM1/",
                                                 "source": source}, timeout=60)
        try:
            assert [link["link"] for link in loaded["links"]] == ["base", "arm"], loaded
            assert [visual["link"] for visual in loaded["visuals"]] == ["base", "arm"]
            [withheld] = loaded["withheld"]
            assert withheld["link"] == "secret_tool"
            assert withheld["frame"] == "PSM1/secret_tool"
            assert "PSM1/secret*" in withheld["reason"], withheld
            arm_mesh = names.register(NameKey.robot_visual("sec", "arm", 0))
            client.wait_for(arm_mesh, timeout=10)
            status = client.wait_for("urdf:sec", lambda m: m.body.code == StatusCode.OK)
            assert "1 link(s) withheld by the frame policy: secret_tool" in status.body.text
            assert status.metadata["ros2.links"] == "2", status.metadata
            # The root link's pose (identity: it is the fixed frame) has come in the robot's
            # TDATA (nothing publishes the others' tf), and the meshes went out together at
            # load: a withheld link's would be here by now.
            root = wait_link_pose(client, loaded["poses_device"],
                                  names.register(NameKey.robot_link("sec", "base")),
                                  lambda m: np.allclose(m, np.eye(4), atol=1e-9), timeout=10)
            np.testing.assert_allclose(root, np.eye(4), atol=1e-9)
            secret_mesh = names.register(NameKey.robot_visual("sec", "secret_tool", 0))
            secret_link = names.register(NameKey.robot_link("sec", "secret_tool"))
            assert client.latest(secret_mesh) is None and client.latest(secret_link) is None
            poses = client.latest(loaded["poses_device"]).body
            assert secret_link not in {element.name for element in poses.elements}
            listed = client.command("list_robots")["robots"]
            assert [(r["name"], r["links"], r["withheld"]) for r in listed] == [("sec", 2, 1)]
        finally:
            client.command("remove_robot", {"name": "sec"})
        # The fixed frame: named in the request, refused before anything loads ...
        error = refusal(client, "create_robot", {"name": "sec2", "tf_prefix": "PSM1/",
                                                 "fixed_frame": "PSM2/base",
                                                 "source": source})
        assert error.code == ErrorCode.FORBIDDEN and error.field == "fixed_frame"
        assert "PSM2/base" in str(error)
        # ... or the root link's, refused when the URDF says what it is.
        error = refusal(client, "create_robot", {"name": "sec3", "source": source})
        assert error.code == ErrorCode.FORBIDDEN and error.field == "fixed_frame"
        assert "'base'" in str(error) or " base" in str(error), str(error)
        assert client.command("list_robots")["robots"] == []


# ---------------------------------------------------------------------------- --frame-prefix


def test_frame_prefix_makes_relative_frames_the_robot_instance(processes: Processes) -> None:
    daemon = start_daemon(processes, "--frame-prefix", "PSM1/")
    # The arm's frames, and a second arm's that the PSM1 daemon must not mix up.
    processes.python("psm1", "tf_chain_publisher.py", "PSM1/", "--rate", "50")
    processes.python("psm2", "tf_chain_publisher.py", "PSM2/", "--rate", "50",
                     "--moving")
    with daemon.connect() as client:
        created = client.command("create_tf_lookup", {"parent": "base", "child": "tool"})
        assert (created["parent"], created["child"]) == ("PSM1/base", "PSM1/tool")
        streamed = client.wait_for(created["device"], is_matrix(BASE_TOOL), timeout=30)
        assert isinstance(streamed.body, Transform)
        # An absolute frame opts out of the prefix: the same lookup, the same device.
        again = client.command("create_tf_lookup", {"parent": "/PSM1/base", "child": "tool"})
        assert again["existed"] and again["device"] == created["device"]
        one_shot = client.command("lookup_transform", {"parent": "/PSM1/base",
                                                       "child": "/PSM1/tool"})
        np.testing.assert_allclose(one_shot["matrix"], BASE_TOOL, atol=1e-3)
        relative = client.command("lookup_transform", {"parent": "base", "child": "tool"})
        assert (relative["parent"], relative["child"]) == ("PSM1/base", "PSM1/tool")
        # The other arm is still reachable by its absolute names (no globs here).
        other = client.command("lookup_transform", {"parent": "/PSM2/base",
                                                    "child": "/PSM2/link1", "timeout": 10})
        np.testing.assert_allclose(other["matrix"], BASE_LINK1, atol=1e-3)
        tf_buffer = client.command("list_bridges")["tf_buffer"]
        assert tf_buffer["frame_prefix"] == "PSM1/"
    assert_clean_exit(daemon)


def test_frame_prefix_is_explained_by_help(processes: Processes) -> None:
    child = processes.bridge("run", "--help")
    assert child.popen.wait(60) == 0
    text = " ".join(child.output().split())
    assert "--frame-prefix PREFIX" in text and "'base' means 'PSM1/base'" in text
    assert "--allow-frame GLOB" in text and "--deny-frame GLOB" in text
    demo = processes.bridge("demo", "--help")
    assert demo.popen.wait(60) == 0 and "--frame-prefix" in demo.output()
