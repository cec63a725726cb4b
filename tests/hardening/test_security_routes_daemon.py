"""Routes around the security policy, tried as a hostile client would (issue 11), on a
running daemon with real rclpy peers: each guard must hold on every route to a resource,
judged by what the peers and the clients really saw, not by the reply alone."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path
from typing import Any, Iterator

import pytest

import slicer_client
from protocol.commands import ErrorCode
from slicer_client.connection import CommandRefusedError, Connection
from support import Child, Processes, RunningDaemon, assert_clean_exit, start_daemon, wait_until

pytestmark = pytest.mark.ros


def refusal(client: Any, op: str, args: dict[str, Any]) -> CommandRefusedError:
    with pytest.raises(CommandRefusedError) as refused:
        client.command(op, args)
    return refused.value


def echoed(echo: Child) -> list[dict[str, Any]]:
    return [json.loads(line[4:]) for line in echo.lines()
            if line.startswith("MSG ")]


def frames_of(value: Any) -> set[str]:
    """Every frame id a TFMessage value (as the daemon gives it) names."""
    return {name for t in value["transforms"]
            for name in (t["header"]["frame_id"], t["child_frame_id"])}


# ---------------------------------------------------------------------------- tf topics


@pytest.fixture(scope="module")
def frames_daemon(module_processes: Processes) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes, "--allow-frame", "PSM1/*")
    yield running
    assert_clean_exit(running)


def test_a_tf_subscriber_passes_on_only_allowed_frames(frames_daemon: RunningDaemon,
                                                       processes: Processes) -> None:
    for prefix in ("PSM1/", "PSM2/"):
        processes.python(f"chain-{prefix[:-1]}", "tf_chain_publisher.py", prefix, "--rate",
                         "20").wait_for_output("READY")
    seen: list[set[str]] = []
    lock = threading.Lock()

    def record(value: Any) -> None:
        with lock:
            seen.append(frames_of(value))

    ros = slicer_client.connect("127.0.0.1", frames_daemon.port)
    try:
        ros.subscribe("/tf", "tf2_msgs/msg/TFMessage", callback=record)
        static = ros.subscribe("/tf_static", "tf2_msgs/msg/TFMessage",
                               qos={"durability": "transient_local"})
        # Both chains publish on /tf: 40 messages cover both publishers many times over.
        wait_until(lambda: len(seen) >= 40, 30, "40 /tf messages")
        static.wait_for_message(20)
        for name in ("/tf", "/tf_static"):
            last = ros.command("get_last_message", {"topic": name, "format": "json"})
            assert last["received"] and "PSM2" not in last["text"], last
            assert frames_of(last["value"]) <= {"PSM1/world", "PSM1/base", "PSM1/link1",
                                                "PSM1/tool"}, last
    finally:
        ros.close()
    with lock:
        every = set().union(*seen)
    assert "PSM1/tool" in every  # the allowed chain does come through
    assert not any(frame.startswith("PSM2/") for frame in every), every


def test_a_tf_publisher_refuses_denied_frames(frames_daemon: RunningDaemon,
                                              processes: Processes) -> None:
    echo = processes.python("echo-tf", "echo_subscriber.py", "/tf", "tf2_msgs/msg/TFMessage")
    echo.wait_for_output("READY")

    def message(parent: str, child: str) -> dict[str, Any]:
        return {"transforms": [{"header": {"frame_id": parent}, "child_frame_id": child,
                                "transform": {"rotation": {"w": 1.0}}}]}

    with frames_daemon.connect() as client:
        client.command("create_publisher", {"topic": "/tf", "type": "tf2_msgs/msg/TFMessage"})
        for parent, child, field in (("PSM1/base", "PSM2/needle", "child_frame_id"),
                                     ("PSM2/base", "PSM1/needle", "header.frame_id")):
            error = refusal(client, "publish", {"topic": "/tf",
                                                "value": message(parent, child)})
            assert error.code == ErrorCode.FORBIDDEN
            assert error.field == f"value.transforms[0].{field}" and "PSM1/*" in str(error)
        # An allowed transform reaches ROS (the witness is not deaf).
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and not any(
                t["child_frame_id"] == "PSM1/needle" for m in echoed(echo)
                for t in m["transforms"]):
            client.command("publish", {"topic": "/tf",
                                       "value": message("PSM1/base", "PSM1/needle")})
            time.sleep(0.1)
    names = {name for m in echoed(echo) for name in frames_of(m)}
    assert "PSM1/needle" in names
    assert not any(name.startswith("PSM2/") for name in names), names


def test_tf_topics_take_only_tf_messages_under_frame_globs(frames_daemon: RunningDaemon,
                                                           ) -> None:
    with frames_daemon.connect() as client:
        error = refusal(client, "create_publisher", {"topic": "/tf_static", "type": "String"})
        assert error.code == ErrorCode.FORBIDDEN and error.field == "type"


# ---------------------------------------------------------------------------- parameters


@pytest.fixture(scope="module")
def parameters_daemon(module_processes: Processes) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes, "--allow-parameter", "/slicer_bridge.*",
                           "--allow-parameter", "/guarded_node.ratio")
    yield running
    assert_clean_exit(running)


def test_parameter_services_of_any_node_fall_under_the_parameter_globs(
        parameters_daemon: RunningDaemon, processes: Processes) -> None:
    peer = processes.python("guarded", "param_node.py", "guarded_node")
    peer.wait_for_output("READY")
    with parameters_daemon.connect() as client:
        for service, kind, request in (
                ("get_parameters", "GetParameters", {"names": ["count"]}),
                ("describe_parameters", "DescribeParameters", {"names": ["count"]}),
                ("set_parameters", "SetParameters", {"parameters": [
                    {"name": "count", "value": {"type": 2, "integer_value": 99}}]}),
                ("set_parameters_atomically", "SetParametersAtomically", {"parameters": [
                    {"name": "count", "value": {"type": 2, "integer_value": 98}}]})):
            error = refusal(client, "call_service", {
                "service": f"/guarded_node/{service}", "type": f"rcl_interfaces/srv/{kind}",
                "request": request, "timeout": 15})
            assert error.code == ErrorCode.FORBIDDEN, service
            assert "/guarded_node.count" in str(error), service
        # An allowed parameter goes through, so the peer's silence about `count` means
        # the refused calls never reached it.
        allowed = client.command("call_service", {
            "service": "/guarded_node/set_parameters", "type": "rcl_interfaces/srv/SetParameters",
            "request": {"parameters": [{"name": "ratio", "value": {"type": 3,
                                                                  "double_value": 0.5}}]},
            "timeout": 15})
        assert allowed["response"]["results"][0]["successful"]
        peer.wait_for_output('"ratio"')
        assert '"count"' not in peer.output()
        # A listing shows only what the globs allow.
        listed = client.command("call_service", {
            "service": "/guarded_node/list_parameters", "type": "rcl_interfaces/srv/ListParameters",
            "request": {}, "timeout": 15})
        assert listed["response"]["result"]["names"] == ["ratio"]
        # Answering for a node's parameters cannot be judged name by name.
        error = refusal(client, "advertise_service", {"service": "/ghost_node/get_parameters",
                                                     "type": "rcl_interfaces/srv/GetParameters"})
        assert error.code == ErrorCode.FORBIDDEN


def test_parameter_events_show_only_allowed_parameters(parameters_daemon: RunningDaemon,
                                                       processes: Processes) -> None:
    peer = processes.python("guarded-events", "param_node.py", "guarded_node")
    peer.wait_for_output("READY")
    ros = slicer_client.connect("127.0.0.1", parameters_daemon.port)
    seen: list[dict[str, Any]] = []
    try:
        ros.subscribe("/parameter_events", "rcl_interfaces/msg/ParameterEvent",
                      callback=seen.append)
        # Until the subscription has matched the node's event publisher, events are lost:
        # set count, then ratio, until ratio's event arrives (count's, in order, before it).
        deadline = time.monotonic() + 60
        for value in range(1, 1000):
            caller = processes.python("setter", "param_caller.py", "/guarded_node",
                                      f'{{"set": "count", "type": "integer", "value": {value}}}',
                                      f'{{"set": "ratio", "type": "double", "value": {value}.5}}')
            assert caller.popen.wait(60) == 0, caller.output()
            if any(p["name"] == "ratio" for e in list(seen) for p in e["changed_parameters"]) \
                    or time.monotonic() > deadline:
                break
    finally:
        ros.close()
    named = {f"{e['node']}.{p['name']}" for e in seen
             for key in ("new_parameters", "changed_parameters", "deleted_parameters")
             for p in e[key]}
    assert "/guarded_node.ratio" in named
    assert "/guarded_node.count" not in named, named


def test_a_parameter_event_publisher_refuses_denied_parameters(
        parameters_daemon: RunningDaemon, processes: Processes) -> None:
    """A client that publishes on /parameter_events could tell every node's watchers that a
    denied parameter changed: the event is judged parameter by parameter, as every other
    parameter route, and only an event naming allowed parameters reaches ROS."""
    echo = processes.python("echo-events", "echo_subscriber.py", "/parameter_events",
                            "rcl_interfaces/msg/ParameterEvent")
    echo.wait_for_output("READY")

    def event(*names: str) -> dict[str, Any]:
        return {"node": "/guarded_node", "changed_parameters": [
            {"name": name, "value": {"type": 3, "double_value": 2.5}} for name in names]}

    def forged() -> list[str]:  # parameters of the events the witness saw from us
        return [p["name"] for m in echoed(echo) if m["node"] == "/guarded_node"
                for p in m["changed_parameters"]]

    with parameters_daemon.connect() as client:
        client.command("create_publisher", {"topic": "/parameter_events",
                                            "type": "rcl_interfaces/msg/ParameterEvent"})
        error = refusal(client, "publish", {"topic": "/parameter_events",
                                            "value": event("ratio", "count")})
        assert error.code == ErrorCode.FORBIDDEN
        assert error.field == "value.changed_parameters"
        assert "/guarded_node.count" in str(error)
        # The allowed one reaches ROS (the witness is not deaf): sent until it is seen, as
        # the publisher may not have matched the witness yet.
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and "ratio" not in forged():
            client.command("publish", {"topic": "/parameter_events", "value": event("ratio")})
            time.sleep(0.1)
    assert set(forged()) == {"ratio"}, forged()


# ---------------------------------------------------------------------------- files

STL = ("solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
       "endloop\nendfacet\nendsolid t\n")


def urdf(meshes: dict[str, str]) -> str:
    links = "".join(f'<link name="{name}"><visual><geometry><mesh filename="{uri}"/>'
                    f'</geometry></visual></link>' for name, uri in meshes.items())
    joints = "".join(f'<joint name="j_{name}" type="fixed"><parent link="base"/>'
                     f'<child link="{name}"/></joint>' for name in meshes)
    return f'<robot name="evil"><link name="base"/>{links}{joints}</robot>'


@pytest.fixture(scope="module")
def folders(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("files")
    out = {"allowed": root / "allowed", "outside": root / "outside"}
    for folder in out.values():
        folder.mkdir()
    (out["allowed"] / "inside.stl").write_text(STL)
    (out["outside"] / "secret.stl").write_text(STL)
    return out


@pytest.fixture(scope="module")
def files_daemon(module_processes: Processes, folders: dict[str, Path],
                 ) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes, "--robot-dir", str(folders["allowed"]))
    yield running
    assert_clean_exit(running)


@pytest.mark.parametrize("source", ["server_parameter", "topic"])
def test_a_clients_robot_reads_meshes_only_inside_the_robot_dirs(
        files_daemon: RunningDaemon, folders: dict[str, Path], source: str) -> None:
    secret = folders["outside"] / "secret.stl"
    missing = folders["outside"] / "missing.stl"
    text = urdf({"inside": (folders["allowed"] / "inside.stl").as_uri(),
                 "secret": secret.as_uri(), "missing": missing.as_uri()})
    name = f"evil_{source}"
    with files_daemon.connect() as client:
        if source == "server_parameter":
            client.command("server_declare_parameter", {"name": f"{name}_urdf", "value": {
                "type": "string", "value": text}})
            spec = {"kind": "parameter", "node": "/slicer_bridge", "parameter": f"{name}_urdf"}
        else:
            topic = f"/{name}_description"
            client.command("create_publisher", {"topic": topic, "type": "String", "qos": {
                "durability": "transient_local", "depth": 1}})
            client.command("publish", {"topic": topic, "value": text})
            spec = {"kind": "topic", "topic": topic}
        robot = client.command("create_robot", {"name": name, "source": spec}, timeout=30)
        assert robot["state"] == "loaded", robot
        assert [v["link"] for v in robot["visuals"]] == ["inside"], robot["visuals"]
        # The client got a model for the allowed mesh only.
        client.wait_for(robot["visuals"][0]["device"], timeout=10)
        assert not any(d.startswith(f"{name}:secret") for d in client.devices())
        # A refused file and a missing one get the same words (but their own URI).
        words = {}
        for warning in robot["warnings"]:
            for link, path in (("secret", secret), ("missing", missing)):
                if path.as_uri() in warning:
                    words[link] = warning.replace(path.as_uri(), "X").replace(link, "L")
        assert set(words) == {"secret", "missing"}, robot["warnings"]
        assert words["secret"] == words["missing"]
        assert "exist" not in " ".join(robot["warnings"]).replace("an existing file", "")
        client.command("remove_robot", {"name": name})


def test_an_operators_robot_reads_a_changed_description_s_meshes_only_inside(
        processes: Processes, folders: dict[str, Path], tmp_path: Path) -> None:
    # The operator's robot reads another node's parameter; a client (or any ROS peer) can
    # change that parameter, so what it names is not the operator's to vouch for.
    inside = (folders["allowed"] / "inside.stl").as_uri()
    peer = processes.python("victim", "param_node.py", "victim_rsp", "--description",
                            urdf({"inside": inside}))
    peer.wait_for_output("READY")
    config = tmp_path / "bridge.yaml"
    config.write_text("robots:\n  - {name: op_robot, source: {kind: parameter, "
                      "node: /victim_rsp}}\n")
    daemon = start_daemon(processes, "--config", str(config),
                          "--robot-dir", str(folders["allowed"]))

    def robot(client: Connection) -> dict[str, Any]:
        return client.command("list_robots")["robots"][0]

    with daemon.connect() as client:
        wait_until(lambda: robot(client)["loads"] >= 1, 30, "the operator's robot")
        assert robot(client)["visuals"] == 1
        evil = urdf({"inside": inside, "secret": (folders["outside"] / "secret.stl").as_uri()})
        client.command("call_service", {
            "service": "/victim_rsp/set_parameters", "type": "rcl_interfaces/srv/SetParameters",
            "request": {"parameters": [{"name": "robot_description",
                                        "value": {"type": 4, "string_value": evil}}]},
            "timeout": 15})
        wait_until(lambda: robot(client)["loads"] >= 2, 30, "the reload")
        assert robot(client)["visuals"] == 1, robot(client)
        assert not any(d.startswith("op_robot:secret") for d in client.devices())
    assert_clean_exit(daemon)


def test_a_refused_urdf_file_and_a_missing_one_get_the_same_reply(
        files_daemon: RunningDaemon, folders: dict[str, Path]) -> None:
    (folders["outside"] / "robot.urdf").write_text(urdf({}))
    replies = []
    with files_daemon.connect() as client:
        for path in (folders["outside"] / "robot.urdf", folders["outside"] / "nothing.urdf"):
            error = refusal(client, "create_robot", {"name": "r", "source": {
                "kind": "file", "path": str(path)}})
            assert error.code == ErrorCode.FORBIDDEN and error.field == "source.path"
            replies.append(str(error).replace(str(path), "X"))
    assert replies[0] == replies[1]


# ---------------------------------------------------------------------------- ownership


def operator_config(tmp_path: Path, topic: str) -> Path:
    path = tmp_path / "bridge.yaml"
    path.write_text(f"subscribers:\n  - {{topic: {topic}, type: String}}\n")
    return path


@pytest.mark.parametrize("read_only", [False, True])
def test_no_client_removes_the_operators_bridges(processes: Processes, tmp_path: Path,
                                                 read_only: bool) -> None:
    topic = "/operator_feed"
    extra = ["--read-only"] if read_only else []
    daemon = start_daemon(processes, "--config", str(operator_config(tmp_path, topic)), *extra)
    with daemon.connect() as hostile:
        error = refusal(hostile, "remove_subscriber", {"topic": topic})
        assert error.code == ErrorCode.FORBIDDEN
        assert ("read-only" if read_only else "operator") in str(error)
        if read_only:  # read-only clients remove nothing, not even their own bridges
            hostile.command("create_subscriber", {"topic": "/mine", "type": "String"})
            assert refusal(hostile, "remove_subscriber", {"topic": "/mine"}).code == \
                ErrorCode.FORBIDDEN
    # Every other client still gets the operator's stream from a real publisher.
    publisher = processes.python("feed", "publish_json.py", topic, "std_msgs/msg/String",
                                 '{"data": "still here"}')
    publisher.wait_for_output("READY")
    with daemon.connect() as other:
        bridges = other.command("list_bridges")["bridges"]
        device = next(b["device"] for b in bridges if b.get("topic") == topic)
        assert other.wait_for(device, timeout=20).body.text == "still here"
    assert_clean_exit(daemon)


def test_the_facade_removes_from_a_new_connection_what_the_rules_allow(
        processes: Processes, tmp_path: Path) -> None:
    daemon = start_daemon(processes, "--config",
                          str(operator_config(tmp_path, "/operator_feed")))
    first = slicer_client.connect("127.0.0.1", daemon.port)
    first.GetDefaultROS2Node().CreateAndAddSubscriberNode("String", "/client_feed")
    first.GetDefaultROS2Node().CreateAndAddTf2LookupNode("a", "b")
    # Kept, so that they outlive this connection (else they would end with it).
    first.find("create_subscriber", "/client_feed").keep()
    first.find("create_tf_lookup", "a", "b").keep()
    first.close()
    second = slicer_client.connect("127.0.0.1", daemon.port)
    try:
        node = second.GetDefaultROS2Node()
        assert node.RemoveAndDeleteSubscriberNode("/client_feed") is True
        assert node.RemoveAndDeleteTf2LookupNode("a", "b") is True
        assert node.RemoveAndDeleteSubscriberNode("/client_feed") is False  # gone now
        with pytest.raises(CommandRefusedError) as refused:
            node.RemoveAndDeleteSubscriberNode("/operator_feed")
        assert refused.value.code == ErrorCode.FORBIDDEN
        topics = {b.get("topic") for b in second.list_bridges()["bridges"]}
        assert "/client_feed" not in topics and "/operator_feed" in topics
    finally:
        second.close()
    # The ROS graph agrees: the daemon no longer subscribes to the removed topic.
    deadline = time.monotonic() + 20
    with Connection("127.0.0.1", daemon.port) as probe:
        while time.monotonic() < deadline:
            names = {t["topic"] for t in probe.command("list_topics")["topics"]}
            if "/client_feed" not in names:
                break
            time.sleep(0.1)
        assert "/client_feed" not in names and "/operator_feed" in names
    assert_clean_exit(daemon)


def test_the_daemon_serves_every_client_op_the_schema_declares(frames_daemon: RunningDaemon,
                                                               ) -> None:
    from protocol.commands import REQUEST_TYPES

    with frames_daemon.connect() as client:
        ops = client.command("hello")["ops"]
        assert ops == sorted(op for op, cls in REQUEST_TYPES.items() if not cls.to_client)
        error = refusal(client, "service_request", {"service": "/s", "type": "std_srvs/Trigger",
                                                    "request": {}})
        assert error.code == ErrorCode.NOT_SUPPORTED  # the daemon's to send, not to serve


# ---------------------------------------------------------------------------- actions

GRIPPER = "control_msgs/action/GripperCommand"


def test_an_action_guard_holds_on_every_route(processes: Processes) -> None:
    """--deny-action: the action op, its hidden services and its topics are all refused,
    and the real server never sees a goal."""
    server = processes.python("gripper", "gripper_action_server.py", "--action", "/arm/grip")
    server.wait_for_output("READY")
    daemon = start_daemon(processes, "--deny-action", "/arm/*")
    client = daemon.connect()
    try:
        wait_until(lambda: any(a["action"] == "/arm/grip" for a in
                               client.command("list_actions")["actions"]), 20,
                   "the action listed (listing is not refused)")
        goal = {"command": {"position": 1.0, "max_effort": 1.0}}
        routes = [
            ("send_goal", {"action": "/arm/grip", "type": GRIPPER, "goal": goal}),
            ("cancel_goal", {"action": "/arm/grip", "goal_id": "0" * 32}),
            ("advertise_action", {"action": "/arm/other", "type": GRIPPER}),
            ("call_service", {"service": "/arm/grip/_action/cancel_goal",
                              "type": "action_msgs/srv/CancelGoal", "request": {}}),
            ("advertise_service", {"service": "/arm/grip2/_action/get_result",
                                   "type": "std_srvs/srv/Trigger"}),
            ("create_subscriber", {"topic": "/arm/grip/_action/status",
                                   "type": "action_msgs/msg/GoalStatusArray"}),
            ("create_publisher", {"topic": "/arm/grip/_action/status",
                                  "type": "action_msgs/msg/GoalStatusArray"}),
        ]
        for op, args in routes:
            error = refusal(client, op, args)
            assert error.code == ErrorCode.FORBIDDEN, (op, error)
            assert "/arm/*" in str(error), (op, error)
    finally:
        client.close()
    assert "GOAL" not in server.output() and "CANCEL" not in server.output()


def test_read_only_clients_list_and_watch_actions_but_send_nothing(processes: Processes
                                                                   ) -> None:
    server = processes.python("gripper", "gripper_action_server.py", "--action", "/grip")
    server.wait_for_output("READY")
    daemon = start_daemon(processes, "--read-only")
    client = daemon.connect()
    try:
        wait_until(lambda: any(a["action"] == "/grip" for a in
                               client.command("list_actions")["actions"]), 20, "/grip listed")
        client.command("create_subscriber", {"topic": "/grip/_action/status",
                                             "type": "action_msgs/msg/GoalStatusArray"})
        for op, args in [("send_goal", {"action": "/grip", "type": GRIPPER}),
                         ("cancel_goal", {"action": "/grip", "goal_id": "0" * 32}),
                         ("advertise_action", {"action": "/mine", "type": GRIPPER})]:
            error = refusal(client, op, args)
            assert error.code == ErrorCode.FORBIDDEN and "read-only" in str(error), op
    finally:
        client.close()
    assert "GOAL" not in server.output()
