"""Rigid-transform algebra on plain float tuples: the tf-math the buffer needs.

Why this module exists next to `protocol.conversions`: conversions.py is the one place where
*units and conventions* change (metres <-> mm, quaternion <-> matrix, IGTL order, time). It
has no quaternion product, inverse or slerp, because nothing crossing the wire needs them.
The tf buffer composes chains of links many thousands of times a second, so it needs that
algebra, and it needs it fast.

Why tuples of floats and not numpy: every value here is a 3-vector or a quaternion, and a
numpy call's fixed overhead, whatever the size, is more than the whole quaternion product
in plain floats. bench/bench_tf.py measures both
(``compose``: tuples vs the same formulas on numpy arrays) and the tuples win by several
times. Batch work (many transforms at once) would favour numpy; the buffer never has that.

Conventions (the same as ROS and conversions.py): a transform is ``(tx, ty, tz, qx, qy, qz,
qw)`` in metres, the quaternion (x, y, z, w), Hamilton product. ``compose(a, b)`` is the
transform "a after b": it maps a point p to a(b(p)); with a = parent<-middle and b =
middle<-child, it is parent<-child.
"""

from __future__ import annotations

import math
from typing import Tuple

__all__ = [
    "Vec3",
    "Quat",
    "Tf7",
    "IDENTITY",
    "quat_multiply",
    "quat_conjugate",
    "quat_normalize",
    "quat_rotate",
    "quat_slerp",
    "quat_angle",
    "compose",
    "invert",
    "interpolate",
    "transform_point",
]

Vec3 = Tuple[float, float, float]
Quat = Tuple[float, float, float, float]
# (tx, ty, tz, qx, qy, qz, qw): one flat tuple is cheaper to build and unpack than two.
Tf7 = Tuple[float, float, float, float, float, float, float]

IDENTITY: Tf7 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)

# Below this angle between two quaternions slerp falls back to a normalised lerp: sin(theta)
# in the denominator loses precision, and the two agree to ~1e-12 there.
_SLERP_LINEAR_DOT = 0.9999995


def quat_multiply(a: Quat, b: Quat) -> Quat:
    """Hamilton product a * b (rotate by b first, then by a)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def quat_conjugate(q: Quat) -> Quat:
    """The inverse rotation of a unit quaternion."""
    return (-q[0], -q[1], -q[2], q[3])


def quat_normalize(q: Quat) -> Quat:
    """Unit quaternion with the same direction; a zero quaternion raises ValueError."""
    x, y, z, w = q
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not n > 0.0:  # also catches NaN
        raise ValueError(f"quaternion: expected a non-zero norm, got {n!r}")
    return (x / n, y / n, z / n, w / n)


def quat_rotate(q: Quat, v: Vec3) -> Vec3:
    """Rotate v by the unit quaternion q: v + 2w(u x v) + 2u x (u x v), u = q.xyz."""
    qx, qy, qz, qw = q
    vx, vy, vz = v
    # c = 2 (u x v)
    cx = 2.0 * (qy * vz - qz * vy)
    cy = 2.0 * (qz * vx - qx * vz)
    cz = 2.0 * (qx * vy - qy * vx)
    return (
        vx + qw * cx + qy * cz - qz * cy,
        vy + qw * cy + qz * cx - qx * cz,
        vz + qw * cz + qx * cy - qy * cx,
    )


def quat_slerp(a: Quat, b: Quat, ratio: float) -> Quat:
    """Spherical interpolation from a (ratio 0) to b (ratio 1) along the shorter arc.

    q and -q are the same rotation; like tf2, the shorter of the two arcs is taken.
    """
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    dot = ax * bx + ay * by + az * bz + aw * bw
    if dot < 0.0:
        bx, by, bz, bw, dot = -bx, -by, -bz, -bw, -dot
    if dot > _SLERP_LINEAR_DOT:
        wa, wb = 1.0 - ratio, ratio
    else:
        theta = math.acos(dot)
        s = math.sin(theta)
        wa = math.sin((1.0 - ratio) * theta) / s
        wb = math.sin(ratio * theta) / s
    x = wa * ax + wb * bx
    y = wa * ay + wb * by
    z = wa * az + wb * bz
    w = wa * aw + wb * bw
    n = math.sqrt(x * x + y * y + z * z + w * w)
    return (x / n, y / n, z / n, w / n)


def quat_angle(a: Quat, b: Quat) -> float:
    """Angle in radians of the rotation taking a to b (0 .. pi), for tolerance checks."""
    # atan2 of the relative rotation's half-angle sine and cosine stays accurate for tiny
    # angles, where acos(a . b) loses about half the digits.
    rx, ry, rz, rw = quat_multiply(quat_conjugate(a), b)
    return 2.0 * math.atan2(math.sqrt(rx * rx + ry * ry + rz * rz), abs(rw))


def compose(a: Tf7, b: Tf7) -> Tf7:
    """a after b: maps p to a(b(p)). With a = parent<-mid and b = mid<-child: parent<-child."""
    atx, aty, atz, qx, qy, qz, qw = a
    btx, bty, btz, bx, by, bz, bw = b
    cx = 2.0 * (qy * btz - qz * bty)
    cy = 2.0 * (qz * btx - qx * btz)
    cz = 2.0 * (qx * bty - qy * btx)
    return (
        atx + btx + qw * cx + qy * cz - qz * cy,
        aty + bty + qw * cy + qz * cx - qx * cz,
        atz + btz + qw * cz + qx * cy - qy * cx,
        qw * bx + qx * bw + qy * bz - qz * by,
        qw * by - qx * bz + qy * bw + qz * bx,
        qw * bz + qx * by - qy * bx + qz * bw,
        qw * bw - qx * bx - qy * by - qz * bz,
    )


def invert(a: Tf7) -> Tf7:
    """The inverse transform: child<-parent from parent<-child."""
    tx, ty, tz, qx, qy, qz, qw = a
    # t' = -(q^-1 v q) for the conjugate quaternion.
    ix, iy, iz = quat_rotate((-qx, -qy, -qz, qw), (-tx, -ty, -tz))
    return (ix, iy, iz, -qx, -qy, -qz, qw)


def interpolate(a: Tf7, b: Tf7, ratio: float) -> Tf7:
    """Linear interpolation of the translation and slerp of the rotation (tf2's rule)."""
    r0 = 1.0 - ratio
    qx, qy, qz, qw = quat_slerp(a[3:], b[3:], ratio)
    return (
        r0 * a[0] + ratio * b[0],
        r0 * a[1] + ratio * b[1],
        r0 * a[2] + ratio * b[2],
        qx, qy, qz, qw,
    )


def transform_point(a: Tf7, p: Vec3) -> Vec3:
    """Apply the transform a to the point p (metres)."""
    x, y, z = quat_rotate((a[3], a[4], a[5], a[6]), p)
    return (x + a[0], y + a[1], z + a[2])
