"""slicer_client: talk to the slicer-ros2-bridge daemon from 3D Slicer or any Python 3.9+.

    import slicer_client
    ros = slicer_client.connect("127.0.0.1", 18944)          # Pythonic API (client.py)
    rosNode = ros.GetDefaultROS2Node()                         # reference CamelCase facade

Pure Python with numpy and `protocol` only (no rclpy). See slicer_client/README.md.
"""

from slicer_client.bridge_state import BridgeSpec, BridgeState, StateFormatError
from slicer_client.client import Client, connect
from slicer_client.errors import (BridgeClientError, CommandRefusedError, CommandTimeoutError,
                                  ConnectionClosedError, DaemonUnreachableError, DeadLinkError,
                                  IkFailedError, KeyFileError, NotTheDaemonError,
                                  ParameterRejectedError, RobotNotLoadedError)
from slicer_client.matrices import MatrixError, as_numpy, to_vtk
from slicer_client.recording import Recording

__all__ = ["BridgeClientError", "BridgeSpec", "BridgeState", "Client",
           "CommandRefusedError", "CommandTimeoutError", "ConnectionClosedError",
           "DaemonUnreachableError", "DeadLinkError", "IkFailedError", "KeyFileError",
           "MatrixError", "NotTheDaemonError", "ParameterRejectedError", "Recording",
           "RobotNotLoadedError",
           "StateFormatError", "as_numpy", "connect", "to_vtk"]
