"""The reference SlicerROS2's module logic (``vtkSlicerROS2Logic``) over a `Client`:
``slicer.util.getModuleLogic('ROS2')`` gives this object in a script written for the
reference (entry_points.py; inside 3D Slicer, the ROS2Bridge module's logic hands it out).

``Spin()`` runs, on the calling thread, the callbacks of what arrived since the last spin
(observers of subscribers, parameters, lookups...) and refreshes the tf lookups, as the
reference's 20 ms timer spins its node: a script written for it that spins and then reads
finds the message that was published before, counted and seen by its observers.
"""

from __future__ import annotations

import threading
from typing import Any, Callable, Dict, List, Set, Tuple

from slicer_client.reference.messages import MessageTypes
from slicer_client.reference.nodes import (FacadeClient, NodeFactory, PlainNodes, ROS2Node,
                                           RobotNode)
from slicer_client.reference.vtk_values import SlicerValues

__all__ = ["ROS2Logic"]


class ROS2Logic:
    def __init__(self, client: Any, *, vtk: Any = None,
                 nodes: NodeFactory | None = None) -> None:
        """`vtk`: the vtk module, False for plain stand-ins, None to import it if there.
        `nodes`: what makes the facade's nodes (plain objects unless given; the ROS2Bridge
        module sets MRML nodes of its scene)."""
        self.client: FacadeClient = client
        self.nodes: NodeFactory = nodes if nodes is not None else PlainNodes()
        self.values = SlicerValues(vtk)
        self.types = MessageTypes(client.describe_type, self.values)
        self._default: ROS2Node | None = None
        self._nodes: List[ROS2Node] = []
        # Which facade nodes hold each bridge: a bridge goes when the last one lets go.
        self._holders: Dict[Tuple[str, ...], Set[int]] = {}
        self._lock = threading.Lock()

    # --- the reference's logic --------------------------------------------------------------
    def Spin(self) -> None:  # noqa: N802
        self.client.events.spin()

    def GetDefaultROS2Node(self) -> ROS2Node:  # noqa: N802
        """The node every script starts from (``ros2:node:slicer`` in the reference): here
        the daemon's own ROS node, named by `GetROS2NodeName`."""
        if self._default is None:
            self._default = self.nodes.make(ROS2Node, ("GetDefaultROS2Node",), None, self)
        return self._default

    def CreateROS2Node(self, name: str = "") -> ROS2Node:  # noqa: N802
        """Another node, for what the reference makes with
        ``slicer.mrmlScene.AddNewNodeByClass("vtkMRMLROS2NodeNode")`` then ``Create(name)``."""
        node: ROS2Node = self.nodes.make(ROS2Node, ("CreateROS2Node", name), None, self, name)
        self._nodes.append(node)
        return node

    def AddRobot(self, robotName: str, parameterNodeName: str,  # noqa: N802,N803
                 parameterName: str = "robot_description", fixedFrame: str = "",  # noqa: N803
                 tfPrefix: str = "") -> RobotNode:  # noqa: N803
        return self.GetDefaultROS2Node().CreateAndAddRobotNode(
            robotName, parameterNodeName, parameterName, fixedFrame, tfPrefix)

    def RemoveRobot(self, robotName: str) -> bool:  # noqa: N802,N803
        return self.GetDefaultROS2Node().RemoveAndDeleteRobotNode(robotName)

    # --- what nodes need ----------------------------------------------------------------------
    def add_tick(self, hook: Callable[[], None]) -> None:
        self.client.events.add_tick(hook)

    def remove_tick(self, hook: Callable[[], None]) -> None:
        self.client.events.remove_tick(hook)

    def spinning_here(self) -> bool:
        """Is this thread delivering a spin's callbacks right now?"""
        return bool(self.client.events.spinning_here())

    def hold(self, key: Tuple[str, ...], owner: Any) -> None:
        with self._lock:
            self._holders.setdefault(key, set()).add(id(owner))

    def release(self, key: Tuple[str, ...], owner: Any) -> bool:
        """`owner` lets go of a bridge; True if nobody else holds it (remove it then)."""
        with self._lock:
            holders = self._holders.get(key, set())
            holders.discard(id(owner))
            if holders:
                return False
            self._holders.pop(key, None)
            return True
