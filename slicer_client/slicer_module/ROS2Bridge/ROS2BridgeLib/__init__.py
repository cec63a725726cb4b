"""The ROS2Bridge module's code beside its module file (Slicer's `<Module>Lib` convention):
`transport` (slicer_client's Transport over Slicer's OpenIGTLinkIF connector), `parameters`
(the module's parameter node), `logic` (what scripts use), `reference` (SlicerROS2's entry
points), `scene_nodes` (SlicerROS2's nodes as MRML nodes of the scene).

Every part imports the client packages `slicer_client` and `protocol`. The module no longer
finds them by itself: they come with the SlicerROS2Bridge extension, or from the client
wheel installed into Slicer's Python. Missing, they are named here, with the commands,
before any part fails on an import deep inside.
"""

import importlib.util

WHEEL_COMMANDS = (
    "build the client wheel in the repository (`python3 tools/build_client_wheel.py`, or "
    "`make client-wheel`), then install it in 3D Slicer's Python console with "
    "`slicer.util.pip_install('<clone>/dist/slicer_ros2_bridge_client-0.1.0-py3-none-any.whl')` "
    "and restart Slicer; or install the SlicerROS2Bridge extension, which ships them")


def missing_client_packages() -> list[str]:
    """The client packages this Python cannot import."""
    return [name for name in ("protocol", "slicer_client")
            if importlib.util.find_spec(name) is None]


_missing = missing_client_packages()
if _missing:
    raise ImportError(
        f"The ROS2Bridge module needs the Python package(s) {', '.join(_missing)}, which "
        f"3D Slicer's Python cannot import. To install them: {WHEEL_COMMANDS}.",
        name=_missing[0])
