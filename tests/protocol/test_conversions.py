"""Units, rotations, the OpenIGTLink TRANSFORM order and time stamps (protocol/conversions.py)."""

from __future__ import annotations

import math
import time
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.conversions import (
    FLOAT32_BOUND,
    MM_PER_M,
    ConversionError,
    fit_float32_mm,
    fits_float32,
    float32_metres_to_mm,
    igtl12_to_matrix,
    igtl_timestamp_from_ros,
    igtl_timestamp_from_seconds,
    igtl_timestamp_now,
    igtl_timestamp_to_seconds,
    matrix_to_igtl12,
    matrix_to_pose,
    metres_to_mm,
    mm_to_metres,
    pose_to_igtl12,
    pose_to_matrix,
    quaternion_to_rotation,
    ros_time_from_igtl,
    rotation_to_quaternion,
    validate_matrix,
)
from protocol.errors import ProtocolError

H = math.sqrt(0.5)
RZ90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


# ---------------------------------------------------------------- lengths

def test_lengths_real_values() -> None:
    assert MM_PER_M == 1000.0
    assert float(metres_to_mm(0.0031415)) == pytest.approx(3.1415, abs=1e-12)
    assert float(mm_to_metres(3.1415)) == pytest.approx(0.0031415, abs=1e-15)
    pts = np.array([[0.001, 0.002, 0.003], [1.0, -2.0, 0.5]])
    np.testing.assert_allclose(metres_to_mm(pts), [[1, 2, 3], [1000, -2000, 500]])
    assert metres_to_mm(pts).shape == (2, 3)
    np.testing.assert_allclose(mm_to_metres(metres_to_mm(pts)), pts)


# ---------------------------------------------------------------- rotations

def test_quarter_turn_about_z() -> None:
    q = rotation_to_quaternion(RZ90)
    np.testing.assert_allclose(q, [0.0, 0.0, H, H], atol=1e-12)
    np.testing.assert_allclose(quaternion_to_rotation([0.0, 0.0, H, H]), RZ90, atol=1e-12)


def test_identity_and_denormalised_quaternion() -> None:
    np.testing.assert_allclose(quaternion_to_rotation([0, 0, 0, 1]), np.eye(3))
    # ROS messages often carry slightly off quaternions; they are normalised first.
    np.testing.assert_allclose(quaternion_to_rotation([0, 0, 2 * H, 2 * H]), RZ90, atol=1e-12)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_half_turns_take_the_stable_branches(axis: int) -> None:
    # trace = -1: the w branch would divide by ~0; Shepperd's choice avoids it.
    q = np.zeros(4)
    q[axis] = 1.0
    r = quaternion_to_rotation(q)
    back = rotation_to_quaternion(r)
    np.testing.assert_allclose(np.abs(back), np.abs(q), atol=1e-12)
    assert back[3] >= 0.0


def test_canonical_sign_w_non_negative() -> None:
    q = rotation_to_quaternion(quaternion_to_rotation([0.1, 0.2, 0.3, -0.9]))
    assert q[3] > 0
    np.testing.assert_allclose(np.linalg.norm(q), 1.0)


def test_batched_shapes() -> None:
    qs = np.array([[0, 0, 0, 1], [0, 0, H, H], [1, 0, 0, 0]], dtype=float)
    rs = quaternion_to_rotation(qs)
    assert rs.shape == (3, 3, 3)
    np.testing.assert_allclose(rs[1], RZ90, atol=1e-12)
    back = rotation_to_quaternion(rs)
    assert back.shape == (3, 4)
    np.testing.assert_allclose(back, qs, atol=1e-12)


def test_rotation_to_quaternion_accepts_homogeneous() -> None:
    m = np.eye(4)
    m[:3, :3] = RZ90
    np.testing.assert_allclose(rotation_to_quaternion(m), [0, 0, H, H], atol=1e-12)


unit_quaternions = st.lists(
    st.floats(-1.0, 1.0, allow_nan=False), min_size=4, max_size=4
).filter(lambda v: np.linalg.norm(v) > 1e-3)


@given(unit_quaternions)
def test_quaternion_matrix_round_trip(q: list[float]) -> None:
    q_arr = np.asarray(q) / np.linalg.norm(q)
    r = quaternion_to_rotation(q_arr)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    back = rotation_to_quaternion(r)
    # q and -q are the same rotation; canonical form has w >= 0.
    assert min(np.abs(back - q_arr).max(), np.abs(back + q_arr).max()) < 1e-9
    np.testing.assert_allclose(quaternion_to_rotation(back), r, atol=1e-12)


