"""One route per message kind (bridge/topics/routes.py), decided in one place: what each
kind of topic takes, real codecs."""

from __future__ import annotations

import pytest

from bridge.codecs import codec_for
from bridge.topics.routes import Route, route_for


@pytest.mark.parametrize(("ros_type", "route"), [
    ("geometry_msgs/msg/Pose", Route.POSE),
    ("geometry_msgs/msg/PoseStamped", Route.POSE),
    ("geometry_msgs/msg/TransformStamped", Route.POSE),
    ("sensor_msgs/msg/Image", Route.IMAGE),
    ("sensor_msgs/msg/PointCloud2", Route.SERIALIZED),
    ("sensor_msgs/msg/JointState", Route.MESSAGE),
    ("std_msgs/msg/String", Route.MESSAGE),
    ("tf2_msgs/msg/TFMessage", Route.MESSAGE),
])
def test_each_kind_takes_its_route(ros_type: str, route: Route) -> None:
    assert route_for(codec_for(ros_type), filtered=False) is route


@pytest.mark.parametrize("ros_type", ["geometry_msgs/msg/PoseStamped", "sensor_msgs/msg/Image",
                                      "sensor_msgs/msg/PointCloud2"])
def test_a_filtered_topic_goes_as_messages_whatever_its_kind(ros_type: str) -> None:
    """The security policy's filter judges rclpy messages: no raw route passes it by."""
    assert route_for(codec_for(ros_type), filtered=True) is Route.MESSAGE
