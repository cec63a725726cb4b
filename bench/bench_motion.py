"""Motion (issue 46): inverse kinematics of a 7-joint arm, and a link's distance to a
100,000-triangle mesh, each beside a stated baseline.

Rows:
- IK, ours: `bridge.motion.solve_ik` (damped least squares with limits and restarts) on
  the 7-joint Panda-like arm of tests/seven_dof_urdf.py, --targets targets from random
  valid configurations, each seeded from another random configuration (what a dragged
  target far from the current pose asks);
- IK, ours from a near seed: the same targets seeded 0.05 rad from their answer (what a
  dragged target asks, frame to frame);
- IK, baseline: pinocchio's own documented CLIK loop (its example "inverse kinematics":
  LOCAL frame Jacobian, damping 1e-12, step 0.1, at most 1000 iterations, no limits) on
  pinocchio's own URDF model of the same arm, from the same seeds;
- distance, ours: `CollisionWorld.distances` (FK, then coal's sphere-to-BVH distance) from
  a link (a 5 cm sphere) to a 101,120-triangle closed surface;
- distance, baseline: trimesh's proximity query (closest point on the mesh to the sphere's
  centre, minus the radius) on the same mesh, its index already built.

Times are p50 / p99 in milliseconds; success is within 0.1 mm and 0.1 degrees.

usage: python bench/bench_motion.py [--targets N] [--queries N]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402
import trimesh  # noqa: E402

from bridge.motion.collisions import CollisionWorld  # noqa: E402
from bridge.motion.ik import solve_ik  # noqa: E402
from bridge.motion.model import MotionModel  # noqa: E402
from bridge.robots import load_robot  # noqa: E402
from seven_dof_urdf import SEVEN_DOF_URDF  # noqa: E402

TIP = "tcp"
SPHERE_URDF = """<robot name="probe">
  <link name="base"/><link name="tool">
    <collision><geometry><sphere radius="0.05"/></geometry></collision></link>
  <joint name="x" type="prismatic"><parent link="base"/><child link="tool"/>
    <axis xyz="1 0 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>"""


def percentiles(times_s: list[float]) -> tuple[float, float]:
    ms = np.asarray(times_s) * 1000.0
    return float(np.percentile(ms, 50)), float(np.percentile(ms, 99))


def clik(model: pin.Model, data: pin.Data, frame: int, target: pin.SE3,
         q: np.ndarray) -> tuple[np.ndarray, bool]:
    """pinocchio's documented CLIK example, as published (frame version, no limits)."""
    eps, it_max, dt, damp = 1e-4, 1000, 1e-1, 1e-12
    for _ in range(it_max):
        pin.framesForwardKinematics(model, data, q)
        i_md = data.oMf[frame].actInv(target)
        err = pin.log(i_md).vector
        if np.linalg.norm(err) < eps:
            return q, True
        jac = pin.computeFrameJacobian(model, data, q, frame, pin.ReferenceFrame.LOCAL)
        jac = -pin.Jlog6(i_md.inverse()) @ jac
        v = -jac.T @ np.linalg.solve(jac @ jac.T + damp * np.eye(6), err)
        q = pin.integrate(model, q, v * dt)
    return q, False


def reached(pose: np.ndarray, target: np.ndarray) -> bool:
    mm = float(np.linalg.norm(pose[:3, 3] - target[:3, 3])) * 1000.0
    cos = (np.trace(pose[:3, :3].T @ target[:3, :3]) - 1.0) / 2.0
    return mm <= 0.1 and math.degrees(math.acos(max(-1.0, min(1.0, cos)))) <= 0.1


