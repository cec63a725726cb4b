"""The reference SlicerROS2's nodes as MRML nodes of 3D Slicer's scene (issue 42).

The extension's MRML library (slicer_client/slicer_module/ROS2BridgeMRML) gives the scene the
reference's node classes in C++ (``vtkMRMLROS2NodeNode``, ``vtkMRMLROS2SubscriberStringNode``,
a kind's base such as ``vtkMRMLROS2SubscriberNode`` for a type outside the reference's list),
holding no ROS. Each facade class (slicer_client/reference/nodes.py) is made a Python subclass
of its C++ class, which the scene hands back as that Python object (VTK keeps it). Each node is

* in the scene under the reference's ID (``vtkMRMLROS2NodeNode1``,
  ``vtkMRMLROS2SubscriberStringNode1``...) and name (``ros2:sub:/chatter``), found by the
  scene's own ``GetNodesByClass``, with the attribute ``ROS2.Class`` = the reference's class
  name (`nodes_of_class` matches it, also for a type the library has no class of);
* observed with VTK's own ``AddObserver`` (events as VTK hands them to Python);
* saved with the scene under its class's tag: ``ROS2.Recipe`` is the call that made it,
  ``ROS2.Owner`` its ROS node's ID. A reopened scene holds them as nodes of the C++ classes;
  `SceneNodes.adopt` makes each again with the same ID through its recipe once the module is
  connected (the daemon's bridges come back with the module's saved bridge state).

Without the library (the module folder added by hand, no extension build), the nodes are
``vtkMRMLScriptedModuleNode``s (``vtkMRMLLinearTransformNode``s for tf2 lookups) and only
`nodes_of_class` finds them by class.
"""

import importlib
import json
import logging
from typing import Any, Optional

import slicer
import vtk

from slicer_client.matrices import fill_vtk
from slicer_client.reference.nodes import (EVENT_IDS, ROS2Node, Recipe, Tf2LookupNode,
                                           reference_base_class, reference_class)

__all__ = ["CLASS_ATTRIBUTE", "OWNER_ATTRIBUTE", "RECIPE_ATTRIBUTE", "SceneNodes",
           "library_classes", "nodes_of_class", "register_node_classes", "saved_recipe"]

CLASS_ATTRIBUTE = "ROS2.Class"
RECIPE_ATTRIBUTE = "ROS2.Recipe"
OWNER_ATTRIBUTE = "ROS2.Owner"
log = logging.getLogger("ROS2Bridge")


LIBRARY_MODULE = "vtkSlicerROS2BridgeModuleMRMLPython"  # the extension build's wrapped library


def library_classes() -> dict[str, type]:
    """The MRML library's classes by name, put in the `slicer` namespace as Slicer does for
    a module library; empty when the library is not installed."""
    if not hasattr(slicer, "vtkMRMLROS2NodeNode"):
        try:
            library = importlib.import_module(LIBRARY_MODULE)
        except ImportError:
            return {}
        for name in dir(library):
            if name.startswith("vtkMRMLROS2"):
                setattr(slicer, name, getattr(library, name))
    return {name: getattr(slicer, name) for name in dir(slicer)
            if name.startswith("vtkMRMLROS2") and name.endswith("Node")}


def register_node_classes(scene: Any) -> None:
    """Let `scene` make the library's nodes from their tags (a scene opened from a file)."""
    for cls in library_classes().values():
        node = cls()
        if scene.GetClassNameByTag(node.GetNodeTagName()) != node.GetClassName():
            scene.RegisterNodeClass(node)


def _reference_nodes(scene: Any) -> list[Any]:
    return [n for n in slicer.util.getNodesByClass("vtkMRMLNode", scene)
            if n.GetAttribute(CLASS_ATTRIBUTE)]


def nodes_of_class(scene: Any, className: str) -> list[Any]:  # noqa: N803
    """The scene's reference nodes of `className` (``vtkMRMLROS2NodeNode``...), in the
    scene's order: what ``GetNodesByClass`` gives for a registered class."""
    return [n for n in _reference_nodes(scene) if n.GetAttribute(CLASS_ATTRIBUTE) == className]


def _invoke(base: type) -> Any:
    def InvokeEvent(self: Any, event: Any, *data: Any) -> Any:  # noqa: N802
        """The facade's event names as VTK's numbers (VTK knows only its own names)."""
        return base.InvokeEvent(self, EVENT_IDS.get(event, event), *data)  # type: ignore[attr-defined]
    return InvokeEvent


def _modify_transform(self: Any) -> None:
    """A tf2 lookup node's matrix is the lookup's: one TransformModifiedEvent and one
    ModifiedEvent per lookup, as the reference's transform node gives."""
    matrix = self.resource.matrix
    if matrix is None:
        return
    was_modifying = self.StartModify()
    self.SetMatrixTransformToParent(fill_vtk(matrix, vtk.vtkMatrix4x4()))
    self.EndModify(was_modifying)


def saved_recipe(node: Any) -> Recipe:
    """A saved node's recipe, checked: only the calls that make reference nodes, with text
    arguments, of the class the node says it is (a scene file is input like any other)."""
    text = node.GetAttribute(RECIPE_ATTRIBUTE) or ""
    try:
        recipe = json.loads(text)
    except ValueError:
        recipe = None
    if not (isinstance(recipe, list) and recipe and all(isinstance(a, str) for a in recipe)):
        raise ValueError(f"{RECIPE_ATTRIBUTE}: expected a JSON list of strings, got {text!r}")
    made = reference_class(tuple(recipe))  # raises for a call that makes no reference node
    said = node.GetAttribute(CLASS_ATTRIBUTE)
    if made != said:
        raise ValueError(f"{RECIPE_ATTRIBUTE}: expected a call that makes a {said}, got "
                         f"{recipe[0]}, which makes a {made}")
    return tuple(recipe)


