"""The Pythonic API against a real daemon: callbacks and their threads, the spin mode,
errors that say what went wrong, and daemon restarts."""

from __future__ import annotations

import threading

import numpy as np
import pytest

import slicer_client
from protocol.commands import ErrorCode
from protocol.messages import Transform
from support import Processes, RunningDaemon, pick_free_port, scaled, wait_until

pytestmark = pytest.mark.ros


def test_subscriber_callback_runs_on_the_dispatcher_thread(ros: slicer_client.Client) -> None:
    """Nobody spins: the dispatcher thread runs it, never the receive thread (a callback
    there could not wait for a reply that same thread must read)."""
    threads: list[str] = []
    got = threading.Event()

    def on_value(value) -> None:
        threads.append(threading.current_thread().name)
        got.set()

    sub = ros.subscribe("/py_cb", "String", callback=on_value)
    pub = ros.publisher("/py_cb", "String")
    wait_until(lambda: pub.publish("x") >= 1 and got.wait(0.1), timeout=20,
               what="the callback")
    assert threads[0] == "slicer-client-callbacks"
    assert sub.last_value == "x" and sub.count >= 1
    assert sub.last_message_yaml() == "data: x\n"
    assert ros.subscribe("/py_cb", "String") is sub  # idempotent, like the daemon


def test_spin_mode_runs_callbacks_in_the_spinning_thread(daemon: RunningDaemon) -> None:
    with slicer_client.connect("127.0.0.1", daemon.port, callbacks="spin") as ros:
        seen: list[tuple[object, str]] = []
        ros.subscribe("/py_queue", "Int", callback=lambda v: seen.append(
            (v, threading.current_thread().name)))
        pub = ros.publisher("/py_queue", "Int")
        wait_until(lambda: pub.publish(5) >= 1 and ros.process_events(timeout=0.1) > 0,
                   timeout=20, what="a queued callback")
        assert seen[0] == (5, threading.current_thread().name)


def test_pose_publisher_streams_igtl_transforms_to_ros(ros: slicer_client.Client,
                                                       processes: Processes) -> None:
    echo = processes.python("echo", "echo_subscriber.py", "/py_stream",
                            "geometry_msgs/msg/PoseStamped")
    echo.wait_for_output("READY", timeout=30)
    pub = ros.publisher("/py_stream", "PoseStamped")
    matrix = np.eye(4)
    matrix[2, 3] = 250.0
    def received() -> bool:
        pub.send(matrix)  # a TRANSFORM under the publisher's device, no reply
        return "MSG " in echo.output()
    wait_until(received, timeout=20, what="the streamed pose in ROS")
    assert '"z": 0.25' in echo.output()


def test_refusal_names_the_op_the_field_and_why(ros: slicer_client.Client) -> None:
    with pytest.raises(slicer_client.CommandRefusedError) as caught:
        ros.subscribe("/py_bad", "String", qos={"depth": 0})
    error = caught.value
    assert error.op == "create_subscriber"
    assert error.field == "qos.depth"
    assert error.code == ErrorCode.OUT_OF_RANGE
    assert "qos.depth" in str(error) and "got 0" in str(error)
    with pytest.raises(slicer_client.CommandRefusedError, match="NOT_FOUND"):
        ros.command("remove_subscriber", {"topic": "/py_never_made"})
    assert ros.find("create_subscriber", "/py_bad") is None


def test_bad_matrix_is_refused_before_sending(ros: slicer_client.Client) -> None:
    broadcaster = ros.tf_broadcaster("py_w", "py_c")
    with pytest.raises(slicer_client.MatrixError, match="matrix"):
        broadcaster.broadcast(np.full((4, 4), 2.0))
    with pytest.raises(slicer_client.MatrixError, match=r"shape \(4, 4\)"):
        broadcaster.broadcast([[1, 0], [0, 1]])