def bench_ik(count: int) -> list[tuple[str, str, float, float, str]]:
    ours = MotionModel(load_robot(SEVEN_DOF_URDF))
    theirs = pin.buildModelFromXML(SEVEN_DOF_URDF)
    their_data = theirs.createData()
    their_frame = theirs.getFrameId(TIP)
    rng = np.random.default_rng(7)
    rows = []
    far: list[float] = []
    near: list[float] = []
    base: list[float] = []
    solved = {"far": 0, "near": 0, "base": 0}
    within = 0
    for _ in range(count):
        truth = ours.random_theta(rng)
        target = ours.link_pose(truth, TIP)
        seed = ours.random_theta(rng)
        start = time.perf_counter()
        result = solve_ik(ours, target, TIP, ours.positions_of(seed))
        far.append(time.perf_counter() - start)
        solved["far"] += result.ok
        close = ours.positions_of(truth + rng.normal(0.0, 0.05, len(truth)))
        start = time.perf_counter()
        result = solve_ik(ours, target, TIP, close)
        near.append(time.perf_counter() - start)
        solved["near"] += result.ok
        q0 = ours.configuration(seed)[:theirs.nq]  # the same start, pinocchio's joints
        start = time.perf_counter()
        q, ok = clik(theirs, their_data, their_frame, pin.SE3(target), q0.copy())
        base.append(time.perf_counter() - start)
        pin.framesForwardKinematics(theirs, their_data, q)
        good = ok and reached(np.array(their_data.oMf[their_frame].homogeneous), target)
        solved["base"] += good
        within += good and bool(np.all(q >= theirs.lowerPositionLimit - 1e-9)
                                and np.all(q <= theirs.upperPositionLimit + 1e-9))
    for name, times, key, note in (
            ("IK 7-joint, ours (random seed)", far, "far", "within limits"),
            ("IK 7-joint, ours (seed 0.05 rad away)", near, "near", "within limits"),
            ("IK 7-joint, pinocchio CLIK example", base, "base",
             f"no limits: {within}/{count} within")):
        p50, p99 = percentiles(times)
        rows.append((name, f"{solved[key]}/{count}", p50, p99, note))
    return rows


def bench_distance(count: int) -> list[tuple[str, str, float, float, str]]:
    mesh = trimesh.creation.uv_sphere(radius=0.1, count=[159, 159])  # 101,120 triangles
    triangles = len(mesh.faces)
    model = MotionModel(load_robot(SPHERE_URDF))
    world = CollisionWorld(model)
    start = time.perf_counter()
    world.set_obstacle("anatomy", mesh.vertices, mesh.faces)
    build_ours = time.perf_counter() - start
    start = time.perf_counter()
    query = trimesh.proximity.ProximityQuery(mesh)
    query.on_surface([[0.5, 0.0, 0.0]])  # builds its index
    build_theirs = time.perf_counter() - start
    rng = np.random.default_rng(3)
    ours: list[float] = []
    theirs: list[float] = []
    worst = 0.0
    for _ in range(count):
        x = float(rng.uniform(0.2, 0.9))
        theta = np.array([x])
        start = time.perf_counter()
        [distance] = world.distances(theta, "tool")
        ours.append(time.perf_counter() - start)
        start = time.perf_counter()
        _, gap, _ = query.on_surface([[x, 0.0, 0.0]])
        theirs.append(time.perf_counter() - start)
        worst = max(worst, abs(distance.distance_m - (float(gap[0]) - 0.05)) * 1000.0)
    rows = []
    for name, times, build in (("distance to a 100k-triangle mesh, ours (coal)", ours,
                                build_ours),
                               ("distance, trimesh proximity query", theirs, build_theirs)):
        p50, p99 = percentiles(times)
        rows.append((name, f"{triangles} tris", p50, p99, f"build {build * 1000:.0f} ms"))
    rows.append(("  ours vs trimesh, largest difference", "", worst, worst, "mm"))
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--targets", type=int, default=200)
    parser.add_argument("--queries", type=int, default=500)
    args = parser.parse_args()
    rows = bench_ik(args.targets) + bench_distance(args.queries)
    print(f"{'what':<46} {'solved':>9} {'p50 ms':>8} {'p99 ms':>8}  note")
    for name, solved, p50, p99, note in rows:
        print(f"{name:<46} {solved:>9} {p50:>8.3f} {p99:>8.3f}  {note}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
