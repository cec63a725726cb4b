"""Render the README's demo picture from a real 3D Slicer scene -> docs/demo-robot.png.

    .venv/bin/python tools/render_scene_picture.py [--out docs/demo-robot.png]

End to end through the real path: starts `slicer-ros2-bridge demo` on a free port in a ROS
domain of its own; in 3D Slicer's core (slicer-core from PyPI with Slicer's own
OpenIGTLinkIF connector: the peer built from ../shared/peers/slicer-openigtlinkif, see
tools/slicer_core/peer.py) the ROS2Bridge module connects and loads the robot; Slicer's
connector makes the nodes, the module places them, and Slicer's own 3D displayable
managers render the scene offscreen (tools/slicer_core/render.py). Only Qt is imitated
(tools/slicer_core/qt_layer.py).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from tools.slicer_core.demo import peer_or_exit, ros_env, start_demo  # noqa: E402

SCENE = REPO / "tools" / "slicer_core" / "scenes" / "demo_robot_picture.py"
RUNNER = REPO / "tools" / "slicer_core" / "run_scene.py"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "demo-robot.png")
    parser.add_argument("--settle", type=float, default=9.0,
                        help="seconds of motion watched for the pose reaching furthest out "
                             "(default 9: a full swing)")
    parser.add_argument("--size", type=int, nargs=2, default=(1200, 900))
    args = parser.parse_args(argv)
    python = peer_or_exit()
    env = ros_env("render")
    demo, port = start_demo(env)
    try:
        scene_args = {"port": port, "models": 14, "settle": args.settle,
                      "size": list(args.size), "out": str(args.out.resolve())}
        args.out.parent.mkdir(parents=True, exist_ok=True)
        done = subprocess.run([str(python), str(RUNNER), str(SCENE), json.dumps(scene_args)],
                              capture_output=True, text=True, env=dict(env, PYTHONPATH=""))
    finally:
        os.killpg(demo.pid, signal.SIGINT)
        demo.wait(30)
    results = [ln for ln in done.stdout.splitlines() if ln.startswith("RESULT ")]
    if done.returncode != 0 or not results:
        raise SystemExit(f"the scene failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}")
    result = json.loads(results[-1][len("RESULT "):])
    print(f"wrote {args.out} ({result['models']} models, {result['links']} link transforms)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
