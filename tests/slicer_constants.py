"""3D Slicer's event and state numbers that tests/slicer_standin.py hands out, in one table.
The real-Slicer tier checks every entry against slicer-core and Slicer's OpenIGTLinkIF
connector (tests/slicer_real/test_constants_in_slicer.py), so they are Slicer's, not
remembered ones. Key: "<class>.<name>" as Python reaches it in `slicer` (or `vtk`)."""

from __future__ import annotations

SLICER_CONSTANTS: dict[str, int] = {
    "vtkCommand.ModifiedEvent": 33,
    "vtkMRMLScene.StartSaveEvent": 8464,
    "vtkMRMLScene.StartCloseEvent": 8451,
    "vtkMRMLScene.EndCloseEvent": 8707,
    "vtkMRMLScene.EndImportEvent": 8709,
    "vtkMRMLTransformNode.TransformModifiedEvent": 15000,
    "vtkMRMLTextNode.TextModifiedEvent": 51000,
    "vtkMRMLModelNode.MeshModifiedEvent": 17001,
    "vtkMRMLMarkupsNode.PointModifiedEvent": 19008,
    "vtkMRMLIGTLConnectorNode.ConnectedEvent": 118944,
    "vtkMRMLIGTLConnectorNode.DisconnectedEvent": 118945,
    "vtkMRMLIGTLConnectorNode.StateOff": 0,
    "vtkMRMLIGTLConnectorNode.StateWaitConnection": 1,
    "vtkMRMLIGTLConnectorNode.StateConnected": 2,
    "vtkSlicerOpenIGTLinkCommand.CommandCompletedEvent": 128004,
    "vtkSlicerOpenIGTLinkCommand.CommandExpired": 2,
    "vtkSlicerOpenIGTLinkCommand.CommandResponseReceived": 5,
}

# How a Python observer is handed the event, as VTK's wrapping does: by name for vtkCommand's
# own events, 'NoEvent' for any other number (a class's custom event).
VTK_EVENT_NAMES: dict[int, str] = {33: "ModifiedEvent"}


def event_as_observers_get_it(event: int) -> str:
    return VTK_EVENT_NAMES.get(event, "NoEvent")


def constant(key: str) -> int:
    return SLICER_CONSTANTS[key]
