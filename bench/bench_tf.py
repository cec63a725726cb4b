"""Benchmark of the daemon's tf buffer (bridge/tf): lookups, batch inserts, lookup registry.

Run: .venv/bin/python bench/bench_tf.py [--quick]

Measured in the same run, on the same data:
- TfBuffer.lookup on a 20-frame tree, as a chain (leaf to root) and branchy (leaf to leaf
  of two branches), at the latest common time and at a time between samples (every link
  interpolated);
- a naive baseline doing the same latest lookup by composing one 4x4 numpy matrix per link
  (protocol.conversions.pose_to_matrix, then @), the obvious way to write it, and the same
  with the 4x4 matrices built once at insert time (numpy's best case: products only);
- composing one link with the tuple tf-math, with numpy (3x3 R, t) and with 4x4 matrices
  built by pose_to_matrix (why bridge/tf/math.py uses tuples);
- set_transforms for a 7-link robot update (one /tf message), and the registry's updates()
  call that follows it;
- the daemon's work per /tf message of that robot on each tf store, the compiled one
  (bridge/tf/_compiled_store.pyx: the CDR read and stored in one call) and the pure Python
  fallback (bridge/tf/store.py: read by bridge/codecs/cdr.py, then set_transforms): the
  serialized TFMessage in, the 7 registered lookups' results out.
Each figure is the best of several repeats (the machine is shared; the best is the least
disturbed), in microseconds per call.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from bisect import bisect_right
from typing import Callable, Dict, List, Tuple

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from bridge.tf import LookupRegistry, StampedTransform, TfBuffer  # noqa: E402
from bridge.tf.math import Tf7, compose  # noqa: E402
from protocol.conversions import pose_to_matrix  # noqa: E402

S = 1_000_000_000
SAMPLES = 100  # per dynamic frame: 1 s of data at 100 Hz
STEP = S // 100


def quat(axis: Tuple[float, float, float], angle: float) -> Tuple[float, float, float, float]:
    n = math.sqrt(sum(a * a for a in axis))
    s = math.sin(angle / 2) / n
    return (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle / 2))


def build(parents: Dict[str, str]) -> Tuple[TfBuffer, Dict[str, Tuple[str, List[int], List[Tf7]]]]:
    """A buffer with SAMPLES samples per frame, and the same data for the naive baseline."""
    buf = TfBuffer()
    plain: Dict[str, Tuple[str, List[int], List[Tf7]]] = {}
    for k in range(SAMPLES):
        batch = []
        for i, (child, parent) in enumerate(parents.items()):
            v = (0.1 * i, 0.01 * k, 0.05, *quat((1.0, 0.5 * i, 0.3), 0.1 * i + 0.001 * k))
            batch.append(StampedTransform(parent, child, (k + 1) * STEP, v[:3], v[3:]))
            entry = plain.setdefault(child, (parent, [], []))
            entry[1].append((k + 1) * STEP)
            entry[2].append(v)  # type: ignore[arg-type]
        buf.set_transforms(batch, static=False)
    return buf, plain


def naive_lookup(plain: Dict[str, Tuple[str, List[int], List[Tf7]]], target: str,
                 source: str, t: int,
                 premade: Dict[str, List[np.ndarray]] | None = None) -> np.ndarray:
    """The obvious implementation: one 4x4 matrix per link, numpy products, matrix inverse.

    With ``premade`` the 4x4 matrices were built once per sample at insert time (the best
    case for numpy): only the products and the inverse remain per lookup.
    """

    def to_root(frame: str) -> Tuple[List[str], List[np.ndarray]]:
        frames, mats = [frame], []
        while frame in plain:
            parent, stamps, values = plain[frame]
            i = bisect_right(stamps, t) - 1
            if premade is not None:
                mats.append(premade[frame][i])
            else:
                v = values[i]
                mats.append(pose_to_matrix(v[:3], v[3:]))
            frame = parent
            frames.append(frame)
        return frames, mats

    sf, sm = to_root(source)
    tf_, tm = to_root(target)
    common = next(f for f in sf if f in set(tf_))
    a = np.eye(4)
    for m in sm[: sf.index(common)]:
        a = m @ a
    b = np.eye(4)
    for m in tm[: tf_.index(common)]:
        b = m @ b
    return np.linalg.inv(b) @ a


def best_us(fn: Callable[[], object], number: int, repeat: int) -> float:
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter_ns()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter_ns() - t0) / number)
    return best / 1000.0


def numpy_compose(a: Tuple[np.ndarray, np.ndarray],
                  b: Tuple[np.ndarray, np.ndarray]) -> Tuple[np.ndarray, np.ndarray]:
    """The numpy way to compose one link: (R 3x3, t 3) pairs, R_a R_b and R_a t_b + t_a."""
    ra, ta = a
    rb, tb = b
    return ra @ rb, ra @ tb + ta


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats (CI smoke run)")
    args = parser.parse_args()
    number, repeat = (200, 3) if args.quick else (2000, 7)

    chain = {f"c{i}": f"c{i - 1}" for i in range(1, 21)}  # c0 <- c1 <- ... <- c20
    # branchy: a binary tree of 20 frames under b0, lookup between the two deepest leaves
    branchy = {f"b{i}": f"b{(i - 1) // 2}" for i in range(1, 21)}
    chain_buf, chain_plain = build(chain)
    tree_buf, tree_plain = build(branchy)
    mid = SAMPLES // 2 * STEP + STEP // 2  # between two samples: every link interpolates
    latest = SAMPLES * STEP

    # The implementations agree before we time them.
    for buf, plain, target, source in ((chain_buf, chain_plain, "c0", "c20"),
                                       (tree_buf, tree_plain, "b20", "b15")):
        got = buf.lookup(target, source).matrix_mm()
        np.testing.assert_allclose(got, naive_lookup(plain, target, source, latest), atol=1e-6)

    chain_mats = {f: [pose_to_matrix(v[:3], v[3:]) for v in vals]
                  for f, (_, _, vals) in chain_plain.items()}
    tree_mats = {f: [pose_to_matrix(v[:3], v[3:]) for v in vals]
                 for f, (_, _, vals) in tree_plain.items()}
    rows: List[Tuple[str, float, float]] = []  # (what, ours us, naive us)
    cases = [
        ("chain 20 links, latest", lambda: chain_buf.lookup("c0", "c20"),
         lambda: naive_lookup(chain_plain, "c0", "c20", latest)),
        ("branchy leaf-leaf, latest", lambda: tree_buf.lookup("b20", "b15"),
         lambda: naive_lookup(tree_plain, "b20", "b15", latest)),
        ("chain, vs numpy 4x4 premade", lambda: chain_buf.lookup("c0", "c20"),
         lambda: naive_lookup(chain_plain, "c0", "c20", latest, chain_mats)),
        ("branchy, vs numpy 4x4 premade", lambda: tree_buf.lookup("b20", "b15"),
         lambda: naive_lookup(tree_plain, "b20", "b15", latest, tree_mats)),
        ("chain 20 links, interpolated", lambda: chain_buf.lookup("c0", "c20", mid), None),
        ("branchy leaf-leaf, interpolated", lambda: tree_buf.lookup("b20", "b15", mid), None),
    ]
    for name, ours, naive in cases:
        rows.append((name, best_us(ours, number, repeat),
                     best_us(naive, number // 4, repeat) if naive else math.nan))

    # tiny-op math: tuples vs numpy arrays for one composition
    ta: Tf7 = (0.1, 0.2, 0.3, *quat((1, 2, 3), 0.4))  # type: ignore[assignment]
    tb: Tf7 = (0.3, -0.1, 0.2, *quat((3, 1, 0), 1.1))  # type: ignore[assignment]
    ma, mb = pose_to_matrix(ta[:3], ta[3:]), pose_to_matrix(tb[:3], tb[3:])
    na, nb = (ma[:3, :3].copy(), ma[:3, 3] / 1000.0), (mb[:3, :3].copy(), mb[:3, 3] / 1000.0)
    np.testing.assert_allclose(numpy_compose(na, nb)[1], compose(ta, tb)[:3], atol=1e-12)
    math_tuple = best_us(lambda: compose(ta, tb), number * 10, repeat)
    math_numpy = best_us(lambda: numpy_compose(na, nb), number, repeat)
    math_matrix = best_us(lambda: pose_to_matrix(ta[:3], ta[3:]) @ pose_to_matrix(tb[:3], tb[3:]),
                          number, repeat)

    # set_transforms: one 7-link robot update per call (new stamps each call)
    robot = {f"link{i}": ("base" if i == 1 else f"link{i - 1}") for i in range(1, 8)}
    batches = []
    for k in range(number * repeat + 10):
        batches.append([StampedTransform(p, c, (k + 1) * STEP, (0.1, 0.0, 0.2),
                                         quat((0, 0, 1), 0.001 * k))
                        for c, p in robot.items()])
    robot_buf = TfBuffer()
    it = iter(batches)
    set_us = best_us(lambda: robot_buf.set_transforms(next(it), static=False), number, repeat)
    make_us = best_us(lambda: [StampedTransform(p, c, 1, (0.1, 0.0, 0.2), (0.0, 0.0, 0.0, 1.0))
                               for c, p in robot.items()], number, repeat)

    # registry: 10 lookups on the robot, one 7-link update each call
    reg_buf = TfBuffer()
    reg = LookupRegistry(reg_buf)
    for i in range(1, 8):
        reg.add("base", f"link{i}")
    reg.add("link2", "link7")
    reg.add("link7", "link1")
    reg.add("base", "missing")  # pending: costs nothing per update
    reg_it = iter(batches)
    now = [0]

    def update() -> int:
        now[0] += STEP
        return len(reg.updates(reg_buf.set_transforms(next(reg_it), static=False), now[0]))

    update()
    reg_us = best_us(update, number // 4, repeat)
    assert update() == 9  # every lookup moved: 9 results delivered per update

    print(f"tf buffer benchmark ({'quick' if args.quick else 'full'}; best of {repeat};"
          f" {SAMPLES} samples per frame)")
    print("chain: c0 <- c1 <- ... <- c20, lookup c0<-c20 (20 links); branchy: binary tree of 20"
          " frames, lookup b20<-b15 (6 links, via b1, root b0)")
    print(f"{'case':38s} {'ours us':>9s} {'lookups/s':>10s} {'naive us':>9s} {'naive/ours':>10s}")
    for name, ours_us, naive_us in rows:
        ratio = f"{naive_us / ours_us:10.1f}" if not math.isnan(naive_us) else f"{'-':>10s}"
        naive_txt = f"{naive_us:9.1f}" if not math.isnan(naive_us) else f"{'-':>9s}"
        print(f"{name:38s} {ours_us:9.1f} {1e6 / ours_us:10.0f} {naive_txt} {ratio}")
    print(f"{'compose one link: tuples':38s} {math_tuple:9.2f}")
    print(f"{'compose one link: numpy R@R, R@t+t':38s} {math_numpy:9.2f} "
          f"{'':10s} {'':9s} {math_numpy / math_tuple:10.1f}")
    print(f"{'compose one link: 4x4 pose_to_matrix @':38s} {math_matrix:9.2f} "
          f"{'':10s} {'':9s} {math_matrix / math_tuple:10.1f}")
    print(f"{'set_transforms, 7-link robot update':38s} {set_us:9.1f} "
          f"{1e6 / set_us:10.0f} (updates/s)")
    print(f"{'  (building the 7 StampedTransforms)':38s} {make_us:9.1f}")
    print(f"{'set_transforms + registry.updates (10)':38s} {reg_us:9.1f} "
          f"{1e6 / reg_us:10.0f} (updates/s)")
    per_message(robot, number, repeat)


def _feeder(buf: TfBuffer, messages: List[bytes]) -> Callable[[], set[str]]:
    """Stores the next message on each call, as the daemon does; returns the changed frames."""
    from bridge.tf.capability import tf_cdr_to_transforms

    it = iter(messages)

    def store() -> set[str]:
        data = next(it)
        changed = buf.set_transforms_cdr(data, static=False)
        if changed is None:  # the pure Python store: read here, as the daemon does
            changed = buf.set_transforms(tf_cdr_to_transforms(data), static=False)
        return changed
    return store


def _store_costs(messages: List[bytes], compiled: bool, number: int) -> Tuple[float, float]:
    """(read+store, read+store+evaluate) in us per message, on fresh buffers."""
    store_us = best_us(_feeder(TfBuffer(compiled=compiled), messages), number, 3)
    buf = TfBuffer(compiled=compiled)
    reg = LookupRegistry(buf)
    for i in range(1, 8):
        reg.add("base", f"link{i}")
    store = _feeder(buf, messages)
    now = [0]

    def update() -> int:
        now[0] += STEP
        return len(reg.updates(store(), now[0]))

    assert update() == 7  # every lookup moved: 7 results per message
    return store_us, best_us(update, number, 3)


def per_message(robot: Dict[str, str], number: int, repeat: int) -> None:
    """The daemon's tf work per /tf message (CDR in, 7 lookup results out) on each store."""
    from geometry_msgs.msg import TransformStamped
    from rclpy.serialization import serialize_message
    from tf2_msgs.msg import TFMessage

    from bridge.tf import buffer as buffer_module

    messages = []
    for k in range(number * repeat + 10):
        msg = TFMessage()
        for child, parent in robot.items():
            ts = TransformStamped()
            ts.header.stamp.sec, ts.header.stamp.nanosec = divmod((k + 1) * STEP, S)
            ts.header.frame_id, ts.child_frame_id = parent, child
            ts.transform.translation.x = 0.1
            (ts.transform.rotation.x, ts.transform.rotation.y, ts.transform.rotation.z,
             ts.transform.rotation.w) = quat((0, 0, 1), 0.001 * k)
            msg.transforms.append(ts)
        messages.append(serialize_message(msg))
    stores = [("pure Python", False)]
    if buffer_module.CompiledFrameStore is not None:
        stores.insert(0, ("compiled", True))
    print("per /tf message of the 7-link robot, CDR in -> 7 lookup results out (us):")
    for name, compiled in stores:
        store_us, update_us = _store_costs(messages, compiled, number // 2)
        print(f"  {name + ' store':36s} read+store {store_us:6.1f}   "
              f"read+store+evaluate {update_us:6.1f}")


if __name__ == "__main__":
    main()