def test_a_daemon_that_is_not_running_gives_a_clear_error() -> None:
    port = pick_free_port()
    with pytest.raises(slicer_client.DaemonUnreachableError) as caught:
        slicer_client.connect("127.0.0.1", port)
    text = str(caught.value)
    assert f"127.0.0.1:{port}" in text
    assert "slicer-ros2-bridge run" in text


def test_state_lists_what_was_created_in_order(ros: slicer_client.Client,
                                               daemon: RunningDaemon) -> None:
    ros.subscribe("/py_state_a", "String")
    ros.publisher("/py_state_b", "PoseStamped", qos={"depth": 1})
    ros.tf_lookup("py_w", "py_tool", rate_hz=30)
    state = slicer_client.BridgeState.from_json(ros.state().to_json())
    assert [s.key for s in state.specs] == [
        ("create_subscriber", "/py_state_a"), ("create_publisher", "/py_state_b"),
        ("create_tf_lookup", "py_w", "py_tool")]
    # Restoring into another client re-creates the same bridges.
    with slicer_client.connect("127.0.0.1", daemon.port) as other:
        made = other.restore(state)
        assert [r.spec for r in made] == list(state.specs)


def test_reconnects_after_a_daemon_restart_and_restores_subscriptions(
        processes: Processes) -> None:
    port = pick_free_port()
    first = processes.bridge("run", "--port", str(port))
    first.wait_for_output("listening on", timeout=30)
    changes: list[tuple[bool, str]] = []
    with slicer_client.connect("127.0.0.1", port, retry_interval=0.1) as ros:
        ros.on_connection_change(lambda up, why: changes.append((up, why)))
        sub = ros.subscribe("/py_restart", "PoseStamped")
        processes.python("pose", "pose_publisher.py", "/py_restart", "0.001", "0", "0",
                         "0", "0", "0", "1")
        sub.wait_for_message(timeout=30)
        before = sub.count
        assert first.stop() == 0
        wait_until(lambda: not ros.connected, timeout=10, what="the client to see the loss")
        wait_until(lambda: bool(changes) and changes[0][0] is False, timeout=10,
                   what="the loss's callback")
        with pytest.raises(slicer_client.ConnectionClosedError, match=f"127.0.0.1:{port}"):
            ros.command("list_bridges", timeout=0.2)
        second = processes.bridge("run", "--port", str(port))
        second.wait_for_output("listening on", timeout=30)
        wait_until(lambda: ros.connected, timeout=30, what="the client to reconnect")
        # Connection callbacks run where callbacks run (not on the receive thread): after.
        wait_until(lambda: changes[-1] == (True, ""), timeout=30, what="the callback")
        # The same object streams again: the new daemon got the subscription back.
        wait_until(lambda: sub.count > before + 3, timeout=30, what="messages after restart")
        np.testing.assert_allclose(sub.last_value[0, 3], 1.0, atol=1e-6)
        listed = ros.list_bridges()["bridges"]
        assert any(b.get("topic") == "/py_restart" for b in listed)
        assert isinstance(ros.latest(sub.device).body, Transform)


def test_service_call_through_the_pythonic_api_and_the_facade(ros: slicer_client.Client,
                                                               processes: Processes) -> None:
    server = processes.python("services", "service_server.py", "--namespace", "/py_srv")
    server.wait_for_output("READY", timeout=30)
    service = ros.service("/py_srv/set_enabled", "std_srvs/srv/SetBool")
    response = service.call({"data": True}, timeout=15.0)  # the first call may wait for discovery
    assert response["success"] is True
    server.wait_for_output('CALL set_enabled {"data": true}')
    node = ros.GetDefaultROS2Node().CreateAndAddServiceClientNode("std_srvs/srv/Trigger",
                                                                  "/py_srv/trigger")
    assert node.SendBlockingRequest({}).GetSuccess() is True  # a message object
    assert node.GetLastResponse().GetSuccess() is True
    with pytest.raises(slicer_client.CommandRefusedError) as caught:
        ros.service("/py_srv/nobody_here", "std_srvs/srv/Trigger").call({}, timeout=0.5)
    assert caught.value.code in (ErrorCode.UNAVAILABLE, ErrorCode.TIMEOUT)