@given(unit_quaternions, st.lists(st.floats(-100.0, 100.0), min_size=3, max_size=3))
def test_pose_matrix_round_trip(q: list[float], t: list[float]) -> None:
    m = pose_to_matrix(t, q)
    np.testing.assert_allclose(m[:3, 3], np.asarray(t) * 1000.0)
    t_back, q_back = matrix_to_pose(m)
    np.testing.assert_allclose(t_back, t, atol=1e-9)
    np.testing.assert_allclose(quaternion_to_rotation(q_back), m[:3, :3], atol=1e-9)


def test_pose_to_matrix_real_values() -> None:
    m = pose_to_matrix([0.0031415, -0.5, 2.0], [0.0, 0.0, H, H])
    assert m.dtype == np.float64
    np.testing.assert_allclose(m[:3, 3], [3.1415, -500.0, 2000.0])
    np.testing.assert_allclose(m[:3, :3], RZ90, atol=1e-12)
    np.testing.assert_array_equal(m[3], [0, 0, 0, 1])
    t, q = matrix_to_pose(m)
    np.testing.assert_allclose(t, [0.0031415, -0.5, 2.0])
    np.testing.assert_allclose(q, [0, 0, H, H], atol=1e-12)


# ---------------------------------------------------------------- OpenIGTLink TRANSFORM

def test_igtl12_order_element_by_element() -> None:
    m = np.eye(4)
    for i in range(3):
        for j in range(4):
            m[i, j] = 10 * (i + 1) + (j + 1)  # R_ij = "ij"; TX = 14, TY = 24, TZ = 34
    out = matrix_to_igtl12(m)
    assert out.dtype == np.float32
    assert out.shape == (12,)
    expected = [11, 21, 31, 12, 22, 32, 13, 23, 33, 14, 24, 34]  # R11 R21 R31 R12 ... TZ
    for k, value in enumerate(expected):
        assert out[k] == value, k
    np.testing.assert_array_equal(igtl12_to_matrix(out), m)


def test_igtl12_of_a_real_pose() -> None:
    m = pose_to_matrix([0.0031415, 0.0, 0.0], [0.0, 0.0, H, H])
    out = matrix_to_igtl12(m)
    np.testing.assert_allclose(out[:3], [0, 1, 0], atol=1e-7)  # first column of Rz(90)
    np.testing.assert_allclose(out[3:6], [-1, 0, 0], atol=1e-7)
    np.testing.assert_allclose(out[9:], [3.1415, 0, 0], rtol=1e-7)


@pytest.mark.parametrize(
    ("values", "fld"),
    [(np.zeros(11), "transform"), ([float("nan")] * 12, "transform")],
)
def test_igtl12_to_matrix_refuses(values: object, fld: str) -> None:
    with pytest.raises(ConversionError) as info:
        igtl12_to_matrix(values)  # type: ignore[arg-type]
    assert info.value.field == fld


# ---------------------------------------------------------------- validation

def test_validate_matrix_accepts_rigid_and_float32_noise() -> None:
    m = pose_to_matrix([0.1, 0.2, 0.3], [0.1, 0.2, 0.3, 0.9])
    noisy = igtl12_to_matrix(matrix_to_igtl12(m))  # through float32
    np.testing.assert_allclose(validate_matrix(noisy), noisy)


@pytest.mark.parametrize(
    ("matrix", "fld", "word"),
    [
        (np.eye(3), "matrix", "shape"),
        (np.full((4, 4), np.nan), "matrix", "finite"),
        (np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [1, 0, 0, 1]]), "matrix[3]",
         "0 0 0 1"),
        (np.diag([2.0, 1.0, 1.0, 1.0]), "matrix rotation", "orthonormal"),
        (np.diag([-1.0, 1.0, 1.0, 1.0]), "matrix rotation", "determinant"),
        ([["a"] * 4] * 4, "matrix", "4x4"),
    ],
)
def test_validate_matrix_errors_name_field(matrix: object, fld: str, word: str) -> None:
    with pytest.raises(ConversionError) as info:
        validate_matrix(matrix)  # type: ignore[arg-type]
    err = info.value
    assert isinstance(err, ProtocolError)
    assert err.field == fld
    assert word in err.expected
    assert str(err).startswith(fld)


def test_validate_matrix_custom_field_name() -> None:
    with pytest.raises(ConversionError) as info:
        validate_matrix(np.zeros((4, 4)), field="request.matrix")
    assert info.value.field.startswith("request.matrix")


@pytest.mark.parametrize(
    ("q", "got"), [([0, 0, 0, 0], "norm 0"), ([0, 0, 1], "shape (3,)"), ([np.inf, 0, 0, 1], "NaN")]
)
def test_bad_quaternions(q: list[float], got: str) -> None:
    with pytest.raises(ConversionError) as info:
        quaternion_to_rotation(q)
    assert info.value.field == "quaternion"
    assert got in str(info.value.got)


