"""How the facade makes its nodes (issue 42): through the logic's node factory, which the
ROS2Bridge module replaces with MRML nodes of its scene (tests/slicer_real checks those).
Each node carries its recipe, the call that made it, from which a saved scene's nodes are
made again; the factory hears of renames and removals. Plain objects outside Slicer."""

from __future__ import annotations

from typing import Any, Optional

import pytest

from slicer_client.reference.nodes import PlainNodes, ROS2Node, reference_class

pytestmark = pytest.mark.ros


@pytest.mark.parametrize("recipe, expected", [
    (("GetDefaultROS2Node",), "vtkMRMLROS2NodeNode"),
    (("CreateROS2Node", "testNode"), "vtkMRMLROS2NodeNode"),
    (("CreateAndAddSubscriberNode", "String", "/t"), "vtkMRMLROS2SubscriberStringNode"),
    (("CreateAndAddSubscriberNode", "std_msgs/msg/String", "/t"),
     "vtkMRMLROS2SubscriberStringNode"),
    (("CreateAndAddPublisherNode", "vtkMRMLROS2PublisherPoseStampedNode", "/t", "", ""),
     "vtkMRMLROS2PublisherPoseStampedNode"),
    (("CreateAndAddServiceClientNode", "vtkMRMLROS2ServiceClientSpawnNode", "/spawn"),
     "vtkMRMLROS2ServiceClientSpawnNode"),
    (("CreateAndAddTf2LookupNode", "a", "b"), "vtkMRMLROS2Tf2LookupNode"),
    (("CreateAndAddRobotNode", "arm", "/rsp", "robot_description", "", ""),
     "vtkMRMLROS2RobotNode"),
])
def test_each_recipe_names_the_reference_s_class(recipe: tuple, expected: str) -> None:
    assert reference_class(recipe) == expected


def test_an_unknown_recipe_is_refused_naming_the_known_ones() -> None:
    with pytest.raises(ValueError, match="expected a recipe starting with one of "
                                         "GetDefaultROS2Node.*got \\('Nope',\\)"):
        reference_class(("Nope",))
    with pytest.raises(ValueError, match="expected CreateAndAddSubscriberNode's class name "
                                         "after it, got \\('CreateAndAddSubscriberNode',\\)"):
        reference_class(("CreateAndAddSubscriberNode",))


class Recording(PlainNodes):
    def __init__(self) -> None:
        self.events: list[tuple[str, str, tuple]] = []

    def make(self, cls: type, recipe: tuple, owner: Optional[ROS2Node], *args: Any) -> Any:
        node = super().make(cls, recipe, owner, *args)
        self.events.append(("make", cls.__name__, tuple(recipe)))
        return node

    def changed(self, node: Any) -> None:
        self.events.append(("changed", type(node).__name__, tuple(node.recipe)))

    def discard(self, node: Any) -> None:
        self.events.append(("discard", type(node).__name__, tuple(node.recipe)))


def test_nodes_are_made_renamed_and_let_go_through_the_factory(rosLogic: Any) -> None:  # noqa: N803
    nodes = rosLogic.nodes = Recording()
    ros2Node = rosLogic.CreateROS2Node()  # noqa: N806 - what AddNewNodeByClass gives
    ros2Node.Create("testNode")
    sub = ros2Node.CreateAndAddSubscriberNode("String", "/factory_string")
    lookup = ros2Node.CreateAndAddTf2LookupNode("a", "b")
    assert lookup.SetChildID("c")
    spawn = ros2Node.CreateAndAddServiceClientNode("SetBool", "/factory_service")
    assert sub.recipe == ("CreateAndAddSubscriberNode", "String", "/factory_string")
    assert spawn.recipe == ("CreateAndAddServiceClientNode", "SetBool", "/factory_service")
    assert ros2Node.RemoveAndDeleteSubscriberNode("/factory_string")
    ros2Node.Destroy()
    assert nodes.events == [
        ("make", "ROS2Node", ("CreateROS2Node", "")),
        ("changed", "ROS2Node", ("CreateROS2Node", "testNode")),
        ("make", "SubscriberNode", ("CreateAndAddSubscriberNode", "String", "/factory_string")),
        ("make", "Tf2LookupNode", ("CreateAndAddTf2LookupNode", "a", "b")),
        ("changed", "Tf2LookupNode", ("CreateAndAddTf2LookupNode", "a", "c")),
        ("make", "ServiceClientNode", ("CreateAndAddServiceClientNode", "SetBool",
                                       "/factory_service")),
        ("discard", "SubscriberNode", ("CreateAndAddSubscriberNode", "String",
                                       "/factory_string")),
        ("discard", "Tf2LookupNode", ("CreateAndAddTf2LookupNode", "a", "c")),
        ("discard", "ServiceClientNode", ("CreateAndAddServiceClientNode", "SetBool",
                                          "/factory_service")),
    ]
