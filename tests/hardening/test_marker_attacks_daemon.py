"""Markers as an attack surface (issue 22, items 2, 3 and 6): frames judged as they are
used, memory budgets refused before anything is allocated, and other clients' streams
kept apart. A real daemon, raw TCP clients, rclpy peers in their own processes."""

from __future__ import annotations

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
            bridges = ask(client, "list_bridges", {}, 2)["result"]["bridges"]
            return next(b["frames"] for b in bridges if b["kind"] == "tf_buffer")
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
        viewer = RawClient(daemon.port)  # gets the live models as it connects
        viewer.send(command_bytes("hello", b"{}", 1))  # header v2: models come with it
        model = viewer.read_until(lambda m: m.device_name == row["device"], timeout=10)
        viewer.close()
        assert isinstance(model.body, PolyData)
        # A 10 mm cube about the origin of its own frame, nowhere near (1, 2, 3) m.
        assert float(np.abs(np.asarray(model.body.points)).max()) <= 5.0 + 1e-3
    finally:
        client.close()
