"""Time to turn a robot into POLYDATA messages: the Omni (../shared) and the demo arm.

Rows, per robot (median of --repeat runs, milliseconds):
- ours, cold cache: parse the URDF, read and convert every mesh, build and pack every
  POLYDATA body (a fresh MeshCache each run; the OS file cache is warm for all rows);
- ours, cached: the same with a warm MeshCache (a reload, or a second robot of the kind);
- baseline: yourdfpy's own ``URDF.load`` with its mesh loading and scene graph (no POLYDATA),
  the usual way to get a URDF's meshes in Python.
Plus forward kinematics per call and a 10,000-link chain (parse + FK).

usage: python bench/bench_robot_load.py [--repeat N]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import yourdfpy  # noqa: E402

from bridge.robots import (LoadOptions, MeshCache, load_robot, load_robot_file,  # noqa: E402
                           to_polydata)
from bridge.robots.demo import demo_urdf_path  # noqa: E402


def median_ms(fn: Callable[[], object], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append((time.perf_counter() - start) * 1000)
    return statistics.median(times)


def to_bodies(urdf: Path, packages: dict[str, Path], cache: MeshCache) -> int:
    model = load_robot_file(urdf, package_paths=packages, cache=cache)
    return sum(len(to_polydata(v).pack()) for v in model.visuals)


def yourdfpy_load(urdf: Path, packages: dict[str, Path]) -> None:
    def handler(fname: str) -> str:
        name = fname
        for package, folder in packages.items():
            prefix = f"package://{package}/"
            if name.startswith(prefix):
                return str(folder / name[len(prefix):])
        return str(urdf.parent / name)
    yourdfpy.URDF.load(str(urdf), load_meshes=True, build_scene_graph=True,
                       filename_handler=handler)


def chain(n: int) -> str:
    links = "".join(f'<link name="l{i}"><visual><geometry><box size="0.01 0.01 0.1"/>'
                    f'</geometry></visual></link>' for i in range(n))
    joints = "".join(f'<joint name="j{i}" type="revolute"><parent link="l{i - 1}"/>'
                     f'<child link="l{i}"/><origin xyz="0 0 0.1"/><axis xyz="0 1 0"/>'
                     f'<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
                     for i in range(1, n))
    return f'<robot name="chain">{links}{joints}</robot>'


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    robots: list[tuple[str, Path, dict[str, Path]]] = []
    omni = REPO.parent / "shared" / "robots" / "sensable_omni_model"
    if omni.is_dir():
        robots.append(("omni", omni / "urdf" / "omni.urdf", {"sensable_omni_model": omni}))
    else:
        print(f"(skipping the Omni: {omni} is absent)")
    urdf, packages = demo_urdf_path(Path(tempfile.mkdtemp(prefix="bench-demo-")))
    robots.append(("demo arm", urdf, packages))

    print(f"{'robot':<10} {'visuals':>7} {'triangles':>9} {'bytes':>9} {'cold ms':>8} "
          f"{'cached ms':>9} {'yourdfpy ms':>11} {'FK us':>7}")
    for name, path, pkgs in robots:
        model = load_robot_file(path, package_paths=pkgs, cache=MeshCache())
        size = to_bodies(path, pkgs, MeshCache())
        cold = median_ms(lambda path=path, pkgs=pkgs: to_bodies(path, pkgs, MeshCache()),
                         args.repeat)
        warm_cache = MeshCache()
        to_bodies(path, pkgs, warm_cache)
        cached = median_ms(lambda path=path, pkgs=pkgs, cache=warm_cache: to_bodies(
            path, pkgs, cache), args.repeat)
        baseline = median_ms(lambda path=path, pkgs=pkgs: yourdfpy_load(path, pkgs), args.repeat)
        joints = {j: 0.3 for j in model.kinematics.actuated_joints}
        fk_us = median_ms(lambda model=model, joints=joints: [model.link_poses(joints)
                                                              for _ in range(100)],
                          args.repeat) * 10
        triangles = sum(len(v.triangles) for v in model.visuals)
        print(f"{name:<10} {len(model.visuals):>7} {triangles:>9} {size:>9} {cold:>8.1f} "
              f"{cached:>9.1f} {baseline:>11.1f} {fk_us:>7.1f}")

    # A huge CAD-like mesh: 1.3 M triangles, read plain and decimated to 50,000.
    import trimesh
    big_mesh = Path(tempfile.mkdtemp(prefix="bench-mesh-")) / "sphere.stl"
    big_mesh.write_bytes(trimesh.exchange.stl.export_stl(trimesh.creation.icosphere(8)))
    huge = f'<robot name="h"><link name="a"><visual><geometry><mesh filename="{big_mesh}"/>' \
           '</geometry></visual></link></robot>'
    full_ms = median_ms(lambda: load_robot(huge, cache=MeshCache()), 3)
    small_ms = median_ms(lambda: load_robot(huge, cache=MeshCache(),
                                            options=LoadOptions(max_triangles=50_000)), 3)
    small = load_robot(huge, cache=MeshCache(), options=LoadOptions(max_triangles=50_000))
    print(f"1,310,720-triangle STL: load {full_ms:.0f} ms; load + decimate to "
          f"{len(small.visuals[0].triangles):,} triangles {small_ms:.0f} ms")

    text = chain(10_000)
    parse_ms = median_ms(lambda: load_robot(text, cache=MeshCache()), max(1, args.repeat // 2))
    big = load_robot(text, cache=MeshCache())
    fk_ms = median_ms(lambda: big.link_poses({}), args.repeat)
    print(f"10,000-link chain: load (parse + 10,000 box visuals) {parse_ms:.0f} ms, "
          f"FK {fk_ms:.1f} ms per call")
    return 0


if __name__ == "__main__":
    sys.exit(main())
