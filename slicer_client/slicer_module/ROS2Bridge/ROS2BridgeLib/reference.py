"""The reference SlicerROS2's entry points, answered by the ROS2Bridge module where
SlicerROS2 itself is not installed (slicer_client/reference/entry_points.py):
`slicer.util.getModuleLogic('ROS2')` and `AddNewNodeByClass("vtkMRMLROS2NodeNode")`."""

import logging
from typing import Any

import slicer

from slicer_client.reference.entry_points import install as install_entry_points

__all__ = ["installReferenceEntryPoints"]

log = logging.getLogger("ROS2Bridge")


class _ReferenceLogic:
    """`getModuleLogic('ROS2')` before this module's GUI exists: the module logic is made
    (and connected) only when a reference method is first called."""

    def __getattr__(self, name: str) -> Any:
        return getattr(slicer.util.getModuleLogic("ROS2Bridge"), name)


def installReferenceEntryPoints() -> None:
    """Once every module is loaded (Slicer's startupCompleted): is SlicerROS2 there to
    answer its own name? If not, this module answers it."""
    if install_entry_points(slicer, _ReferenceLogic()):
        log.info("answering SlicerROS2's getModuleLogic('ROS2') (SlicerROS2 is not installed)")