class SceneNodes:
    """The facade's node factory (slicer_client.reference.nodes.NodeFactory) in a scene."""

    def __init__(self, scene: Any) -> None:
        self.scene = scene
        self._classes: dict[tuple[type, Any], type] = {}
        register_node_classes(scene)
        self._reuse_id: Optional[str] = None  # the saved node `adopt` makes again

    def _base(self, recipe: Recipe) -> Any:
        """The C++ class of the node `recipe` makes: the reference's own, else its kind's
        base; without the library, a scripted module node (a linear transform for a lookup)."""
        classes = library_classes()
        mrml = classes.get(reference_class(recipe)) or classes.get(reference_base_class(recipe))
        if mrml is not None:
            return mrml
        if reference_base_class(recipe) == "vtkMRMLROS2Tf2LookupNode":
            return slicer.vtkMRMLLinearTransformNode
        return slicer.vtkMRMLScriptedModuleNode

    def _mrml_class(self, cls: type, base: Any) -> type:
        """The MRML class of a facade class: the facade's methods first, VTK's own for
        observers, events and the node's name."""
        mrml = self._classes.get((cls, base))
        if mrml is None:
            lookup = issubclass(cls, Tf2LookupNode)

            def __init__(self: Any, *args: Any) -> None:
                base.__init__(self)
                cls.__init__(self, *args)  # type: ignore[misc]
            namespace: dict[str, Any] = {
                "__init__": __init__,
                "facadeName": cls.GetName,  # type: ignore[attr-defined]
                "InvokeEvent": _invoke(base),
                **{name: getattr(base, name) for name in (
                    "GetName", "AddObserver", "RemoveObserver", "RemoveAllObservers",
                    "HasObserver")}}
            if lookup:
                namespace["_modify"] = _modify_transform
            mrml = type(f"{cls.__name__}MRML", (cls, base), namespace)
            self._classes[(cls, base)] = mrml
        return mrml

    def _free_id(self, className: str) -> str:  # noqa: N803
        number = 1
        while self.scene.GetNodeByID(f"{className}{number}") is not None:
            number += 1
        return f"{className}{number}"

    def make(self, cls: type, recipe: Recipe, owner: Optional[ROS2Node], *args: Any) -> Any:
        node = self._mrml_class(cls, self._base(recipe))(*args)
        node.recipe = tuple(recipe)
        className = reference_class(recipe)  # noqa: N806
        node_id, self._reuse_id = self._reuse_id or self._free_id(className), None
        # The scene gives a node the ID it asks for only through its own factory: a
        # placeholder takes it, the Python node copies it (CopyWithScene) and replaces it.
        placeholder = self.scene.GetNodeByID(node_id)
        if placeholder is None:
            placeholder = self.scene.AddNewNodeByClassWithID(
                node.GetClassName(), "", node_id)
        node.CopyWithScene(placeholder)
        self.scene.RemoveNode(placeholder)
        node.SetAttribute(CLASS_ATTRIBUTE, className)
        if owner is not None:
            node.SetAttribute(OWNER_ATTRIBUTE, owner.GetID())  # type: ignore[attr-defined]
        self._describe(node)
        self.scene.AddNode(node)
        return node

    def _describe(self, node: Any) -> None:
        node.SetAttribute(RECIPE_ATTRIBUTE, json.dumps(list(node.recipe)))
        node.SetName(node.facadeName())

    def changed(self, node: Any) -> None:
        self._describe(node)

    def discard(self, node: Any) -> None:
        if node.GetScene() is not None:
            node.GetScene().RemoveNode(node)

    def adopt(self, logic: Any) -> list[str]:
        """Make the saved reference nodes of the scene again (plain MRML nodes after a
        scene is opened) with `logic` (a `ROS2Logic` connected to the daemon): each keeps
        its ID and name. Returns the problems met (a node that could not be made is left
        as it was, named in the log)."""
        saved = [n for n in _reference_nodes(self.scene) if not hasattr(n, "facadeName")]
        # ROS nodes first: the others are made by theirs.
        saved.sort(key=lambda n: n.GetAttribute(CLASS_ATTRIBUTE) != "vtkMRMLROS2NodeNode")
        problems = []
        made_for: dict[str, Any] = {}  # saved ID -> the node made for it
        for node in saved:
            node_id = node.GetID()
            try:
                recipe = saved_recipe(node)
                if recipe[0] in ("GetDefaultROS2Node", "CreateROS2Node"):
                    maker: Any = logic
                else:
                    owner_id = node.GetAttribute(OWNER_ATTRIBUTE) or ""
                    maker = made_for.get(owner_id) or self.scene.GetNodeByID(owner_id)
                    if not hasattr(maker, "facadeName"):
                        raise LookupError(f"its ROS node {owner_id!r} is not in the scene")
                self._reuse_id = node_id
                made = getattr(maker, recipe[0])(*recipe[1:])
                made_for[node_id] = made
                if made.GetID() != node_id:  # one made before the scene was opened
                    self.scene.RemoveNode(node)
            except Exception as error:  # noqa: BLE001 - the other nodes still come back
                log.exception("the saved node %s was not made again", node_id)
                problems.append(f"The saved node {node_id} was not made again: {error}")
            finally:
                self._reuse_id = None
        return problems
