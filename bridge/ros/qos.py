"""The rclpy `QoSProfile` for a bridge's QoS.

The QoS a client asks for is validated by the command schema (`protocol.commands.QoS`:
depth, reliability reliable|best_effort, durability volatile|transient_local); this module
only maps it onto rclpy, keeping the last `depth` messages.
"""

from __future__ import annotations

from typing import Any

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from protocol.commands import QoS

__all__ = ["BULK_DEPTH", "DEFAULT_DEPTH", "LATCHED_QOS", "TF_QOS", "TF_STATIC_SUBSCRIBER_QOS",
           "default_depth", "qos_profile", "qos_to_dict"]

_RELIABILITY = {"reliable": ReliabilityPolicy.RELIABLE,
                "best_effort": ReliabilityPolicy.BEST_EFFORT}
_DURABILITY = {"volatile": DurabilityPolicy.VOLATILE,
               "transient_local": DurabilityPolicy.TRANSIENT_LOCAL}


# The history a bridge keeps when the client does not say (rclpy's own default).
DEFAULT_DEPTH = 10
# Bulk types (images, point clouds): the bridge sends only the newest of those waiting, so
# a deeper history would only keep stale copies alive (Fast DDS keeps a payload per slot:
# 10 x a 20 MB cloud is 200 MB).
BULK_DEPTH = 1


def default_depth(bulk: bool) -> int:
    return BULK_DEPTH if bulk else DEFAULT_DEPTH


def qos_profile(qos: QoS) -> QoSProfile:
    depth = DEFAULT_DEPTH if qos.depth is None else qos.depth
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=_RELIABILITY[qos.reliability],
        durability=_DURABILITY[qos.durability])


def qos_to_dict(profile: QoSProfile) -> dict[str, Any]:
    """The schema's form of a profile (for replies and logs)."""
    reliability = {v: k for k, v in _RELIABILITY.items()}.get(
        profile.reliability, str(profile.reliability.name).lower())
    durability = {v: k for k, v in _DURABILITY.items()}.get(
        profile.durability, str(profile.durability.name).lower())
    return {"depth": int(profile.depth), "reliability": reliability, "durability": durability}


# tf2_ros's own profiles: /tf is volatile with depth 100; /tf_static and other latched
# topics (robot_description) are transient local, so a late subscriber still gets them.
TF_QOS = qos_profile(QoS(depth=100))
TF_STATIC_SUBSCRIBER_QOS = qos_profile(QoS(depth=100, durability="transient_local"))
LATCHED_QOS = qos_profile(QoS(depth=1, durability="transient_local"))
