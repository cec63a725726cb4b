"""Slicer's main thread under a pose stream, in a real Slicer scene (run by
bench/bench_slicer_main_thread.py with the Slicer peer's Python).

mode "module": the ROS2Bridge module connected, the demo robot loaded and placed, and a
PoseStamped subscriber made as a Slicer user makes it (the reference's
CreateAndAddSubscriberNode) with an observer that reads each pose;
mode "connector": a plain OpenIGTLinkIF connector only (Slicer's own cost of the same
stream, the floor of any Slicer-side client).
Prints READY, waits for "MEASURE SECONDS" on stdin, runs Slicer's event loop (its 5 ms
timer) for that long, and returns the share of wall time the main thread spent in it.
"""

from __future__ import annotations

import sys
import time
from typing import Any


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    scene = session.scene
    seen = [0]
    if args["mode"] == "module":
        logic = session.logic
        logic.connect("127.0.0.1", int(args["port"]))
        session.pump(30, until=lambda: logic.client is not None, what="the module's client")
        logic.loadRobot("demo", "/robot_state_publisher", "robot_description")
        session.pump(60, what="the robot placed", until=lambda: len(logic._planned) >= 25)
        sub = logic.GetDefaultROS2Node().CreateAndAddSubscriberNode("PoseStamped",
                                                                    args["topic"])

        def on_message(caller: Any, event: Any) -> None:
            # Reads the pose as a user's observer does (a PoseStamped message object, from
            # the whole message the connector imported as a text node; its vtkMatrix4x4).
            caller.GetLastMessage().GetPose()
            seen[0] += 1
        sub.AddObserver("ModifiedEvent", on_message)
        count = sub.GetNumberOfMessages
    else:
        connector = scene.AddNewNodeByClass("vtkMRMLIGTLConnectorNode")
        connector.SetTypeClient("127.0.0.1", int(args["port"]))
        connector.Start()
        session.pump(30, until=lambda: connector.GetState() == connector.StateConnected,
                     what="connected")

        observed: list[Any] = []  # the stream's transform node, once it came

        def count() -> int:
            if not observed:
                node = scene.GetFirstNode(args["device"], "vtkMRMLLinearTransformNode")
                if node is not None:
                    observed.append(node)
                    node.AddObserver(node.TransformModifiedEvent,
                                     lambda caller, event: seen.__setitem__(0, seen[0] + 1))
            return seen[0]
    print("READY", flush=True)
    seconds = float(sys.stdin.readline().split()[1])
    busy = 0.0
    first = count()
    cpu0, start = time.thread_time(), time.monotonic()
    while time.monotonic() - start < seconds:
        t0 = time.monotonic()
        session.slicer_app.processEvents()
        if args["mode"] != "module":
            count()
        busy += time.monotonic() - t0
        time.sleep(0.005)  # Qt's idle until the next 5 ms timer tick
    wall = time.monotonic() - start
    return {"mode": args["mode"], "wall_s": wall, "busy_share": busy / wall,
            "cpu_share": (time.thread_time() - cpu0) / wall,
            "messages": count() - first, "observed": seen[0]}
