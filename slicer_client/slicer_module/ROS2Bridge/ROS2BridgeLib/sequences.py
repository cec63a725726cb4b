"""A played bag into Slicer's Sequences (issue 45): the module, connected to a player
(`slicer-ros2-bridge play BAG`), seeks it to each sampled time and records what the
connector's nodes hold then, one sequence per node, indexed by the bag's clock (seconds
from its start), under one sequence browser whose proxies are the nodes themselves. So the
robot's link transforms (its models stay under them), tf lookups, images, point clouds and
text all step together, and scrubbing the browser moves the robot."""

from __future__ import annotations

import time
from typing import Any, Callable

import slicer

__all__ = ["SequenceRecorder", "record_bag", "recorded_nodes", "settle", "time_sequence"]

ROLE_ATTRIBUTE = "OpenIGTLink.ros2.role"
# What does not change along a bag: a robot's meshes (their link transforms move them).
STILL_ROLES = ("robot_visual",)
RECORDED_CLASSES = ("vtkMRMLLinearTransformNode", "vtkMRMLScalarVolumeNode",
                    "vtkMRMLVectorVolumeNode", "vtkMRMLModelNode", "vtkMRMLTextNode")
SEQUENCE_ATTRIBUTE = "ROS2Bridge.bag"  # the bag a sequence or browser was made from
SETTLE_QUIET_S = 0.05  # a seek's state is one burst: this long without a change ends it
SETTLE_TIMEOUT_S = 1.0  # no change at all this long: the new time shows the same state


def time_sequence(scene: Any, name: str, attribute: str, value: str) -> Any:
    """A sequence node indexed by time in seconds (numeric), marked with `attribute`."""
    sequence = scene.AddNewNodeByClass("vtkMRMLSequenceNode", name)
    sequence.SetAttribute(attribute, value)
    sequence.SetIndexName("time")
    sequence.SetIndexUnit("s")
    sequence.SetIndexType(sequence.NumericIndex)
    return sequence


def recorded_nodes(connector: Any) -> list[Any]:
    """The connector's nodes whose content follows the bag's clock (a robot's link nodes:
    those its tracking-data bundle made)."""
    nodes = []
    for i in range(connector.GetNumberOfIncomingMRMLNodes()):
        node = connector.GetIncomingMRMLNode(i)
        if node is not None and node.IsA("vtkMRMLIGTLTrackingDataBundleNode"):
            nodes += [node.GetTransformNode(j) for j in range(node.GetNumberOfTransformNodes())]
        elif (node is not None and any(node.IsA(cls) for cls in RECORDED_CLASSES)
                and node.GetAttribute(ROLE_ATTRIBUTE) not in STILL_ROLES):
            nodes.append(node)
    return nodes


class SequenceRecorder:
    """Sequences of nodes, filled one sample at a time (`add`), then put under one browser
    (`finish`). Not before: a browser sets its proxies to its selected item whenever its
    sequences change, which would undo what the connector writes in them meanwhile."""

    def __init__(self, scene: Any, bag: str) -> None:
        self.scene = scene
        self.bag = bag
        self.sequences: dict[str, tuple[Any, Any]] = {}  # node ID -> (node, its sequence)

    def add(self, offset: float, nodes: list[Any]) -> None:
        """What each of `nodes` holds now, at `offset` s on the bag's clock."""
        for node in nodes:
            entry = self.sequences.get(node.GetID())
            if entry is None:
                entry = self.sequences[node.GetID()] = (node, self._sequence_of(node))
            entry[1].SetDataNodeAtValue(node, f"{offset:.6f}")

    def _sequence_of(self, node: Any) -> Any:
        return time_sequence(self.scene, f"{node.GetName()} (bag)", SEQUENCE_ATTRIBUTE,
                             self.bag)

    def finish(self, name: str) -> Any:
        """The browser of the sequences, its proxies the nodes themselves, at item 0."""
        browser = self.scene.AddNewNodeByClass("vtkMRMLSequenceBrowserNode", name)
        browser.SetAttribute(SEQUENCE_ATTRIBUTE, self.bag)
        for node, sequence in self.sequences.values():
            browser.AddSynchronizedSequenceNode(sequence)
            browser.AddProxyNode(node, sequence, False)
        browser.SetSelectedItemNumber(0)
        return browser


def record_bag(scene: Any, connector: Any, bag: str, offsets: list[float],
               seek: Callable[[float], Any]) -> Any:
    """Seek to each of `offsets` and record the nodes once the state at that time is in
    them (`settle`)."""
    recorder = SequenceRecorder(scene, bag)
    for offset in offsets:
        before = _mtimes(recorded_nodes(connector))
        seek(offset)
        settle(connector, before)
        recorder.add(offset, recorded_nodes(connector))
    return recorder.finish(f"{bag} (bag)")


def _mtimes(nodes: list[Any]) -> dict[str, int]:
    return {node.GetID(): node.GetMTime() for node in nodes}


def settle(connector: Any, before: dict[str, int], *, quiet_s: float = SETTLE_QUIET_S,
           timeout_s: float = SETTLE_TIMEOUT_S) -> None:
    """Run Slicer's event loop until the burst of state a seek sends is in its nodes: some node
    changed, then a pass of `quiet_s` changed none. The seek's answer comes after that
    state on the socket but is taken out of turn, so the nodes may not hold it yet. If
    nothing changes within `timeout_s`, the state at the new time is the one shown."""
    deadline = time.monotonic() + timeout_s
    last, changed_at = before, None
    while time.monotonic() < deadline:
        slicer.app.processEvents()  # OpenIGTLinkIF's timer puts what came in the nodes
        now = _mtimes(recorded_nodes(connector))
        if now != last:
            last, changed_at = now, time.monotonic()
        elif changed_at is not None and time.monotonic() - changed_at >= quiet_s:
            return
        time.sleep(0.005)  # the connector's own 5 ms timer
