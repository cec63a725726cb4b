"""Robots: URDF loading, meshes for Slicer (mm), forward kinematics, a state publisher.

What the daemon calls::

    model = load_robot(urdf_text, package_paths={"pkg": Path(...)})   # or load_robot_file
    for visual in model.visuals:            # one POLYDATA per link visual, once per client
        body = to_polydata(visual)          # points in mm in the link frame
    poses = model.link_poses({"joint": q})  # 4x4 metres in the root link frame (FK)
    model.warnings                          # missing or broken meshes, by file and link
"""

from bridge.robots.description import (JointLimits, JointSpec, LinkSpec, Mimic,
                                       RobotDescription, VisualSpec, parse_urdf)
from bridge.robots.errors import MeshError, ResourceError, RobotError, UrdfError
from bridge.robots.kinematics import Kinematics
from bridge.robots.meshes import DEFAULT_MESH_CACHE, MeshCache
from bridge.robots.model import (DEFAULT_RGBA, RGBA_ATTRIBUTE, LoadOptions, RobotModel,
                                 VisualMesh, load_robot, load_robot_file, to_polydata)
from bridge.robots.resources import PackageResolver, parse_package_path_option

__all__ = [
    "DEFAULT_MESH_CACHE",
    "DEFAULT_RGBA",
    "RGBA_ATTRIBUTE",
    "JointLimits",
    "JointSpec",
    "Kinematics",
    "LinkSpec",
    "LoadOptions",
    "MeshCache",
    "MeshError",
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
    "parse_package_path_option",
    "parse_urdf",
    "to_polydata",
]
