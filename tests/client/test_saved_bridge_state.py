"""A client's bridges saved as a `BridgeState` (what the module keeps in a Slicer scene) and
re-created by another client of a real daemon: every kind with a Pythonic class, with its
options and follow-ups (a parameter client's observed names); and saved text that cannot be
read, refused naming the entry and field."""

from __future__ import annotations

import json

import pytest

import slicer_client
from slicer_client.bridge_state import BridgeState, StateFormatError
from support import Processes, RunningDaemon, wait_until

pytestmark = pytest.mark.ros


def _bridges(client: slicer_client.Client) -> set[tuple[str, str]]:
    listed = client.command("list_bridges")["bridges"]
    return {(b["kind"], f"{b['parent']}->{b['child']}" if "parent" in b
             else b.get("topic") or b.get("node") or b.get("name")) for b in listed}


def test_a_saved_state_recreates_every_kind_in_another_client(
        daemon: RunningDaemon, processes: Processes) -> None:
    peer = processes.python("bs_params", "param_node.py", "bs_params")
    peer.wait_for_output("READY", timeout=30)
    with slicer_client.connect("127.0.0.1", daemon.port) as first:
        first.publisher("/bs_pose", "geometry_msgs/msg/PoseStamped", frame="bs_frame")
        first.subscribe("/bs_sub", "std_msgs/msg/String", rate_hz=5.0, messages=True)
        params = first.parameters("/bs_params")
        params.observe(["count"], all_changes=True)
        first.tf_lookup("bs_world", "bs_tool", rate_hz=10.0)
        first.tf_broadcaster("bs_world", "bs_fixed", static=True)
        first.robot("bs_robot", namespace="bs_nowhere", wait=True)  # its node never comes
        first.markers("/bs_markers", "visualization_msgs/msg/MarkerArray", "bs_world")
        saved = first.state().to_json()
    state = BridgeState.from_json(saved)
    ops = [spec.op for spec in state.specs]
    assert len(ops) == 7 and len(set(ops)) == 7
    with slicer_client.connect("127.0.0.1", daemon.port) as second:
        made = second.restore(state)
        assert [r.spec for r in made] == list(state.specs)
        kinds = _bridges(second)
        for expected in (("publisher", "/bs_pose"), ("subscriber", "/bs_sub"),
                         ("tf_lookup", "bs_world->bs_tool"),
                         ("tf_broadcaster", "bs_world->bs_fixed"),
                         ("robot", "bs_robot"), ("marker_subscriber", "/bs_markers"),
                         ("parameter_client", "/bs_params")):
            assert expected in kinds, (expected, kinds)
        restored = second.find("create_parameter_client", "/bs_params")
        assert restored is not None
        # The observed names came back with it: a change made in ROS reaches this client.
        seen: list = []
        restored.add_callback(lambda name, value: seen.append((name, value)))
        params2 = second.parameters("/bs_params")
        params2.set("count", 11)
        wait_until(lambda: ("count", 11) in seen, timeout=20, what="the observed change")
        assert second.find("create_tf_broadcaster", "bs_world", "bs_fixed").spec.args[
            "static"] is True


@pytest.mark.parametrize("text, message", [
    ("[1]", "saved bridge state: expected a JSON object"),
    ("{not json", "saved bridge state: expected JSON, got"),
    ('{"version": 0}', "saved bridge state: version 1 expected, got 0"),
    ('{"version": 1, "bridges": {}}', "saved bridge state.bridges: expected a list"),
    ('{"version": 1, "bridges": [3]}', "bridges[0]: expected an object, got int"),
    ('{"version": 1, "bridges": [{"op": "create_nothing"}]}',
     "bridges[0].op: expected one of"),
    ('{"version": 1, "bridges": [{"op": "create_subscriber", "args": []}]}',
     "bridges[0].args: expected an object, got list"),
    ('{"version": 1, "bridges": [{"op": "create_parameter_client", "args": {"node": "/n"},'
     ' "then": [{"op": "remove_subscriber"}]}]}', "bridges[0].then[0]: expected {'op':"),
    ('{"version": 1, "bridges": [{"op": "create_subscriber", "args": {"topic": "/t"}}]}',
     "bridges[0]: create_subscriber arguments:"),
    ('{"version": 1, "bridges": [{"op": "create_subscriber", "args": {"topic": "/t", '
     '"type": "String"}, "kept": 1}]}', "bridges[0].kept: expected true or false, got 1"),
])
def test_saved_text_that_cannot_be_read_names_the_entry(text: str, message: str) -> None:
    from slicer_client.bridge_state import STATE_VERSION
    text = text.replace('"version": 1', f'"version": {STATE_VERSION}')
    message = message.replace("version 1 expected", f"version {STATE_VERSION} expected")
    with pytest.raises(StateFormatError) as error:
        BridgeState.from_json(text)
    assert str(error.value).startswith(message), str(error.value)


def test_an_empty_saved_state_is_no_bridges() -> None:
    assert BridgeState.from_json("  ").specs == ()
    state = BridgeState(extra={"host": "h"})
    assert json.loads(state.to_json())["extra"] == {"host": "h"}
    assert BridgeState.from_json(state.to_json()).extra == {"host": "h"}
