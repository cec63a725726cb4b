"""The reference SlicerROS2's API over this project's client: its module logic (logic.py),
its MRML node classes (nodes.py), message objects for any ROS type (messages.py), the
Slicer value of each of its type names (slicer_types.py), VTK values or plain stand-ins
(vtk_values.py), and its entry points in a script (entry_points.py).

    import slicer_client
    rosLogic = slicer_client.connect().logic     # or slicer.util.getModuleLogic('ROS2')
    rosNode = rosLogic.GetDefaultROS2Node()
    pub = rosNode.CreateAndAddPublisherNode('String', '/my_string')
    pub.Publish('hello')
"""

from __future__ import annotations

from slicer_client.reference.logic import ROS2Logic
from slicer_client.reference.messages import (MessageObject, MessageTypes, MessageValueError,
                                              accessor_name, vtk_class_name)
from slicer_client.reference.nodes import (ActionClientNode, MarkerSubscriberNode,
                                           ParameterNode, PublisherNode, ROS2Node, RobotNode,
                                           ServiceClientNode, SubscriberNode,
                                           Tf2BroadcasterNode, Tf2LookupNode)

__all__ = ["ActionClientNode", "MarkerSubscriberNode", "MessageObject", "MessageTypes",
           "MessageValueError", "ParameterNode", "PublisherNode", "ROS2Logic", "ROS2Node",
           "RobotNode", "ServiceClientNode", "SubscriberNode", "Tf2BroadcasterNode",
           "Tf2LookupNode", "accessor_name", "vtk_class_name"]
