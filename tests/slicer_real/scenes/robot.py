"""A robot loaded by the module in a real scene: its link transforms, models, parenting,
colours, subject-hierarchy folders; then its joint sliders move it, seen through an
observer on a link's transform node."""

from __future__ import annotations

import math
from typing import Any

from scene_tools import connect, folder_path, nodes, world_matrix


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    logic = connect(session, args["port"])
    name = args["robot"]
    logic.loadRobot(name, args["node"], "robot_description")

    def visuals() -> list[Any]:
        return nodes(session, "vtkMRMLModelNode", robot=name, role="robot_visual")
    session.pump(90, until=lambda: len(visuals()) == args["models"] and all(
        v.GetID() in logic._planned for v in visuals()), what="every visual placed")
    session.pump(90, until=lambda: any(line.endswith("meshes received")
                                       for line in logic.robotLines()),
                 what="the robot's load counted")
    links = nodes(session, "vtkMRMLLinearTransformNode", robot=name, role="robot_link")
    result: dict[str, Any] = {
        "links": sorted(n.GetName() for n in links),
        "link_parents": {n.GetName(): (n.GetParentTransformNode().GetName()
                                       if n.GetParentTransformNode() else None)
                         for n in links},
        "models": {},
        "robot_lines": logic.robotLines(),
    }
    for model in visuals():
        display = model.GetDisplayNode()
        poly = model.GetPolyData()
        result["models"][model.GetName()] = {
            "parent": model.GetParentTransformNode().GetName(),
            "link": model.GetAttribute("OpenIGTLink.ros2.link"),
            "colour": list(display.GetColor()), "opacity": display.GetOpacity(),
            "scalars": bool(display.GetScalarVisibility()),
            "active_scalar": display.GetActiveScalarName() or "",
            "points": poly.GetNumberOfPoints(), "folders": folder_path(model),
            "rgba_colours": _distinct_rgba(poly),
        }
    if not args.get("joint"):
        return result

    # Joint sliders: the user moves one, the robot's link follows in the scene.
    joint, child, degrees = args["joint"], args["child_link"], float(args["degrees"])
    sliders = logic.jointSliders(name)
    result["sliders"] = {s.name: [s.unit, s.minimum, s.maximum] for s in sliders}
    link = session.scene.GetFirstNode(f"{name}:{child}", "vtkMRMLLinearTransformNode")
    events: list[str] = []
    tag = link.AddObserver(session.scene.GetNodeByID(link.GetID()).TransformModifiedEvent,
                           lambda caller, event: events.append(event))

    def angle() -> float:
        m = world_matrix(link)
        return math.degrees(math.atan2(m[1][0], m[0][0]))
    moved = logic.setJoints(name, sliders, {joint: degrees})
    session.pump(20, until=lambda: abs(angle() - degrees) < 0.5, what=f"{child} at {degrees}")
    link.RemoveObserver(tag)
    result.update(moved=moved, angle=angle(), events=sorted(set(events)),
                  event_count=len(events))
    return result


def _distinct_rgba(poly: Any) -> int:
    array = poly.GetPointData().GetArray("RGBA")
    if array is None:
        return 0
    return len({tuple(array.GetTuple(i)) for i in range(array.GetNumberOfTuples())})
