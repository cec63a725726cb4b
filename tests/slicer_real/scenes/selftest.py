"""The module's self-test (slicer_client/slicer_module/selftest.py, what users run inside
3D Slicer), run in the real scene once per entry of args["ports"]: a daemon's port (scene
placement and the round trip through Slicer's connector), or None (ROS2BRIDGE_TEST_PORT
unset: the scene part only)."""

from __future__ import annotations

import contextlib
import io
import os
import runpy
from typing import Any

from tools.slicer_core.session import MODULE_DIR


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    from slicer.ScriptedLoadableModule import ScriptedLoadableModuleTest
    selftest = runpy.run_path(str(MODULE_DIR.parent / "selftest.py"))
    runs = []
    for port in args["ports"]:
        os.environ.pop("ROS2BRIDGE_TEST_PORT", None)
        if port is not None:
            os.environ["ROS2BRIDGE_TEST_PORT"] = str(port)
        ScriptedLoadableModuleTest.displayed.clear()
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = selftest["main"]()
        runs.append({"code": code, "displayed": list(ScriptedLoadableModuleTest.displayed),
                     "stdout": out.getvalue(), "stderr": err.getvalue()})
    return {"runs": runs}
