"""One topic, one type: the check every capability makes before it creates a subscription
or a publisher on a topic a client named.

Within one process, rmw_fastrtps refuses a second DDS topic of the same name with another
type, and rclpy reports it as an untyped ``RCLError`` ("invalid allocator" for a
subscription). Across the graph a type clash makes two endpoints that never match. Either
way the client is told, before anything is created, which type the topic already has.
"""

from __future__ import annotations

from bridge.ros.ros_node import RosNode
from protocol.commands import CommandFailedError, ErrorCode

__all__ = ["refuse_other_type"]


def refuse_other_type(ros: RosNode, topic: str, ros_type: str, field: str) -> None:
    """ALREADY_EXISTS naming ``field`` if the ROS graph (this daemon's own endpoints
    included) has ``topic`` (fully qualified) with a type other than ``ros_type``."""
    known = ros.topic_types(topic)
    if known and ros_type not in known:
        raise CommandFailedError(field, f"the type {topic} already has in the ROS graph "
                                 f"({', '.join(known)})", ros_type,
                                 code=ErrorCode.ALREADY_EXISTS)
