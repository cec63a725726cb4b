"""Run one scene script in a real 3D Slicer core (the peer's Python), as the real-Slicer
tier does: `run_scene.py SCRIPT 'JSON ARGS'`. SCRIPT defines `main(session, args) -> dict`;
its result is printed last as one line, `RESULT {json}`. ARGS' "session" entry holds
open_session's options. Exit 1 with the traceback when it
raises. The session (scene, connector, module logic) is closed either way."""

from __future__ import annotations

import json
import runpy
import sys
import traceback
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from tools.slicer_core.session import open_session  # noqa: E402


def main() -> int:
    script, args = sys.argv[1], json.loads(sys.argv[2] if len(sys.argv) > 2 else "{}")
    sys.path.insert(0, str(Path(script).resolve().parent))  # the scene's own helpers
    scene_main = runpy.run_path(script)["main"]
    session = open_session(**args.pop("session", {}))
    try:
        result = scene_main(session, args)
    except Exception:  # noqa: BLE001 - printed for the test, and the exit code says it
        traceback.print_exc()
        return 1
    finally:
        session.close()
    print("RESULT " + json.dumps(result), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
