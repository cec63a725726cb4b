"""Markers as an attack surface (issue 22, items 2, 3 and 6): frames judged as they are
used, memory budgets refused before anything is allocated, and other clients' streams
kept apart. A real daemon, raw TCP clients, rclpy peers in their own processes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from hardening_tools import MarkerPeer, RawClient, ask, command_bytes
from protocol.messages import PolyData
from support import Processes, start_daemon, wait_until

CUBE = 1


def test_a_denied_frame_does_not_leak_through_a_marker_on_a_prefixed_daemon(
        processes: Processes, tmp_path: Path) -> None:
    """--frame-prefix PSM1/ --deny-frame PSM1/secret, a read-only client: a marker in frame
    'secret' was judged as 'secret' but placed by 'PSM1/secret' (its model landed at the
    denied frame's pose). A marker's frame id is ROS's: judged, placed and followed as
    written."""
    daemon = start_daemon(processes, "--read-only", "--frame-prefix", "PSM1/",
                          "--deny-frame", "PSM1/secret")
    peer = MarkerPeer(processes, tmp_path)
    client = RawClient(daemon.port)
    try:
        created = ask(client, "create_marker_subscriber", {
            "topic": "/test_markers", "type": "MarkerArray", "fixed_frame": "world"}, 1)
        assert created["ok"], created
        # The denied frame under the arm's own world, and a visible one in the same
        # message: once list_bridges shows the visible one, tf holds both.
        peer.send(statics=[["world", "PSM1/world", 0.0, 0.0, 0.0],
                           ["PSM1/world", "PSM1/secret", 1.0, 2.0, 3.0],
                           ["world", "PSM1/visible", 0.0, 0.0, 1.0]])

        def frames() -> list[str]:
            return list(ask(client, "list_bridges", {}, 2)["result"]["tf_buffer"]["frames"])
        wait_until(lambda: "PSM1/visible" in frames(), timeout=10, what="the static frames")
        assert "PSM1/secret" not in frames()
        cube = {"type": CUBE, "scale": [0.01, 0.01, 0.01], "ns": "leak"}
        peer.send(markers=[{**cube, "id": 1, "frame": "secret"},
                           {**cube, "id": 2, "frame": "PSM1/secret"}])
        listed: dict = {}

        def shown() -> bool:
            nonlocal listed
            listed = ask(client, "list_markers", {"topic": "/test_markers"}, 3)["result"]
            return len(listed["markers"]) == 1 and len(listed["withheld"]) == 1
        wait_until(shown, timeout=10, what="one marker shown, one withheld")
        (withheld,) = listed["withheld"]
        assert withheld["id"] == 2 and "PSM1/secret" in withheld["reason"]
        (row,) = listed["markers"]
        assert (row["id"], row["frame"], row["placed"]) == (1, "secret", False), row
        viewer = RawClient(daemon.port)  # subscribes: gets the live models at once
        viewer.send(command_bytes("create_marker_subscriber", json.dumps({
            "topic": "/test_markers", "type": "MarkerArray",
            "fixed_frame": "world"}).encode(), 1))
        model = viewer.read_until(lambda m: m.device_name == row["device"], timeout=10)
        viewer.close()
        assert isinstance(model.body, PolyData)
        # A 10 mm cube about the origin of its own frame, nowhere near (1, 2, 3) m.
        assert float(np.abs(np.asarray(model.body.points)).max()) <= 5.0 + 1e-3
    finally:
        client.close()


SPHERE_LIST = 7


def _sphere_list(marker_id: int, points: int) -> dict:
    grid = [[0.01 * (i % 50), 0.01 * (i // 50), 0.0] for i in range(points)]
    return {"ns": "bomb", "id": marker_id, "type": SPHERE_LIST, "frame": "world",
            "scale": [0.01, 0.01, 0.01], "points": grid}


def test_models_past_the_memory_budget_are_refused_before_they_are_made(
        processes: Processes, tmp_path: Path) -> None:
    """The issue's bomb, scaled down: each SPHERE_LIST is a model of 2,456 bytes a point
    (42 vertices, 80 triangles), and a topic may keep half of --max-marker-bytes. What
    fits is shown; the next is refused, named with the budget, and nothing of it kept."""
    daemon = start_daemon(processes, "--max-marker-bytes", "4000000")
    peer = MarkerPeer(processes, tmp_path)
    client = RawClient(daemon.port)
    try:
        assert ask(client, "create_marker_subscriber", {
            "topic": "/test_markers", "type": "MarkerArray", "fixed_frame": "world"}, 1)["ok"]
        # 600 points: 1.47 MB each. The first fits the topic's 2 MB, the second does not.
        peer.send(markers=[_sphere_list(1, 600), _sphere_list(2, 600)])
        listed: dict = {}

        def settled() -> bool:
            nonlocal listed
            listed = ask(client, "list_markers", {"topic": "/test_markers"}, 2)["result"]
            return len(listed["markers"]) + len(listed["errors"]) == 2
        wait_until(settled, timeout=20, what="both markers judged")
        assert [m["id"] for m in listed["markers"]] == [1]
        (error,) = listed["errors"]
        assert error["id"] == 2 and "memory budget" in error["error"]
        assert "2000000 bytes of models a topic" in error["error"]
        assert "a model of 1473664 bytes" in error["error"]
        bridges = ask(client, "list_bridges", {}, 3)["result"]["bridges"]
        (sub,) = [b for b in bridges if b["kind"] == "marker_subscriber"]
        assert 1_400_000 < sub["model_bytes"] <= 2_000_000
        # Deleting the first frees its share: the second fits when sent again.
        peer.send(markers=[{"ns": "bomb", "id": 1, "action": 2}, _sphere_list(2, 600)])
        wait_until(lambda: [m["id"] for m in ask(client, "list_markers", {
            "topic": "/test_markers"}, 4)["result"]["markers"]] == [2], timeout=20,
            what="the second marker shown")
    finally:
        client.close()


def _marker_messages(messages: list) -> list[str]:
    return [m.device_name for m in messages
            if m.device_name.startswith(("mk:", "mks:", "mkf:"))]


def test_markers_go_only_to_the_clients_that_asked_for_them(
        processes: Processes, tmp_path: Path) -> None:
    """Issue 22, item 3: every client was sent every marker model (a storm disconnected a
    client that had asked for nothing). A marker topic's models, index and frames go to
    the clients that created or subscribed to it; the operator's go to everyone."""
    config = tmp_path / "bridges.yaml"
    config.write_text("marker_subscribers:\n  - {topic: /test_marker, type: "
                      "visualization_msgs/msg/Marker, fixed_frame: world}\n")
    daemon = start_daemon(processes, "--config", str(config))
    peer = MarkerPeer(processes, tmp_path)
    asker, other = RawClient(daemon.port), RawClient(daemon.port)
    try:
        other.send(command_bytes("hello", b"{}", 1))  # header v2, attached
        other.read_until(lambda m: m.type_name == "RTS_COMMAND", timeout=10)
        assert ask(asker, "create_marker_subscriber", {
            "topic": "/test_markers", "type": "MarkerArray", "fixed_frame": "world"}, 1)["ok"]
        peer.send(markers=[{"ns": "a", "id": 1, "type": CUBE, "scale": [0.1] * 3,
                            "frame": "base", "locked": True}],
                  marker={"ns": "op", "id": 1, "type": CUBE, "scale": [0.1] * 3,
                          "frame": "world"})
        model = asker.read_until(lambda m: m.device_name.startswith("mk:test_markers"),
                                 timeout=20)
        assert isinstance(model.body, PolyData)
        # Whatever the hub sent ``other`` before its next reply, it sent in order: none
        # of the asker's topic, but the operator's topic's model.
        other.send(command_bytes("hello", b"{}", 2))
        seen: list = []
        other.read_until(lambda m: seen.append(m) or (  # type: ignore[func-returns-value]
            m.type_name == "RTS_COMMAND" and m.body.command_id == 2), timeout=10)
        got = _marker_messages(seen)
        assert not [d for d in got if "test_markers" in d or d.startswith("mkf:world>base")]
        if not any(d.startswith("mk:test_marker:") for d in got):
            other.read_until(lambda m: m.device_name.startswith("mk:test_marker:"),
                             timeout=20)
        # Subscribing (creating it again) gives the asker's topic to ``other`` too: its
        # live models at once (before the reply), and the later ones.
        other.send(command_bytes("create_marker_subscriber", json.dumps({
            "topic": "/test_markers", "type": "MarkerArray",
            "fixed_frame": "world"}).encode(), 3))
        other.read_until(lambda m: m.device_name == model.device_name, timeout=10)
        assert json.loads(other.read_until(lambda m: m.type_name == "RTS_COMMAND",
                                           timeout=10).body.text)["result"]["existed"]
    finally:
        asker.close()
        other.close()
