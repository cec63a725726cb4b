"""What the reference facade asks of the daemon, over real TCP: `describe_type`, a
subscriber's message stream (whole messages, lossless, only to the clients that asked,
with the subscription's count), `publish` of whole messages, and parameter clients that
keep every change of their node."""

from __future__ import annotations

import json

import pytest

from protocol.commands import ErrorCode, TypeDescription
from protocol.messages import Json, Message, RawBody, String
from protocol.naming import KEY_COUNT, KEY_TYPE
from slicer_client.connection import CommandRefusedError, Connection
from support import Processes, RunningDaemon, wait_until

pytestmark = pytest.mark.ros


def test_describe_type_gives_every_type_a_message_is_made_of(client: Connection) -> None:
    described = TypeDescription.from_dict(client.command("describe_type",
                                                         {"type": "PoseArray"}))
    assert described.type == "geometry_msgs/msg/PoseArray"
    assert described.parts == {"message": "geometry_msgs/msg/PoseArray"}
    assert set(described.messages) == {
        "geometry_msgs/msg/PoseArray", "std_msgs/msg/Header", "builtin_interfaces/msg/Time",
        "geometry_msgs/msg/Pose", "geometry_msgs/msg/Point", "geometry_msgs/msg/Quaternion"}
    poses = described.part("message").field("poses")
    assert (poses.type, poses.array) == ("geometry_msgs/msg/Pose", "sequence")
    assert described.messages["geometry_msgs/msg/Quaternion"].default["w"] == 1.0
    service = TypeDescription.from_dict(client.command(
        "describe_type", {"type": "vtkMRMLROS2ServiceClientSetBoolStringNode",
                          "kind": "service"}))
    assert service.parts == {"request": "std_srvs/srv/SetBool_Request",
                             "response": "std_srvs/srv/SetBool_Response"}
    with pytest.raises(CommandRefusedError) as refused:
        client.command("describe_type", {"type": "no_such_pkg/msg/Nope"})
    assert refused.value.code == ErrorCode.UNKNOWN_ROS_TYPE
    assert refused.value.field == "type" and "no_such_pkg" in str(refused.value)


