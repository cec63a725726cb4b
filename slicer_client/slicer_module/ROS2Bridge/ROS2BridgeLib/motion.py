"""The module's Motion section in the scene (issue 46): a target (a transform node, or a
markups point with its orientation) for a robot's tip, solved by the daemon's inverse
kinematics, and shown as a preview robot: its own transforms and semi-transparent models
that share the robot's meshes, green when solved, red when not. The robot itself does not
move: solving is a read."""

from __future__ import annotations

import re
from typing import Any, Mapping, Optional

import numpy as np
import numpy.typing as npt
import slicer
import vtk

from slicer_client.matrices import fill_vtk

from .sequences import time_sequence

__all__ = ["FAILED_COLOUR", "MotionPreview", "OBSTACLE_TOPICS", "OBSTACLE_TYPE", "PREVIEW_OPACITY",
           "SOLVED_COLOUR", "ik_status", "obstacle_name", "segmentation_surface",
           "target_matrix", "world_matrix"]

ROBOT_ATTRIBUTE = "OpenIGTLink.ros2.robot"
LINK_ATTRIBUTE = "OpenIGTLink.ros2.link"
PREVIEW_ATTRIBUTE = "ROS2Bridge.preview"  # the robot a preview node shows
PREVIEW_OPACITY = 0.4
OBSTACLE_TOPICS = "/slicer/obstacles"  # a model made an obstacle goes to <this>/<name>
OBSTACLE_TYPE = "visualization_msgs/msg/Marker"
SOLVED_COLOUR = (0.25, 0.8, 0.35)
FAILED_COLOUR = (0.9, 0.1, 0.1)

F64 = npt.NDArray[np.float64]


def _rows(matrix: Any) -> F64:
    return np.array([[matrix.GetElement(i, j) for j in range(4)] for i in range(4)])


def world_matrix(node: Any) -> F64:
    """A transform node's transform to the scene's world (RAS, mm)."""
    matrix = vtk.vtkMatrix4x4()
    node.GetMatrixTransformToWorld(matrix)
    return _rows(matrix)


def target_matrix(node: Any) -> F64:
    """Where `node` asks the tip to go, in the scene's world (mm): a transform node's
    transform to the world, or a markups node's first point with its orientation."""
    if node is None:
        raise ValueError("choose a target: a transform node or a markups point")
    if node.IsA("vtkMRMLTransformNode"):
        return world_matrix(node)
    if node.IsA("vtkMRMLMarkupsNode"):
        if node.GetNumberOfControlPoints() < 1:
            raise ValueError(f"the target {node.GetName()!r} has no point: place one")
        orientation = vtk.vtkMatrix3x3()
        node.GetNthControlPointOrientationMatrix(0, orientation)
        position = [0.0, 0.0, 0.0]
        node.GetNthControlPointPosition(0, position)
        local = np.eye(4)
        local[:3, :3] = [[orientation.GetElement(i, j) for j in range(3)] for i in range(3)]
        local[:3, 3] = position
        parent = node.GetParentTransformNode()
        return local if parent is None else world_matrix(parent) @ local
    raise ValueError(f"expected a transform node or a markups point as the target, got "
                     f"{node.GetClassName()} {node.GetName()!r}")


