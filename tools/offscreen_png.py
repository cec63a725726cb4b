"""Write VTK renderers to a PNG offscreen (EGL or OSMesa: no display needed), for the
README's markers picture (`render_markers_picture.py`; the demo picture comes from a real
Slicer scene: `render_scene_picture.py`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence


def write_png(renderers: Sequence[Any], size: tuple[int, int], out: Path) -> None:
    import vtk

    window = vtk.vtkRenderWindow()
    window.SetOffScreenRendering(1)
    window.SetMultiSamples(8)
    for renderer in renderers:
        window.AddRenderer(renderer)
    window.SetSize(*size)
    window.Render()
    grab = vtk.vtkWindowToImageFilter()
    grab.SetInput(window)
    grab.Update()
    writer = vtk.vtkPNGWriter()
    writer.SetFileName(str(out))
    writer.SetInputConnection(grab.GetOutputPort())
    writer.Write()
