"""Robots: URDF loading, meshes for Slicer (mm), forward kinematics, a state publisher.

What the daemon calls::

    model = load_robot(urdf_text, package_paths={"pkg": Path(...)})   # or load_robot_file
    for visual in model.visuals:            # one POLYDATA per link visual, once per client
        body = to_polydata(visual)          # points in mm in the link frame
    poses = model.link_poses({"joint": q})  # 4x4 metres in the root link frame (FK)
    model.warnings                          # missing or broken meshes, by file and link
"""

from __future__ import annotations

import importlib
from typing import Any

# Exports are imported on first use: trimesh and yourdfpy cost ~60 MB of memory, which a
# daemon that never loads a robot should not pay.
_EXPORTS = {
    "bridge.robots.description": ("JointLimits", "JointSpec", "LinkSpec", "Mimic",
                                  "RobotDescription", "VisualSpec", "parse_urdf"),
    "bridge.robots.errors": ("MeshError", "ResourceError", "RobotError", "UrdfError"),
    "bridge.robots.kinematics": ("Kinematics",),
    "bridge.robots.meshes": ("DEFAULT_MESH_CACHE", "MeshCache"),
    "bridge.robots.model": ("DEFAULT_RGBA", "LoadOptions", "MeshSource", "RobotModel",
                            "VisualMesh", "load_robot", "load_robot_file", "mesh_for",
                            "to_polydata"),
    "bridge.robots.resources": ("PackageResolver", "parse_package_path_option"),
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}


def __getattr__(name: str) -> Any:
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module 'bridge.robots' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


__all__ = [
    "DEFAULT_MESH_CACHE",
    "DEFAULT_RGBA",
    "JointLimits",
    "JointSpec",
    "Kinematics",
    "LinkSpec",
    "LoadOptions",
    "MeshCache",
    "MeshError",
    "MeshSource",
    "Mimic",
    "PackageResolver",
    "ResourceError",
    "RobotDescription",
    "RobotError",
    "RobotModel",
    "UrdfError",
    "VisualMesh",
    "VisualSpec",
    "load_robot",
    "load_robot_file",
    "mesh_for",
    "parse_package_path_option",
    "parse_urdf",
    "to_polydata",
]