def test_the_message_stream_is_whole_counted_and_private(daemon: RunningDaemon) -> None:
    asker, other = daemon.connect(), daemon.connect()
    try:
        reply = asker.command("create_subscriber", {"topic": "/ms_pose", "type": "PoseStamped",
                                                    "messages": True})
        device = reply["message_device"]
        assert device == "msg:ms_pose"
        # The other client makes the same bridge without asking: no message stream for it.
        assert "message_device" not in other.command(
            "create_subscriber", {"topic": "/ms_pose", "type": "PoseStamped"})
        asker.command("create_publisher", {"topic": "/ms_pose", "type": "PoseStamped"})
        matrix = [[1, 0, 0, 3.1415], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]

        def arrived() -> bool:
            asker.command("publish", {"topic": "/ms_pose", "value": matrix})
            return asker.latest(device) is not None
        wait_until(arrived, timeout=20, what="the message stream")
        first = int(asker.latest(device).metadata[KEY_COUNT])
        assert first >= 1
        # Told apart by its value: the publishes above may still be on their way.
        last = [[1, 0, 0, 2.7182], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
        asker.command("publish", {"topic": "/ms_pose", "value": last})
        message = asker.wait_for(device, lambda m: json.loads(m.body.text)["pose"][
            "position"]["x"] == 2.7182 / 1000)  # whole: not through float32
        # A STRING (what 3D Slicer's connector imports, as a text node) while it fits one.
        assert isinstance(message.body, String)
        assert message.metadata[KEY_TYPE] == "geometry_msgs/msg/PoseStamped"
        assert int(message.metadata[KEY_COUNT]) > first  # the subscription's own count
        # The native stream went to both; the message stream to the one that asked.
        other.wait_for("ms_pose", timeout=10)
        assert device not in other.devices()
        other.send(Message(device_name=device, body=RawBody("GET_JSON", b"")))
        wait_until(lambda: any(device in e for e in other.errors), timeout=10,
                   what="the refusal of a GET_ for another client's stream")
        assert other.latest(device).type_name == "STATUS"  # the refusal, no JSON
    finally:
        asker.close()
        other.close()


def test_a_message_too_long_for_a_string_streams_as_json(client: Connection) -> None:
    """STRING stops at 65535 bytes: a longer message's JSON goes as a JSON message."""
    device = client.command("create_subscriber", {"topic": "/ms_long", "type": "String",
                                                  "messages": True})["message_device"]
    client.command("create_publisher", {"topic": "/ms_long", "type": "String"})
    short, long = "s" * 100, "l" * 70000

    def sent(text: str) -> Message:
        def arrived() -> bool:
            client.command("publish", {"topic": "/ms_long", "message": {"data": text}})
            latest = client.latest(device)
            return latest is not None and json.loads(latest.body.text)["data"] == text
        wait_until(arrived, timeout=20, what=f"a {len(text)}-character message")
        return client.latest(device)
    assert isinstance(sent(short).body, String)
    assert isinstance(sent(long).body, Json)


def test_publish_takes_a_whole_message_checked_strictly(client: Connection) -> None:
    client.command("create_publisher", {"topic": "/ms_joint",
                                                        "type": "JointState"})
    assert client.command("publish", {"topic": "/ms_joint", "message": {
        "name": ["a"], "position": [0.5]}})["subscribers"] >= 0
    with pytest.raises(CommandRefusedError) as refused:
        client.command("publish", {"topic": "/ms_joint", "message": {"position": ["x"]}})
    assert refused.value.code == ErrorCode.WRONG_TYPE
    assert refused.value.field.startswith("message.position")
    with pytest.raises(CommandRefusedError) as refused:
        client.command("publish", {"topic": "/ms_joint", "message": {"nope": 1}})
    assert refused.value.field.startswith("message")
    with pytest.raises(CommandRefusedError, match="either value or message"):
        client.command("publish", {"topic": "/ms_joint", "value": 1, "message": {}})


def test_a_parameter_client_keeps_every_change_when_asked(client: Connection,
                                                          processes: Processes) -> None:
    node = processes.python("params", "param_node.py", "ms_params")
    node.wait_for_output("READY", timeout=30)
    created = client.command("create_parameter_client", {"node": "/ms_params"})
    device = created["device"]
    client.command("observe_parameters", {"node": "/ms_params", "names": ["count"],
                                          "all_changes": True})
    set_reply = client.command("set_parameters", {"node": "/ms_params", "values": {
        "label": {"type": "string", "value": "changed"}}})
    assert set_reply["results"]["label"]["ok"], set_reply
    # The observed value is fetched once the node's services answer (at once, or on the
    # daemon's next readiness check when discovery is slow): wait for both. The node's
    # declarations are events too, and DDS may deliver them late (after a repair), so the
    # label's declared value may be streamed first: wait for the change itself.
    changed = {"type": "string", "value": "changed"}
    streamed = client.wait_for(device, lambda m: isinstance(m.body, String) and "count" in (
        values := json.loads(m.body.text)["values"]) and values.get("label") == changed,
        timeout=20)
    values = json.loads(streamed.body.text)["values"]
    assert values["label"] == changed
    assert values["count"] == {"type": "integer", "value": 3}  # the observed one, fetched


def test_whole_messages_come_at_display_rate_and_the_newest_last(daemon: RunningDaemon) -> None:
    """A facade subscriber asks for each message whole: the daemon makes one when it is
    due (at most one a display frame), not one per message, and the last is the newest,
    with the subscription's exact count. The native stream still brings every message."""
    import threading
    import time

    import slicer_client
    from bridge.topics.whole_messages import DISPLAY_HZ

    published = 300
    arrivals: list[float] = []
    lock = threading.Lock()
    with slicer_client.connect("127.0.0.1", daemon.port) as ros:
        sub = ros.subscribe("/ms_paced", "PoseStamped", messages=True)
        assert sub.message_device == "msg:ms_paced"

        def whole(message: Message) -> None:
            with lock:
                arrivals.append(time.monotonic())
        sub.add_whole_callback(whole)
        pub = ros.publisher("/ms_paced", "PoseStamped")
        start = time.monotonic()
        for i in range(published):
            pub.publish_message({"header": {"frame_id": "paced"},
                                 "pose": {"position": {"x": (i + 1) / 1000.0}}})
        newest = sub.wait_for_whole(lambda m: int(m.metadata[KEY_COUNT]) == published,
                                    timeout=30)
        assert json.loads(newest.body.text)["pose"]["position"]["x"] == published / 1000.0
        sub.wait_for_message(timeout=30, predicate=lambda matrix: abs(
            matrix[0][3] - published) < 1e-3)  # the native stream's newest, in mm
        with lock:
            span, whole_count = arrivals[-1] - start, len(arrivals)
    # Every send of the stream lies between the first publish and the last arrival, each a
    # frame or more after the one before.
    assert 1 <= whole_count <= span * DISPLAY_HZ + 1, (whole_count, span)
