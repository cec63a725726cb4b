"""ROS <-> Slicer conventions: the one place where units, rotations and time stamps change.

Convention (the same as the reference SlicerROS2):

* Axes are unchanged: Slicer's RAS frame maps directly onto the ROS frame (x, y, z
  are copied as they are; no RAS/LPS flip happens here).
* Lengths are millimetres on the Slicer side and metres on the ROS side. Every length in
  the project (poses, transforms, tf, URDF offsets, points, point clouds, mesh vertices)
  crosses through `metres_to_mm` / `mm_to_metres` or the pose/matrix helpers below.
* Quaternions are ordered (x, y, z, w) as in ``geometry_msgs/Quaternion``; the canonical
  form returned here has ``w >= 0``.
* OpenIGTLink time stamps are unsigned 64-bit fixed point: the high 32 bits are seconds
  since 1970-01-01 UTC, the low 32 bits the fraction in units of 2**-32 s. ROS times are
  ``(sec, nanosec)``. Conversions are exact to within 1 ns both ways.

Pure Python 3.9+ and numpy; no I/O, no ROS import.
"""

from __future__ import annotations

import math
import time
from typing import Union

import numpy as np
import numpy.typing as npt

from protocol.errors import ProtocolError

__all__ = [
    "FLOAT32_BOUND",
    "MM_PER_M",
    "ConversionError",
    "fit_float32_mm",
    "float32_metres_to_mm",
    "fits_float32",
    "igtl12_to_matrix",
    "igtl_timestamp_from_ros",
    "igtl_timestamp_from_seconds",
    "igtl_timestamp_now",
    "igtl_timestamp_to_seconds",
    "matrix_to_igtl12",
    "matrix_to_pose",
    "metres_to_mm",
    "mm_to_metres",
    "pose_to_igtl12",
    "pose_to_matrix",
    "quaternion_to_rotation",
    "ros_time_from_igtl",
    "rotation_to_quaternion",
    "validate_matrix",
    "validate_rotation",
]

MM_PER_M = 1000.0

# Tolerance on R @ R.T - I. Matrices travel as float32 on the wire (~1e-7 relative), and
# Slicer users type rotations by hand to three decimals (0.707, 0.866: the reference's own
# tests do, up to 2e-3 off), so this accepts honest rounding yet refuses shear and scale.
ORTHONORMAL_TOLERANCE = 2e-3

# Every magnitude below this rounds to a finite float32 (what a TRANSFORM, a POINT or a
# POLYDATA carries); from it on, to infinity: FLT_MAX plus half its last unit (2**103) is
# a tie, which rounds to the even neighbour, infinity.
FLOAT32_BOUND = 2.0**128 - 2.0**103

_NS_PER_S = 1_000_000_000
_FRAC_PER_S = 1 << 32
_U32_MAX = (1 << 32) - 1
_U64_MAX = (1 << 64) - 1

ArrayLike = npt.ArrayLike
FloatArray = npt.NDArray[np.float64]
Scalar = Union[float, int]


class ConversionError(ProtocolError):
    """A value cannot be converted between ROS and Slicer conventions.

    Carries ``field`` (what was being converted), ``expected`` and ``got``, like every
    `ProtocolError`.
    """


def _fail(field: str, expected: str, got: object) -> ConversionError:
    return ConversionError(field=field, expected=expected, got=got)


# ---------------------------------------------------------------------------- lengths


def fits_float32(*values: float) -> bool:
    """The one rule for a number sent as float32: finite once cast (NaN and infinity fail,
    and so does a finite double too large for float32, 1e36 m once in mm). Every path that
    sends lengths in mm asks it after converting (the native lane takes its bound)."""
    for v in values:
        if not -FLOAT32_BOUND < v < FLOAT32_BOUND:  # False for NaN as well
            return False
    return True


def fit_float32_mm(lengths_m: ArrayLike) -> npt.NDArray[np.bool_]:
    """`fits_float32` of each length (metres) once in mm, element by element: the rule for
    arrays of points (clouds, meshes, marker models)."""
    with np.errstate(over="ignore", invalid="ignore"):
        mm = np.asarray(lengths_m, dtype=np.float64) * MM_PER_M
        return np.asarray(np.abs(mm) < FLOAT32_BOUND)



