"""The module's self-test (slicer_client/slicer_module/selftest.py, what users run inside
3D Slicer), run in the real scene with a daemon port: scene placement and the round trip
through Slicer's connector."""

from __future__ import annotations

import os
import runpy
from typing import Any

from tools.slicer_core.session import MODULE_DIR


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    os.environ["ROS2BRIDGE_TEST_PORT"] = str(args["port"])
    selftest = runpy.run_path(str(MODULE_DIR.parent / "selftest.py"))
    code = selftest["main"]()
    from slicer.ScriptedLoadableModule import ScriptedLoadableModuleTest
    return {"code": code, "displayed": ScriptedLoadableModuleTest.displayed}