class MotionPreview:
    """The preview robot of one robot: a transform per link (``<robot>:preview:<link>``)
    and a model per model of the robot's (sharing its mesh), made on first `show`."""

    def __init__(self, scene: Any, robot: str) -> None:
        self.scene = scene
        self.robot = robot
        self.transforms: dict[str, Any] = {}
        self.models: list[Any] = []
        self.root: Optional[str] = None  # the robot's root link, once an answer showed it
        self.browser: Optional[Any] = None  # the planned path's sequence browser
        self.sequences: list[Any] = []

    def robot_links(self) -> dict[str, tuple[Any, list[Any]]]:
        """The robot's link transforms in the scene, each with the models under it."""
        links: dict[str, tuple[Any, list[Any]]] = {}
        for node in slicer.util.getNodesByClass("vtkMRMLLinearTransformNode", self.scene):
            if (node.GetAttribute(ROBOT_ATTRIBUTE) == self.robot
                    and node.GetAttribute(LINK_ATTRIBUTE)
                    and node.GetAttribute(PREVIEW_ATTRIBUTE) is None):
                links[node.GetAttribute(LINK_ATTRIBUTE)] = (node, [])
        by_id = {node.GetID(): link for link, (node, _) in links.items()}
        for model in slicer.util.getNodesByClass("vtkMRMLModelNode", self.scene):
            link = by_id.get(model.GetTransformNodeID() or "")
            if link is not None and model.GetAttribute(PREVIEW_ATTRIBUTE) is None:
                links[link][1].append(model)
        return links

    def find_root(self, links: Mapping[str, Any]) -> None:
        """Learn the robot's root link from an answer's `links` (poses in the root's frame):
        a link at the identity (the root itself, or one fixed to it at its origin)."""
        scene_links = self.robot_links()
        for link, pose in links.items():
            if link in scene_links and np.allclose(np.asarray(pose, dtype=float), np.eye(4)):
                self.root = link
                return
        raise RuntimeError(f"the robot {self.robot!r} is not in the scene: load it first")

    def root_world(self) -> F64:
        """The root link's transform to the scene's world, as the scene has it now."""
        entry = self.robot_links().get(self.root or "")
        if entry is None:
            raise RuntimeError(f"the robot {self.robot!r} is not in the scene: load it first")
        return world_matrix(entry[0])

    def show(self, links: Mapping[str, Any], root_world: F64, solved: bool) -> None:
        """Place the preview at `links` (each link's pose in the root's frame, mm), coloured
        as `solved` says."""
        if not self.transforms:
            self._make()
        for link, node in self.transforms.items():
            pose = links.get(link)
            if pose is not None:
                node.SetMatrixTransformToParent(
                    fill_vtk(root_world @ np.asarray(pose, dtype=float), vtk.vtkMatrix4x4()))
        colour = SOLVED_COLOUR if solved else FAILED_COLOUR
        for model in self.models:
            display = model.GetDisplayNode()
            if display is not None:
                display.SetColor(*colour)

    def _make(self) -> None:
        for link, (_link_node, models) in self.robot_links().items():
            preview = self.scene.AddNewNodeByClass("vtkMRMLLinearTransformNode",
                                                   f"{self.robot}:preview:{link}")
            preview.SetAttribute(PREVIEW_ATTRIBUTE, self.robot)
            self.transforms[link] = preview
            for model in models:
                copy = self.scene.AddNewNodeByClass(
                    "vtkMRMLModelNode", f"{self.robot}:preview:{model.GetName()}")
                copy.SetAttribute(PREVIEW_ATTRIBUTE, self.robot)
                copy.SetAndObserveMesh(model.GetMesh())  # the same mesh: no copy
                copy.CreateDefaultDisplayNodes()
                display = copy.GetDisplayNode()
                display.SetOpacity(PREVIEW_OPACITY)
                display.SetScalarVisibility(False)
                copy.SetAndObserveTransformNodeID(preview.GetID())
                self.models.append(copy)

    def show_path(self, preview: Any, root_world: F64) -> Any:
        """The preview robot along a planned path: one sequence per link transform of the
        preview (index: time in s), synchronized by a sequence browser whose proxies are
        the preview's transforms, so scrubbing the browser moves the preview. `preview`:
        a plan's ``preview`` (each configuration's ``time_s`` and ``links``). Returns the
        browser (``<robot>:preview path``), made again for each plan."""
        if not self.transforms:
            self._make()
        self._remove_path()
        browser = self.scene.AddNewNodeByClass("vtkMRMLSequenceBrowserNode",
                                               f"{self.robot}:preview path")
        browser.SetAttribute(PREVIEW_ATTRIBUTE, self.robot)
        matrix = vtk.vtkMatrix4x4()
        for link, proxy in self.transforms.items():
            sequence = time_sequence(self.scene, f"{self.robot}:preview path:{link}",
                                     PREVIEW_ATTRIBUTE, self.robot)
            for item in preview:
                pose = item["links"].get(link)
                if pose is None:
                    continue
                step = slicer.vtkMRMLLinearTransformNode()
                step.SetMatrixTransformToParent(
                    fill_vtk(root_world @ np.asarray(pose, dtype=float), matrix))
                sequence.SetDataNodeAtValue(step, f"{float(item['time_s']):.6f}")
            browser.AddSynchronizedSequenceNode(sequence)
            browser.AddProxyNode(proxy, sequence, False)
            self.sequences.append(sequence)
        self.browser = browser
        browser.SetSelectedItemNumber(0)
        return browser

    def _remove_path(self) -> None:
        for node in [self.browser, *self.sequences]:
            if node is not None and node.GetScene() is not None:
                self.scene.RemoveNode(node)
        self.browser = None
        self.sequences = []

    def remove(self) -> None:
        self._remove_path()
        for node in [*self.models, *self.transforms.values()]:
            if node.GetScene() is not None:
                display: Optional[Any] = (node.GetDisplayNode()
                                          if node.IsA("vtkMRMLDisplayableNode") else None)
                self.scene.RemoveNode(node)
                if display is not None and display.GetScene() is not None:
                    self.scene.RemoveNode(display)
        self.transforms.clear()
        self.models.clear()