def float32_metres_to_mm(x: ArrayLike, out: npt.NDArray[np.float32] | None = None
                         ) -> npt.NDArray[np.float32]:
    """float32 metres to float32 millimetres in one float32 multiply, for clouds of a
    million points: the same numbers as ``metres_to_mm(x).astype(np.float32)`` (a float32
    times 1000 is exact in float64, so both round once, to the nearest float32), and
    infinite exactly where `fit_float32_mm` is False (NaN stays NaN). ``x`` holds float32
    values (any byte order; a float64 array raises TypeError rather than being rounded
    first); written into ``out`` if given."""
    with np.errstate(over="ignore", invalid="ignore"):
        result: npt.NDArray[np.float32] = np.multiply(x, np.float32(MM_PER_M), out=out,
                                                      dtype=np.float32, casting="safe")
    return result


def metres_to_mm(x: ArrayLike) -> FloatArray:
    """Metres (ROS) to millimetres (Slicer); scalars give a 0-d array, arrays keep their shape."""
    return np.asarray(x, dtype=np.float64) * MM_PER_M


def mm_to_metres(x: ArrayLike) -> FloatArray:
    """Millimetres (Slicer) to metres (ROS); scalars give a 0-d array, arrays keep their shape."""
    return np.asarray(x, dtype=np.float64) / MM_PER_M


# ---------------------------------------------------------------------------- rotations


def _as_float_array(value: ArrayLike, field: str, expected: str) -> FloatArray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise _fail(field, expected, f"{type(value).__name__} ({exc})") from None
    return arr


def quaternion_to_rotation(q_xyzw: ArrayLike) -> FloatArray:
    """Unit rotation matrix from a quaternion (x, y, z, w).

    Accepts shape (4,) -> (3, 3) or (N, 4) -> (N, 3, 3). The quaternion is normalised
    first (ROS messages often carry slightly denormalised ones); a zero or non-finite
    quaternion raises `ConversionError`.
    """
    q = _as_float_array(q_xyzw, "quaternion", "4 numbers x, y, z, w")
    if q.ndim not in (1, 2) or q.shape[-1] != 4:
        raise _fail("quaternion", "shape (4,) or (N, 4)", f"shape {q.shape}")
    if not np.all(np.isfinite(q)):
        raise _fail("quaternion", "finite numbers", "NaN or infinity")
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm < 1e-12):
        raise _fail("quaternion", "a non-zero quaternion", "norm 0")
    x, y, z, w = np.moveaxis(q / norm, -1, 0)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    rot = np.stack(
        [
            np.stack([1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)], axis=-1),
            np.stack([2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx)], axis=-1),
            np.stack([2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)], axis=-1),
        ],
        axis=-2,
    )
    return np.asarray(rot, dtype=np.float64)


def rotation_to_quaternion(rotation: ArrayLike) -> FloatArray:
    """Quaternion (x, y, z, w), unit norm, w >= 0, from a rotation matrix.

    Accepts (3, 3) -> (4,) or (N, 3, 3) -> (N, 4); a 4x4 (or N x 4x4) homogeneous matrix is
    also accepted and its rotation part used. Shepperd's method: the largest of the four
    candidate divisors is used, so no branch divides by a small number.
    """
    r = _as_float_array(rotation, "rotation", "a 3x3 rotation matrix")
    if r.ndim not in (2, 3) or r.shape[-2:] not in ((3, 3), (4, 4)):
        raise _fail("rotation", "shape (3, 3), (4, 4) or (N, 3, 3)", f"shape {r.shape}")
    if not np.all(np.isfinite(r)):
        raise _fail("rotation", "finite numbers", "NaN or infinity")
    single = r.ndim == 2
    m = r[None, :3, :3] if single else r[:, :3, :3]
    m00, m01, m02 = m[:, 0, 0], m[:, 0, 1], m[:, 0, 2]
    m10, m11, m12 = m[:, 1, 0], m[:, 1, 1], m[:, 1, 2]
    m20, m21, m22 = m[:, 2, 0], m[:, 2, 1], m[:, 2, 2]
    trace = m00 + m11 + m22
    # Four candidates, each 4*component**2; pick the largest per matrix.
    cand = np.stack(
        [1 + 2 * m00 - trace, 1 + 2 * m11 - trace, 1 + 2 * m22 - trace, 1 + trace], axis=-1
    )
    choice = np.argmax(cand, axis=-1)
    q = np.empty((m.shape[0], 4), dtype=np.float64)
    for k in range(4):
        sel = choice == k
        if not np.any(sel):
            continue
        s = np.sqrt(np.maximum(cand[sel, k], 1e-300))  # = 2 * |component k|
        _a00, a01, a02 = m00[sel], m01[sel], m02[sel]
        a10, _a11, a12 = m10[sel], m11[sel], m12[sel]
        a20, a21, _a22 = m20[sel], m21[sel], m22[sel]
        if k == 0:
            cols = (s / 2, (a01 + a10) / (2 * s), (a02 + a20) / (2 * s), (a21 - a12) / (2 * s))
        elif k == 1:
            cols = ((a01 + a10) / (2 * s), s / 2, (a12 + a21) / (2 * s), (a02 - a20) / (2 * s))
        elif k == 2:
            cols = ((a02 + a20) / (2 * s), (a12 + a21) / (2 * s), s / 2, (a10 - a01) / (2 * s))
        else:
            cols = ((a21 - a12) / (2 * s), (a02 - a20) / (2 * s), (a10 - a01) / (2 * s), s / 2)
        q[sel] = np.stack(cols, axis=-1)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q[q[:, 3] < 0] *= -1.0
    return q[0] if single else q