def test_bad_pose_inputs() -> None:
    with pytest.raises(ConversionError) as info:
        pose_to_matrix([0, 0], [0, 0, 0, 1])
    assert info.value.field == "translation"
    with pytest.raises(ConversionError) as info:
        rotation_to_quaternion(np.zeros((2, 2)))
    assert info.value.field == "rotation"


# ---------------------------------------------------------------- float32 on the wire

BELOW = math.nextafter(FLOAT32_BOUND, 0.0)  # the largest double that is finite as float32


def test_fits_float32_is_what_a_float32_cast_makes_of_the_value() -> None:
    values = [0.0, -0.0, 5e-324, 1.0, float(np.finfo(np.float32).max), BELOW, -BELOW,
              FLOAT32_BOUND, -FLOAT32_BOUND, 1e39, 1e306, math.inf, -math.inf, math.nan]
    with np.errstate(over="ignore"):
        cast = [bool(np.isfinite(np.float32(v))) for v in values]
    assert [fits_float32(v) for v in values] == cast
    assert cast[:7] == [True] * 7 and cast[7:] == [False] * 7
    assert fits_float32() and fits_float32(1.0, 2.0, 3.0)
    assert not fits_float32(1.0, math.nan, 3.0) and not fits_float32(1.0, 2.0, 1e39)


def test_fit_float32_mm_is_fits_float32_of_each_length_in_mm() -> None:
    lengths = np.array([[0.0, 1.5, -2.0], [3.4e35, -3.4e35, 1e36], [math.nan, math.inf, 1e306]])
    want = [[fits_float32(v * MM_PER_M) for v in row] for row in lengths.tolist()]
    assert fit_float32_mm(lengths).tolist() == want == [[True] * 3, [True, True, False],
                                                        [False] * 3]


def _float32_mm_edges() -> np.ndarray:
    """float32 lengths (m) around the last one finite in mm, and the usual oddities."""
    top = np.float32(np.finfo(np.float32).max / MM_PER_M)
    around = [top]
    for toward in (np.float32(np.inf), np.float32(0.0)):
        x = top
        for _ in range(3):
            x = np.nextafter(x, toward)
            around.append(x)
    values = np.array(around + [0.0, -0.0, 1e-45, -1e-45, 1e-38, 0.001, 0.1, 1.5, 3.4e35,
                                1e36, 3.4e38, math.nan, math.inf, -math.inf], dtype=np.float32)
    return np.concatenate([values, -values])


def test_float32_metres_to_mm_is_metres_to_mm_rounded_once_and_infinite_where_it_does_not_fit(
        ) -> None:
    x = _float32_mm_edges()
    with np.errstate(over="ignore"):
        want = metres_to_mm(x).astype(np.float32)
    got = float32_metres_to_mm(x)
    assert got.dtype == np.float32
    assert got.tobytes() == want.tobytes()
    assert np.isfinite(got).tolist() == fit_float32_mm(x).tolist()
    # the last length finite in mm, the 3 float32 above it, the 3 below
    assert np.isfinite(got[:7]).tolist() == [True, False, False, False, True, True, True]
    out = np.zeros((x.size, 2), dtype=np.float32)
    float32_metres_to_mm(x.astype(">f4"), out=out[:, 1])  # a column; big-endian input
    assert out[:, 1].tobytes() == want.tobytes() and not out[:, 0].any()
    with pytest.raises(TypeError):
        float32_metres_to_mm(x.astype(np.float64))  # would be rounded to float32 first


@given(st.floats(width=32))
@settings(max_examples=300, deadline=None)
def test_float32_metres_to_mm_matches_the_float64_path(x_m: float) -> None:
    x = np.array([x_m], dtype=np.float32)
    with np.errstate(over="ignore"):
        want = metres_to_mm(x).astype(np.float32)
    assert float32_metres_to_mm(x).tobytes() == want.tobytes()


@pytest.mark.parametrize("x_m", [1e306, 1e36, -1e36, FLOAT32_BOUND / 1000 * 1.0000001])
def test_a_finite_translation_beyond_float32_in_mm_is_refused_on_both_paths(x_m: float) -> None:
    assert pose_to_igtl12(x_m, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0) is None
    assert pose_to_igtl12(0.0, 0.0, x_m, 0.0, 0.0, 0.0, 1.0) is None
    with pytest.raises(ConversionError) as info:
        pose_to_matrix([0.0, x_m, 0.0], [0, 0, 0, 1])
    assert info.value.field == "translation"
    assert "within float32 once in mm" in info.value.expected
    assert info.value.got == f"{[0.0, x_m, 0.0]} m"


