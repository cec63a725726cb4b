"""The ROS2Bridge module's GUI file: the .ui's widgets are the ones the code names, its
parameter fields are the parameter node's, its defaults the code's; without the client
packages the module says what to install. The widget itself runs in a real Slicer scene
(tests/slicer_real/test_transport_and_widget_in_slicer.py: each control reaches the logic)."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest

from slicer_client.send_plan import KIND_ORDER
from support import REPO

MODULE = REPO / "slicer_client" / "slicer_module" / "ROS2Bridge" / "ROS2Bridge.py"
UI = MODULE.parent / "Resources" / "UI" / "ROS2Bridge.ui"
PARAMETERS = MODULE.parent / "ROS2BridgeLib" / "parameters.py"


def _ui_widgets() -> dict[str, ET.Element]:
    return {w.get("name", ""): w for w in ET.parse(UI).getroot().iter("widget")}


def test_every_widget_the_code_names_is_in_the_ui_file() -> None:
    used = set(re.findall(r"\bui\.(\w+)", MODULE.read_text()))
    assert {"connectButton", "robotCombo", "sendNodeSelector", "jointsWidget"} <= used
    assert used <= set(_ui_widgets())


def test_the_ui_parameter_fields_are_the_parameter_node_s() -> None:
    tree = ast.parse(PARAMETERS.read_text())
    (node,) = [n for n in tree.body
               if isinstance(n, ast.ClassDef) and n.name == "ROS2BridgeParameterNode"]
    fields = {s.target.id for s in node.body
              if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name)}
    bound = {p.findtext("string"): name for name, w in _ui_widgets().items()
             for p in w.findall("property") if p.get("name") == "SlicerParameterName"}
    assert set(bound) == fields - {"bridgeState"}  # the saved bridges have no widget
    assert bound["port"] == "portSpin" and bound["keyFile"] == "keyFileEdit"


def test_the_ui_defaults_match_the_code_s() -> None:
    (default_frame,) = [ast.literal_eval(n.value) for n in ast.parse(PARAMETERS.read_text()).body
                        if isinstance(n, ast.Assign) and isinstance(n.targets[0], ast.Name)
                        and n.targets[0].id == "DEFAULT_FRAME"]
    widgets = _ui_widgets()

    def texts(name: str, tag: str = "string") -> list[str]:
        return [e.text or "" for e in widgets[name].iter(tag)]

    assert texts("markerFrameEdit") == texts("sendFrameEdit") == [default_frame] == ["base_link"]
    assert texts("sendNodeSelector")[:len(KIND_ORDER)] == list(KIND_ORDER)


@pytest.mark.integration  # a Python of its own, without the packages
def test_without_the_client_packages_the_module_says_what_to_install(tmp_path: Path) -> None:
    """A clone's module folder with neither the extension nor the wheel installed."""
    script = (
        "import sys, types\n"
        f"sys.path[:] = [p for p in sys.path if p not in ('', {str(MODULE.parents[3])!r})]\n"
        "sys.modules['protocol'] = None; sys.modules['slicer_client'] = None\n"
        f"sys.path.insert(0, {str(MODULE.parent)!r})\n"
        "import ROS2BridgeLib\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          cwd=tmp_path, timeout=60)
    assert done.returncode == 1
    assert "ImportError: The ROS2Bridge module needs the Python package(s) protocol, " \
        "slicer_client" in done.stderr
    assert "tools/build_client_wheel.py" in done.stderr
    assert "slicer.util.pip_install(" in done.stderr