# ---------------------------------------------------------------------------- poses


def pose_to_matrix(translation_m: ArrayLike, quaternion_xyzw: ArrayLike) -> FloatArray:
    """ROS pose (translation in metres, quaternion x, y, z, w) -> 4x4 float64 matrix in mm.

    This runs once per ROS message on the hot path, so a single pose is computed with plain
    floats (numpy's per-call overhead is most of the cost for seven numbers); anything that
    is not three and four finite numbers goes through the checking path below.
    """
    try:
        tx, ty, tz = (float(v) for v in translation_m)  # type: ignore[union-attr,arg-type]
        x, y, z, w = (float(v) for v in quaternion_xyzw)  # type: ignore[union-attr,arg-type]
    except (TypeError, ValueError):
        return _pose_to_matrix_checked(translation_m, quaternion_xyzw)
    v = pose_to_igtl12(tx, ty, tz, x, y, z, w)
    if v is None:
        return _pose_to_matrix_checked(translation_m, quaternion_xyzw)
    return np.array([[v[0], v[3], v[6], v[9]], [v[1], v[4], v[7], v[10]],
                     [v[2], v[5], v[8], v[11]], [0.0, 0.0, 0.0, 1.0]], dtype=np.float64)


def pose_to_igtl12(tx: float, ty: float, tz: float, x: float, y: float, z: float,
                   w: float) -> tuple[float, ...] | None:
    """ROS pose (metres, quaternion x, y, z, w) as plain floats -> the 12 numbers of an
    OpenIGTLink TRANSFORM in wire order (R11 R21 R31 R12 R22 R32 R13 R23 R33, then the
    translation in mm), or None if a number is not finite, the quaternion is zero, or the
    translation in mm does not fit float32 (`fits_float32`; the caller then takes the
    checked path, which says what is wrong).

    The one quaternion -> matrix formula for single poses: `pose_to_matrix` uses it too.
    """
    norm2 = x * x + y * y + z * z + w * w
    mx, my, mz = tx * MM_PER_M, ty * MM_PER_M, tz * MM_PER_M
    # The rotation's nine numbers lie in [-1, 3] once norm2 is finite and not tiny.
    if not (fits_float32(mx, my, mz) and math.isfinite(norm2)) or norm2 < 1e-24:
        return None
    s = 2.0 / norm2  # normalises the quaternion on the way
    xx, yy, zz = x * x * s, y * y * s, z * z * s
    xy, xz, yz = x * y * s, x * z * s, y * z * s
    wx, wy, wz = w * x * s, w * y * s, w * z * s
    return (1.0 - (yy + zz), xy + wz, xz - wy,
            xy - wz, 1.0 - (xx + zz), yz + wx,
            xz + wy, yz - wx, 1.0 - (xx + yy),
            mx, my, mz)


