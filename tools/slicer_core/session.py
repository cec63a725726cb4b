"""The ROS2Bridge module loaded into a real 3D Slicer core (slicer-core from PyPI with Slicer's
own OpenIGTLinkIF connector, built by ../shared/peers/slicer-openigtlinkif): what Slicer does
at start-up, minus Qt (qt_layer.py names what is imitated).

Runs in the peer's Python (`PREFIX/venv/bin/python`, where `import slicer, slicer_app`
works), never in the daemon's: `open_session()` gives the scene, the module's logic as
`slicer.util.getModuleLogic('ROS2Bridge')` returns it, and `pump()`, Slicer's event loop.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional

REPO = Path(__file__).resolve().parents[2]
MODULE_DIR = REPO / "slicer_client" / "slicer_module" / "ROS2Bridge"


@dataclass
class Session:
    app: Any  # slicer_app.SlicerApp: scene, application logic, module logics
    slicer_app: Any  # slicer.app (qt_layer.Application)
    module: Any  # the ROS2Bridge.py module object
    logic: Any  # its ROS2BridgeLogic, as getModuleLogic('ROS2Bridge') gives it

    @property
    def scene(self) -> Any:
        return self.app.scene

    def pump(self, seconds: float = 0.0, until: Optional[Callable[[], bool]] = None,
             what: str = "the condition") -> None:
        """Slicer's event loop for `seconds`, or until `until()` holds (an AssertionError
        naming `what` if it does not within `seconds`, scaled as the test suite scales its
        deadlines: SLICER_BRIDGE_TEST_TIME_SCALE)."""
        if until is not None:
            seconds *= float(os.environ.get("SLICER_BRIDGE_TEST_TIME_SCALE", "1"))
        deadline = time.monotonic() + seconds
        while True:
            self.slicer_app.processEvents()
            if until is not None and until():
                return
            if time.monotonic() >= deadline:
                if until is not None:
                    raise AssertionError(f"not within {seconds} s: {what}")
                return
            time.sleep(0.005)

    def close(self) -> None:
        self.logic.cleanup()
        self.app.close()


def open_session(*, subject_hierarchy: bool = True) -> Session:
    """Slicer's start-up for this module: the scene and module logics, the Qt layer, the
    module folder on sys.path, the module's class made (it hooks startupCompleted), its
    logic, then startupCompleted (the reference's entry points are installed).
    `subject_hierarchy=False` leaves out the items Slicer's Qt plugins make for new nodes."""
    for path in (str(REPO), str(MODULE_DIR)):
        if path not in sys.path:
            sys.path.insert(0, path)
    import slicer_app  # the peer's Qt-free application

    from tools.slicer_core import qt_layer
    app = slicer_app.SlicerApp(subject_hierarchy=subject_hierarchy)
    _register_segmentation_converters()
    slicer_qt = qt_layer.install(app)
    import ROS2Bridge
    ROS2Bridge.ROS2Bridge(None)
    logic = ROS2Bridge.ROS2BridgeLogic()
    slicer_qt.logics["ROS2Bridge"] = logic
    slicer_qt.startupCompleted()
    return Session(app, slicer_qt, ROS2Bridge, logic)


def _register_segmentation_converters() -> None:
    """What Slicer's Segmentations module does as it starts (qSlicerSegmentationsModule::
    setup): the representation conversion rules, with which a segmentation makes its
    closed surfaces. slicer-core has the rules but not that module's start-up."""
    import slicer

    factory = slicer.vtkSegmentationConverterFactory.GetInstance()
    for name in ("vtkBinaryLabelmapToClosedSurfaceConversionRule",
                 "vtkClosedSurfaceToBinaryLabelmapConversionRule",
                 "vtkClosedSurfaceToFractionalLabelmapConversionRule",
                 "vtkFractionalLabelmapToClosedSurfaceConversionRule"):
        rule = getattr(slicer, name, None)
        if rule is not None:
            factory.RegisterConverterRule(rule())
