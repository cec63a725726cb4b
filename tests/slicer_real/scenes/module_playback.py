"""The module in a real scene against a player (`slicer-ros2-bridge play`, a process without
ROS), as against the daemon (issue 45): its logic reads the bag's clock, seeks, sets the
rate, resumes and pauses; the robot's link transform nodes, made by Slicer's connector,
follow: after a seek, the pose at the seek time."""

from __future__ import annotations

from typing import Any

from scene_tools import connect, matrix


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    logic = connect(session, args["port"])
    status = logic.playbackStatus()
    out: dict[str, Any] = {"start": {"paused": status.paused, "offset": status.offset,
                                     "duration": status.duration}}
    logic.loadRobot("demo", "/robot_state_publisher", "robot_description")
    scene = session.scene

    def flange() -> list[list[float]]:
        node = scene.GetFirstNode("demo:tool_flange", "vtkMRMLLinearTransformNode")
        return matrix(node) if node is not None else []

    def near(want: list[list[float]]) -> bool:
        got = flange()
        return bool(got) and all(abs(got[i][3] - want[i][3]) <= 0.01 for i in range(3))

    out["seeks"] = {}
    for offset in (1.0, 0.4, 1.7):
        if offset != 1.0:
            out["seeks"][str(offset)] = logic.seekPlayback(offset).offset
        want = args["expected"][str(offset)]
        session.pump(60, until=lambda want=want: near(want), what=f"the pose at {offset} s")
        out.setdefault("poses", {})[str(offset)] = flange()
    out["rate"] = logic.setPlaybackRate(3.0).rate
    out["resumed_paused"] = logic.resumePlayback().paused
    session.pump(60, until=lambda: logic.playbackStatus().ended, what="the end of the bag")
    session.pump(60, until=lambda: near(args["expected"]["2.0"]), what="the last pose")
    out["paused_at_end"] = logic.pausePlayback().paused
    return out