def _pose_to_matrix_checked(translation_m: ArrayLike, quaternion_xyzw: ArrayLike) -> FloatArray:
    t = _as_float_array(translation_m, "translation", "3 numbers x, y, z in metres")
    if t.shape != (3,):
        raise _fail("translation", "shape (3,)", f"shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise _fail("translation", "finite numbers", "NaN or infinity")
    q = _as_float_array(quaternion_xyzw, "quaternion", "4 numbers x, y, z, w")
    if q.shape != (4,):
        raise _fail("quaternion", "shape (4,)", f"shape {q.shape}")
    mm = [v * MM_PER_M for v in t.tolist()]  # as pose_to_igtl12 (and no numpy overflow warning)
    if not fits_float32(*mm):
        raise _fail("translation", f"within float32 once in mm (|x| < {FLOAT32_BOUND:.4g} mm)",
                    f"{t.tolist()} m")
    matrix = np.eye(4, dtype=np.float64)
    matrix[:3, :3] = quaternion_to_rotation(q)
    matrix[:3, 3] = mm
    return matrix


def matrix_to_pose(matrix_mm: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """4x4 matrix in mm -> (translation in metres (3,), quaternion x, y, z, w (4,)).

    The matrix is validated first (`validate_matrix`), so a sheared or scaled matrix is
    refused rather than silently turned into a wrong rotation.
    """
    m = validate_matrix(matrix_mm)
    return mm_to_metres(m[:3, 3]), rotation_to_quaternion(m[:3, :3])


# ---------------------------------------------------------------------------- OpenIGTLink


def matrix_to_igtl12(matrix_mm: ArrayLike) -> npt.NDArray[np.float32]:
    """4x4 matrix (mm) -> the 12 float32 of an OpenIGTLink TRANSFORM body.

    Order (column-major rotation, then translation): R11 R21 R31 R12 R22 R32 R13 R23 R33
    TX TY TZ. Only shape and `fits_float32` are checked: TRANSFORM may carry scaling.
    """
    m = _as_float_array(matrix_mm, "matrix", "a 4x4 matrix")
    if m.shape != (4, 4):
        raise _fail("matrix", "shape (4, 4)", f"shape {m.shape}")
    wire = np.concatenate([m[:3, :3].T.reshape(9), m[:3, 3]])  # transposed: columns first
    if not fits_float32(*wire.tolist()):
        raise _fail("matrix", "finite numbers within float32", repr(wire.tolist()))
    return wire.astype(np.float32)


def igtl12_to_matrix(values: ArrayLike) -> FloatArray:
    """The 12 numbers of an OpenIGTLink TRANSFORM body -> 4x4 float64 matrix (mm)."""
    v = _as_float_array(values, "transform", "12 numbers")
    if v.shape != (12,):
        raise _fail("transform", "12 numbers", f"shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise _fail("transform", "finite numbers", "NaN or infinity")
    m = np.eye(4, dtype=np.float64)
    m[:3, :3] = v[:9].reshape(3, 3).T
    m[:3, 3] = v[9:]
    return m


# ---------------------------------------------------------------------------- validation


def validate_rotation(
    rotation: ArrayLike, *, field: str = "rotation", tolerance: float = ORTHONORMAL_TOLERANCE
) -> FloatArray:
    """Return the 3x3 rotation as float64, or raise `ConversionError` if it is not a proper
    rotation (orthonormal within ``tolerance``, determinant +1)."""
    r = _as_float_array(rotation, field, "a 3x3 rotation matrix")
    if r.shape != (3, 3):
        raise _fail(field, "shape (3, 3)", f"shape {r.shape}")
    if not np.all(np.isfinite(r)):
        raise _fail(field, "finite numbers", "NaN or infinity")
    err = float(np.max(np.abs(r @ r.T - np.eye(3))))
    if err > tolerance:
        raise _fail(field, f"an orthonormal rotation (|R R^T - I| <= {tolerance:g})",
                    f"deviation {err:.3g}")
    det = float(np.linalg.det(r))
    if det < 0:
        raise _fail(field, "a proper rotation (determinant +1)", f"determinant {det:.3g}")
    return r


def validate_matrix(
    m: ArrayLike, *, field: str = "matrix", tolerance: float = ORTHONORMAL_TOLERANCE
) -> FloatArray:
    """Return ``m`` as a 4x4 float64 rigid transform, or raise `ConversionError`.

    Refused: shape other than 4x4, NaN/infinity, last row not ``0 0 0 1``, rotation part
    not orthonormal within ``tolerance`` or a reflection. ``field`` names the value in the
    error (for example ``"matrix"`` of a tf broadcast command).
    """
    arr = _as_float_array(m, field, "a 4x4 matrix of numbers")
    if arr.shape != (4, 4):
        raise _fail(field, "shape (4, 4)", f"shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise _fail(field, "finite numbers", "NaN or infinity")
    if not np.allclose(arr[3], (0.0, 0.0, 0.0, 1.0), rtol=0.0, atol=1e-9):
        raise _fail(f"{field}[3]", "last row 0 0 0 1", f"{arr[3].tolist()}")
    validate_rotation(arr[:3, :3], field=f"{field} rotation", tolerance=tolerance)
    return arr


# ---------------------------------------------------------------------------- time stamps


def _check_int(value: object, field: str, low: int, high: int) -> int:
    # bool is an int subclass but never a meaningful time.
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise _fail(field, f"an integer in [{low}, {high}]", f"{type(value).__name__} {value!r}")
    iv = int(value)
    if not low <= iv <= high:
        raise _fail(field, f"an integer in [{low}, {high}]", str(iv))
    return iv


def igtl_timestamp_from_ros(sec: int, nanosec: int) -> int:
    """ROS time (sec, nanosec) -> OpenIGTLink u64 time stamp, fraction rounded to nearest.

    ``sec`` must fit 32 unsigned bits (until 2106); nanosec must be in [0, 999999999].
    """
    return _igtl_timestamp(_check_int(sec, "sec", 0, _U32_MAX),
                           _check_int(nanosec, "nanosec", 0, _NS_PER_S - 1))


def _igtl_timestamp(sec: int, nanosec: int) -> int:
    # Checked by the caller. Largest ns gives 4294967291.7: never rounds up to a second.
    return (sec << 32) | ((nanosec * _FRAC_PER_S + _NS_PER_S // 2) // _NS_PER_S)


def ros_time_from_igtl(ts: int) -> tuple[int, int]:
    """OpenIGTLink u64 time stamp -> ROS time (sec, nanosec), rounded to the nearest ns."""
    t = _check_int(ts, "timestamp", 0, _U64_MAX)
    sec, frac = t >> 32, t & _U32_MAX
    ns = (frac * _NS_PER_S + _FRAC_PER_S // 2) >> 32
    if ns == _NS_PER_S:  # fraction within half a ns of the next second
        sec, ns = sec + 1, 0
    return sec, ns


def igtl_timestamp_now() -> int:
    """The current wall-clock time as an OpenIGTLink time stamp."""
    total = time.time_ns()
    return igtl_timestamp_from_ros(total // _NS_PER_S, total % _NS_PER_S)


def igtl_stamp_or_now(sec: int, nanosec: int) -> int:
    """The one rule for a ROS header stamp -> OpenIGTLink time stamp, on every path: a
    stamp that is unset (0) or that OpenIGTLink cannot hold (negative, a second beyond
    2106, a nanosecond field of a second or more: legal in a uint32) becomes the current
    time, never an error."""
    if isinstance(sec, bool) or isinstance(nanosec, bool) or not isinstance(sec, int) \
            or not isinstance(nanosec, int):
        return igtl_timestamp_now()
    if 0 < sec <= _U32_MAX and 0 <= nanosec < _NS_PER_S:
        return _igtl_timestamp(sec, nanosec)  # checked just above (a hot path's call)
    return igtl_timestamp_now()


def igtl_timestamp_to_seconds(ts: int) -> float:
    """OpenIGTLink time stamp -> float seconds since 1970 (for display and rate maths)."""
    t = _check_int(ts, "timestamp", 0, _U64_MAX)
    return (t >> 32) + (t & _U32_MAX) / _FRAC_PER_S


def igtl_timestamp_from_seconds(seconds: float) -> int:
    """Float seconds since 1970 -> OpenIGTLink time stamp (rounded to nearest 2**-32 s)."""
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float, np.floating, np.integer)):
        raise _fail("seconds", "a number of seconds", type(seconds).__name__)
    value = float(seconds)
    if not (np.isfinite(value) and 0.0 <= value < float(1 << 32)):
        raise _fail("seconds", "a finite number in [0, 2**32)", repr(value))
    whole = int(value)
    frac = round((value - whole) * _FRAC_PER_S)
    if frac >= _FRAC_PER_S:
        whole, frac = whole + 1, 0
    return (whole << 32) | frac
