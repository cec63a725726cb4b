"""An install where the optional compiled modules were not built (no C compiler, Cython or
rcl headers): the bridge falls back to rclpy's take and the pure Python tf store, and asking
for the compiled store says it was not built. Run in a fresh interpreter where importing
them fails, as it does in such an install."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

from support import REPO

pytestmark = pytest.mark.integration  # starts a process

_SCRIPT = textwrap.dedent("""
    import json, sys
    sys.modules["bridge.ros._rcl_reader"] = None  # import fails: ImportError
    sys.modules["bridge.tf._compiled_store"] = None
    from bridge.ros import raw_reader
    from bridge.tf import InvalidArgumentError, StampedTransform, TfBuffer, buffer

    out = {"reader": raw_reader.available(), "compiled": buffer.COMPILED}
    tf = TfBuffer()
    tf.set_transforms([StampedTransform("w", "a", 5, (0.0, 0.0, 1.0), (0.0, 0.0, 0.0, 1.0))],
                      static=False)
    out["lookup"] = list(tf.lookup("w", "a").translation)
    out["store"] = type(tf._store).__name__
    try:
        TfBuffer(compiled=True)
    except InvalidArgumentError as error:
        out["refused"] = str(error)
    print(json.dumps(out))
""")


def test_without_the_compiled_modules_the_python_fallbacks_serve() -> None:
    result = subprocess.run([sys.executable, "-c", _SCRIPT], cwd=REPO, capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout.strip().splitlines()[-1])
    assert out["reader"] is False and out["compiled"] is False
    assert out["lookup"] == [0.0, 0.0, 1.0]
    assert out["store"] == "FrameStore"
    assert "compiled" in out["refused"]
    assert "the compiled store was not built" in out["refused"]
