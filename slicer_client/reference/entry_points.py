"""The reference's two entry points, so that a script written for SlicerROS2 runs with no
line changed where SlicerROS2 itself is not installed:

* ``slicer.util.getModuleLogic('ROS2')`` gives this project's `ROS2Logic`;
* ``slicer.mrmlScene.AddNewNodeByClass("vtkMRMLROS2NodeNode")`` gives a new facade node
  (the scene alone would make a bare node of the C++ class, without the reference's
  methods, so the scene's method is answered for that one class name and passes every
  other call on unchanged); inside 3D Slicer the ROS2Bridge module's node factory makes it
  an MRML node of the scene, with the ID ``vtkMRMLROS2NodeNode<n>``
  (ROS2BridgeLib/scene_nodes.py).

`install` does both on 3D Slicer's own ``slicer`` module (the ROS2Bridge module calls it
once its logic is connected) or on any object with the same two attributes (a script's
stand-in). Where SlicerROS2 is installed (a module named ``ROS2``, or the node class
registered in the scene) it changes nothing: that module answers its own name.
"""

from __future__ import annotations

from typing import Any

__all__ = ["NODE_CLASS", "REFERENCE_MODULE", "install", "reference_installed"]

REFERENCE_MODULE = "ROS2"
NODE_CLASS = "vtkMRMLROS2NodeNode"
OWN_LIBRARY = "vtkSlicerROS2BridgeModuleMRML"  # slicer_client/slicer_module/ROS2BridgeMRML
_MARK = "_slicer_ros2_bridge_entry_point"


def reference_installed(slicer: Any) -> bool:
    """Is SlicerROS2's own module there (checked the way Slicer finds modules)?"""
    app = getattr(slicer, "app", None)
    manager = getattr(app, "moduleManager", None)
    if manager is not None and manager().module(REFERENCE_MODULE):
        return True
    scene = getattr(slicer, "mrmlScene", None)
    registered = getattr(scene, "IsNodeClassRegistered", None)
    if registered is None or not registered(NODE_CLASS):
        return False
    # The ROS2Bridge extension's own MRML library registers a class of that name too.
    return OWN_LIBRARY not in str(getattr(getattr(slicer, NODE_CLASS, None), "__module__", ""))


def install(slicer: Any, logic: Any) -> bool:
    """Answer the reference's entry points of `slicer` with `logic` (a `ROS2Logic`);
    False, and nothing changed, where SlicerROS2 is installed. Installing again replaces
    the logic (a reconnected module)."""
    if reference_installed(slicer):
        return False
    util = slicer.util
    get_logic = getattr(util.getModuleLogic, _MARK, util.getModuleLogic)

    def getModuleLogic(module: Any) -> Any:  # noqa: N802 - Slicer's name
        if module == REFERENCE_MODULE:
            return logic
        return get_logic(module)

    setattr(getModuleLogic, _MARK, get_logic)
    util.getModuleLogic = getModuleLogic

    scene = slicer.mrmlScene
    add_node = getattr(scene.AddNewNodeByClass, _MARK, scene.AddNewNodeByClass)

    def AddNewNodeByClass(class_name: str, *args: Any) -> Any:  # noqa: N802
        if class_name == NODE_CLASS:
            return logic.CreateROS2Node(str(args[0]) if args else "")
        return add_node(class_name, *args)

    setattr(AddNewNodeByClass, _MARK, add_node)
    scene.AddNewNodeByClass = AddNewNodeByClass
    return True