def ik_status(tip: str, result: Any) -> str:
    """A solve's answer in words, for the Motion section's status line."""
    if result.solved:
        return (f"Solved: {tip} at the target ({result.residual_mm:.3f} mm, "
                f"{result.residual_deg:.3f}°)")
    failure = result.failure or {}
    reason = failure.get("reason", "no solution")
    detail = failure.get("text", "")
    return (f"Not solved ({reason}): {detail}; best {result.residual_mm:.1f} mm, "
            f"{result.residual_deg:.1f}° away")


def obstacle_name(node_name: str) -> str:
    """A model's name as an obstacle's and a ROS name's part: letters, digits and ``_``,
    not starting with a digit."""
    name = re.sub(r"[^A-Za-z0-9_]+", "_", node_name).strip("_") or "model"
    return f"m_{name}" if name[0].isdigit() else name


def segmentation_surface(segmentation: Any) -> Any:
    """A segmentation as an obstacle: its segments' closed surfaces (as Slicer shows them)
    in one model, ``<segmentation>: obstacle surface``, under the segmentation's transform,
    so it moves with it. Made again on each call (a segment edited meanwhile)."""
    scene = segmentation.GetScene()
    segmentation.CreateClosedSurfaceRepresentation()
    ids = vtk.vtkStringArray()
    segmentation.GetSegmentation().GetSegmentIDs(ids)
    if ids.GetNumberOfValues() == 0:
        raise ValueError(f"the segmentation {segmentation.GetName()!r} has no segment")
    append = vtk.vtkAppendPolyData()
    for i in range(ids.GetNumberOfValues()):
        surface = vtk.vtkPolyData()
        if not segmentation.GetClosedSurfaceRepresentation(ids.GetValue(i), surface):
            raise ValueError(f"no closed surface for segment {ids.GetValue(i)!r} of "
                             f"{segmentation.GetName()!r}")
        append.AddInputData(surface)
    append.Update()
    name = f"{segmentation.GetName()}: obstacle surface"
    model = scene.GetFirstNode(name, "vtkMRMLModelNode")
    if model is None:
        model = scene.AddNewNodeByClass("vtkMRMLModelNode", name)
        model.CreateDefaultDisplayNodes()
        model.GetDisplayNode().SetVisibility(False)  # the segmentation shows itself
    surface = vtk.vtkPolyData()
    surface.DeepCopy(append.GetOutput())
    model.SetAndObservePolyData(surface)
    model.SetAndObserveTransformNodeID(segmentation.GetTransformNodeID())
    return model
