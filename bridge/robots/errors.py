"""Typed errors of robot loading (URDF parsing, resource resolution, mesh reading).

They extend the project's `ProtocolError` so every one names the offending ``field``
(``"joint 'elbow' <origin> xyz"``, ``"package://pkg/meshes/a.stl"``), what was
``expected`` and what it ``got``; the daemon turns them into error replies unchanged::

    RobotError                 base of this package's errors
    +-- UrdfError              the URDF text cannot give a robot: loading stops
    +-- ResourceError          a mesh URI cannot be resolved to a readable file
    +-- MeshError              a file was found but holds no usable triangle mesh

Only `UrdfError` escapes `load_robot`: a `ResourceError` or `MeshError` for one visual
becomes a warning on the model and the rest of the robot still loads.
"""

from __future__ import annotations

from protocol.errors import ProtocolError

__all__ = ["RobotError", "UrdfError", "ResourceError", "MeshError"]


class RobotError(ProtocolError):
    """Base of the errors raised while turning a robot description into meshes and poses."""


class UrdfError(RobotError):
    """The URDF is malformed: not XML, a missing or bad attribute, a broken tree."""


class ResourceError(RobotError):
    """A resource URI (``package://``, ``file://``, a path) cannot be resolved to a file."""


class MeshError(RobotError):
    """A resolved file cannot be read as a triangle mesh (unknown format, corrupt, empty)."""