def test_hello_replies_what_protocol_readme_documents(ros: slicer_client.Client) -> None:
    import re

    from support import REPO

    row = next(line for line in (REPO / "protocol" / "README.md").read_text().splitlines()
               if line.startswith("| `hello` |"))
    documented = set(re.findall(r'"(\w+)":', row.split("|")[3]))
    reply = ros.command("hello", {"client": "test"})
    assert set(reply) == documented
    assert reply["schema"] == 1 and reply["ops"] == sorted(reply["ops"])
    assert reply["node"] == "/slicer_bridge"


def test_a_wait_on_a_topic_nobody_publishes_says_so(ros: slicer_client.Client,
                                                     processes: Processes) -> None:
    """Issue 43, item 10: a subscription's wait timed out on a topic nobody publishes with
    no hint. It now ends "no publisher of <topic> on the ROS graph"; with a publisher (the
    wait's predicate unmet) it does not."""
    silent = ros.subscribe("/py_nobody", "std_msgs/msg/String")
    with pytest.raises(TimeoutError) as error:
        silent.wait_for_message(timeout=0.5)
    assert str(error.value).startswith("a message on /py_nobody: nothing within 0.5 s")
    assert str(error.value).endswith("; no publisher of /py_nobody on the ROS graph")
    processes.python("pose", "pose_publisher.py", "/py_posed", "1", "2", "3", "0", "0", "0",
                     "1").wait_for_output("READY", timeout=30)
    posed = ros.subscribe("/py_posed", "PoseStamped")
    posed.wait_for_message(timeout=scaled(30))
    with pytest.raises(TimeoutError) as error:
        posed.wait_for_message(timeout=0.5, predicate=lambda matrix: False)
    assert "no publisher" not in str(error.value)


def test_the_live_daemon_refuses_the_players_ops(ros: slicer_client.Client) -> None:
    """Pause, seek and the rest are a player's (`slicer-ros2-bridge play`): the live daemon
    refuses each, saying so, and keeps serving."""
    from support import refused

    for call in (ros.playback, ros.pause, ros.resume, lambda: ros.seek(1.0),
                 lambda: ros.set_rate(2.0)):
        error = refused(call)
        assert error.code == ErrorCode.NOT_SUPPORTED
        assert "slicer-ros2-bridge play" in str(error)
    assert ros.list_topics() is not None


def test_a_type_clash_with_a_kept_bridge_says_how_to_share_or_remove_it(
        daemon: RunningDaemon) -> None:
    """Issue 43, item 7: a script's bridge on /py_force (Float64) it kept outlives it; a
    later script asking for Float32 is told the type there and how to remove the bridge,
    and the removal it names works. (One not kept ends with its script:
    tests/bridge/test_bridge_owners.py.)"""
    with slicer_client.connect("127.0.0.1", daemon.port) as first:
        first.subscribe("/py_force", "std_msgs/msg/Float64").keep()
    with slicer_client.connect("127.0.0.1", daemon.port) as later:
        with pytest.raises(slicer_client.CommandRefusedError) as clash:
            later.subscribe("/py_force", "std_msgs/msg/Float32")
        assert clash.value.code == ErrorCode.ALREADY_EXISTS
        message = str(clash.value)
        assert "expected std_msgs/msg/Float64 (the subscriber bridge on /py_force has it" \
            in message
        assert 'op remove_subscriber {"topic": "/py_force"}' in message
        assert 'ros.remove_bridge("create_subscriber", "/py_force")' in message
        assert later.remove_bridge("create_subscriber", "/py_force") is True
        assert later.subscribe("/py_force", "std_msgs/msg/Float32").type == \
            "std_msgs/msg/Float32"
