"""The ROS2Bridge module's parameter node: what its GUI shows, and the bridges saved with
the scene. Slicer's parameterNodeWrapper reads the annotations below at run time, so this
file keeps them evaluable on Slicer's Python 3.9 (no postponed annotations)."""

from typing import TYPE_CHECKING, Annotated, Any

from slicer.parameterNodeWrapper import WithinRange, parameterNodeWrapper

__all__ = ["DEFAULT_FRAME", "ROS2BridgeParameterNode"]

# The fixed frame markers are placed in and models are sent in, by default: the demo robot's
# root (REP 105's robot base frame), which a graph without a "world" frame still has.
DEFAULT_FRAME = "base_link"


@parameterNodeWrapper
class ROS2BridgeParameterNode:
    """GUI state and the saved bridges (bridgeState: slicer_client BridgeState JSON)."""

    host: str = "127.0.0.1"
    port: Annotated[int, WithinRange(1, 65535)] = 18944  # the QSpinBox connector sets the range
    # The defaults fit `slicer-ros2-bridge demo` (its robot, its root frame base_link).
    robotName: str = "demo"
    robotNode: str = "/robot_state_publisher"
    robotParameter: str = "robot_description"
    # The writers' key (`slicer-ros2-bridge keygen`): presented on each connection, so this
    # module may change ROS on a daemon that asks for it (docs/deployment.md).
    keyFile: str = ""
    # Where the Record button has the daemon write its bag (a path on the daemon's machine).
    recordPath: str = "/tmp/slicer-ros2-session.mcap"
    bridgeState: str = ""

    if TYPE_CHECKING:
        # Added by the wrapper at run time (which refuses a class that defines them):
        # declared for the type checker only.
        def __init__(self, parameterNode: Any) -> None: ...

        def connectGui(self, gui: Any) -> int: ...  # noqa: N802

        def disconnectGui(self, tag: int) -> None: ...  # noqa: N802