def test_a_translation_just_inside_float32_in_mm_is_sent_as_it_is() -> None:
    x_m = 3.4e35  # 3.4e38 mm: finite as float32
    values = pose_to_igtl12(x_m, -x_m, 0.0, 0.0, 0.0, 0.0, 1.0)
    assert values is not None and values[9:] == (x_m * 1000, -x_m * 1000, 0.0)
    out = matrix_to_igtl12(pose_to_matrix([x_m, -x_m, 0.0], [0, 0, 0, 1]))
    assert np.all(np.isfinite(out)) and out[9] == np.float32(3.4e38)


def test_matrix_to_igtl12_refuses_what_float32_makes_infinite() -> None:
    m = np.eye(4)
    m[0, 3] = 1e39  # finite as a double, infinite as float32
    with pytest.raises(ConversionError) as info:
        matrix_to_igtl12(m)
    assert (info.value.field, info.value.expected) == ("matrix", "finite numbers within float32")
    m[0, 3] = BELOW
    assert float(matrix_to_igtl12(m)[9]) == float(np.finfo(np.float32).max)


# ---------------------------------------------------------------- time stamps

def test_timestamp_zero() -> None:
    assert igtl_timestamp_from_ros(0, 0) == 0
    assert ros_time_from_igtl(0) == (0, 0)


def test_timestamp_layout() -> None:
    ts = igtl_timestamp_from_ros(1_700_000_000, 500_000_000)
    assert ts >> 32 == 1_700_000_000
    assert ts & 0xFFFFFFFF == 1 << 31  # half a second
    assert igtl_timestamp_to_seconds(ts) == 1_700_000_000.5


@pytest.mark.parametrize(
    ("sec", "ns"),
    [
        (0, 0),
        (0, 1),
        (0, 999_999_999),
        (1_700_000_000, 999_999_999),
        (2**31 - 1, 999_999_999),  # last second before 2038-01-19
        (2**31 + 12_345, 678_901_234),  # after 2038: u32 seconds still fit
        (2**32 - 1, 999_999_999),  # 2106, the last representable second
    ],
)
def test_timestamp_round_trip_exact(sec: int, ns: int) -> None:
    assert ros_time_from_igtl(igtl_timestamp_from_ros(sec, ns)) == (sec, ns)


@given(st.integers(0, 2**32 - 1), st.integers(0, 999_999_999))
def test_timestamp_round_trip_property(sec: int, ns: int) -> None:
    ts = igtl_timestamp_from_ros(sec, ns)
    assert 0 <= ts < 2**64
    assert ros_time_from_igtl(ts) == (sec, ns)


@given(st.integers(0, 2**64 - 1))
def test_any_igtl_stamp_converts_within_half_ns(ts: int) -> None:
    sec, ns = ros_time_from_igtl(ts)
    assert 0 <= ns <= 999_999_999
    # Exact arithmetic: floats near 2**62 ns are ~512 ns apart, so a float "exact" value
    # made this test fail on large stamps (hypothesis found one) while the code was right.
    exact = Fraction(ts >> 32) * 10**9 + Fraction((ts & 0xFFFFFFFF) * 10**9, 2**32)
    assert abs(sec * 10**9 + ns - exact) <= Fraction(1, 2)


def test_fraction_just_below_a_second_carries() -> None:
    assert ros_time_from_igtl((5 << 32) | 0xFFFFFFFF) == (6, 0)


def test_now_and_seconds() -> None:
    before = time.time()
    ts = igtl_timestamp_now()
    after = time.time()
    assert before - 1e-3 <= igtl_timestamp_to_seconds(ts) <= after + 1e-3
    assert igtl_timestamp_from_seconds(1.5) == (1 << 32) | (1 << 31)


@pytest.mark.parametrize(
    ("sec", "ns", "fld"),
    [(-1, 0, "sec"), (2**32, 0, "sec"), (0, 10**9, "nanosec"), (0, -1, "nanosec"),
     (1.5, 0, "sec"), (True, 0, "sec")],
)
def test_timestamp_errors_name_field(sec: object, ns: object, fld: str) -> None:
    with pytest.raises(ConversionError) as info:
        igtl_timestamp_from_ros(sec, ns)  # type: ignore[arg-type]
    assert info.value.field == fld


def test_bad_igtl_stamp() -> None:
    with pytest.raises(ConversionError) as info:
        ros_time_from_igtl(2**64)
    assert info.value.field == "timestamp"
    with pytest.raises(ConversionError) as info:
        igtl_timestamp_from_seconds(float("nan"))
    assert info.value.field == "seconds"


@settings(max_examples=50)
@given(st.floats(0.0, 2.0**32 - 1, allow_nan=False))
def test_seconds_round_trip(seconds: float) -> None:
    assert igtl_timestamp_to_seconds(igtl_timestamp_from_seconds(seconds)) == pytest.approx(
        seconds, abs=1e-6)
