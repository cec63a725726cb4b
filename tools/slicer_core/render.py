"""Render a real Slicer scene to PNG with Slicer's own 3D displayable managers (models,
markups, transforms, the view's background and camera), offscreen: the vtk wheel renders
through EGL where no display is. Runs in the Slicer peer's Python."""

from __future__ import annotations

from typing import Any

import slicer
import vtk

# Slicer's 3D view draws models, markups and transforms with these (its view factory's
# defaults include them; the camera and view managers keep the view node's settings).
DISPLAYABLE_MANAGERS = ("vtkMRMLCameraDisplayableManager", "vtkMRMLViewDisplayableManager",
                        "vtkMRMLModelDisplayableManager", "vtkMRMLMarkupsDisplayableManager",
                        "vtkMRMLLinearTransformsDisplayableManager")


class SceneView:
    """One 3D view of `scene`: a view node, a renderer and Slicer's displayable managers."""

    def __init__(self, app: Any, size: tuple[int, int] = (1200, 900)) -> None:
        self.view = app.scene.AddNewNodeByClass("vtkMRMLViewNode")
        self.view.SetLayoutName("1")
        self.view.SetBoxVisible(False)
        self.view.SetAxisLabelsVisible(False)
        self.view.SetBackgroundColor(0.93, 0.94, 0.96)
        self.view.SetBackgroundColor2(0.62, 0.68, 0.78)
        self.renderer = vtk.vtkRenderer()
        self.window = vtk.vtkRenderWindow()
        self.window.SetOffScreenRendering(1)
        self.window.SetMultiSamples(8)
        self.window.AddRenderer(self.renderer)
        self.window.SetSize(*size)
        # Slicer's camera manager needs an interactor (without one it crashes).
        self.interactor = vtk.vtkRenderWindowInteractor()
        self.interactor.SetRenderWindow(self.window)
        factory = slicer.vtkMRMLThreeDViewDisplayableManagerFactory.GetInstance()
        factory.SetMRMLApplicationLogic(app.app_logic)
        for name in DISPLAYABLE_MANAGERS:
            if not factory.IsDisplayableManagerRegistered(name):
                factory.RegisterDisplayableManager(name)
        self.group = slicer.vtkMRMLDisplayableManagerGroup()
        self.group.Initialize(factory, self.renderer)
        self.group.SetMRMLDisplayableNode(self.view)

    def look(self, position: tuple[float, float, float], focal: tuple[float, float, float],
             zoom: float = 1.0) -> None:
        camera = self.renderer.GetActiveCamera()
        camera.SetViewUp(0, 0, 1)
        camera.SetPosition(*position)
        camera.SetFocalPoint(*focal)
        self.renderer.ResetCamera()
        camera.Zoom(zoom)

    def caption(self, text: str) -> None:
        actor = vtk.vtkTextActor()
        actor.SetInput(text)
        actor.GetTextProperty().SetFontSize(20)
        actor.GetTextProperty().SetColor(0.15, 0.17, 0.2)
        actor.SetPosition(16, self.window.GetSize()[1] - 40)
        self.renderer.AddViewProp(actor)

    def png(self, path: str) -> None:
        self.group.RequestRender()
        self.window.Render()
        grab = vtk.vtkWindowToImageFilter()
        grab.SetInput(self.window)
        grab.Update()
        writer = vtk.vtkPNGWriter()
        writer.SetFileName(path)
        writer.SetInputConnection(grab.GetOutputPort())
        writer.Write()
