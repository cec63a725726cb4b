"""The compiled tf store gives what the pure Python store gives, to the bit.

Two `TfBuffer`s, one on each store, are fed the same random histories: re-parentings, loops,
static/dynamic switches, out-of-order, repeated and too-old samples, denormalised and invalid
quaternions, NaN, empty and '/'-prefixed frame ids, samples pruned out of a short window.
After each batch, every result they give must be equal: changed frames or the refusal (type
and text), graph versions, frame listings, lookups of every pair at the latest time and at
times around each stamp (values compared bit for bit, errors by type and text), batch
lookups and chain frames. The compiled side reads its batches from real CDR (rclpy's
serializer) through `set_transforms_cdr`, as the daemon does, and the Python side takes the
same batch as `StampedTransform`s.
"""

from __future__ import annotations

import math
import struct
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bridge.tf import buffer as buffer_module
from bridge.tf.buffer import StampedTransform, TfBuffer
from bridge.tf.errors import TfError

pytestmark = pytest.mark.skipif(
    buffer_module.CompiledFrameStore is None,
    reason="the compiled tf store was not built (no C compiler or Cython at install)")

S = 1_000_000_000
FRAMES = ["a", "b", "c", "d", "e", "/a", ""]
WINDOW_S = 2.0  # short, so histories reach the pruning


def _bits(value: Any) -> Any:
    """Floats as their bit patterns (so -0.0 != 0.0 and any last-bit difference shows)."""
    if isinstance(value, float):
        return struct.pack("<d", value)
    if isinstance(value, tuple):
        return tuple(_bits(v) for v in value)
    return value


def _outcome(call: Any, *args: Any, **kwargs: Any) -> Any:
    try:
        result = call(*args, **kwargs)
    except TfError as error:
        return ("error", type(error).__name__, str(error))
    if isinstance(result, StampedTransform):
        return ("ok", result.parent, result.child, result.stamp_ns,
                _bits(result.translation), _bits(result.rotation))
    return ("ok", result)


def _many(results: list) -> list:
    return [_outcome(_given, r) for r in results]


def _given(result: Any) -> Any:
    if isinstance(result, TfError):
        raise result
    return result


def _quaternion(kind: str, x: float, y: float, z: float, w: float) -> tuple:
    if kind == "nan":
        return (math.nan, y, z, w)
    if kind == "long":
        return (2.0 * x, 2.0 * y, 2.0 * z, 2.0 * w)
    n = math.sqrt(x * x + y * y + z * z + w * w) or 1.0
    q = (x / n, y / n, z / n, w / n)
    if kind == "slightly":
        return tuple(v * 1.002 for v in q)
    return q


# Irregular numbers: hypothesis' favourite floats (0, 1, 0.5) interpolate to the same bits
# by almost any formula, and would hide a formula that differs.
unit = st.integers(-10**6, 10**6).map(lambda k: k / 999_983)
coordinate = st.integers(-10**7, 10**7).map(lambda k: k / 999_983)
transforms = st.tuples(
    st.sampled_from(FRAMES), st.sampled_from(FRAMES),
    st.one_of(st.integers(0, 24).map(lambda k: k * 250_000_037),  # within and beyond the window
              st.integers(-3, 3).map(lambda k: k * S + 7),  # negative seconds too
              st.just(0)),
    st.tuples(coordinate, coordinate, coordinate),
    st.sampled_from(["unit", "unit", "unit", "slightly", "long", "nan"]),
    st.tuples(unit, unit, unit, unit))
batches = st.tuples(st.booleans(), st.lists(transforms, min_size=0, max_size=6))


def _stamped(parent: str, child: str, stamp: int, t: tuple, kind: str,
             q: tuple) -> StampedTransform:
    return StampedTransform(parent, child, stamp, t, _quaternion(kind, *q))


def _cdr(batch: list[StampedTransform]) -> bytes:
    from geometry_msgs.msg import TransformStamped
    from rclpy.serialization import serialize_message
    from tf2_msgs.msg import TFMessage

    msg = TFMessage()
    for tr in batch:
        ts = TransformStamped()
        sec, nanosec = divmod(tr.stamp_ns, S)
        ts.header.stamp.sec, ts.header.stamp.nanosec = sec, nanosec
        ts.header.frame_id, ts.child_frame_id = tr.parent, tr.child
        (ts.transform.translation.x, ts.transform.translation.y,
         ts.transform.translation.z) = tr.translation
        (ts.transform.rotation.x, ts.transform.rotation.y, ts.transform.rotation.z,
         ts.transform.rotation.w) = tr.rotation
        msg.transforms.append(ts)
    return serialize_message(msg)


def _ticks() -> Any:
    """A clock that stands still: each batch then gets the tick after the last (1, 2, ...),
    the same on both buffers."""
    return lambda: 0


def _compare(py: TfBuffer, compiled: TfBuffer, times: list[int]) -> None:
    assert py.graph_version == compiled.graph_version
    # What the buffer judges room by: each child frame's newest parent and receive tick.
    assert sorted(py._store.receipts()) == sorted(compiled._store.receipts())
    assert py.forgotten == compiled.forgotten
    assert py.frames() == compiled.frames()
    assert py.frame_info() == compiled.frame_info()
    names = [f for f in FRAMES if f] + ["unknown"]
    pairs = [(a, b) for a in names for b in names]
    assert _many(py.lookup_latest_many(pairs)) == _many(compiled.lookup_latest_many(pairs))
    for target, source in pairs:
        for t in times:
            assert (_outcome(py.lookup, target, source, t)
                    == _outcome(compiled.lookup, target, source, t)), (target, source, t)
        assert (_outcome(py.chain_frames, target, source)
                == _outcome(compiled.chain_frames, target, source))


@settings(max_examples=250, deadline=None)
@given(st.lists(batches, min_size=1, max_size=8), st.booleans())
def test_both_stores_give_the_same_results(history: list, clear_midway: bool) -> None:
    py = TfBuffer(WINDOW_S, compiled=False, clock=_ticks())
    compiled = TfBuffer(WINDOW_S, compiled=True, clock=_ticks())
    assert compiled.compiled and not py.compiled
    stamps = {0}
    for number, (static, raw) in enumerate(history):
        batch = [_stamped(*r) for r in raw]
        stamps.update(tr.stamp_ns for tr in batch if tr.stamp_ns >= 0)
        expected = _outcome(py.set_transforms, batch, static=static)
        got = _outcome(compiled.set_transforms_cdr, _cdr(batch), static=static)
        if expected[0] == "error":
            assert got == expected
        else:
            assert got == ("ok", expected[1])
        if clear_midway and number == len(history) // 2:
            py.clear()
            compiled.clear()
    # Irregular offsets: ratios like 0.5 give the same bits by almost any formula.
    times = sorted({max(0, s + d) for s in stamps for d in (-S // 7 - 3, 0, S // 9 + 11)})
    _compare(py, compiled, times)


@settings(max_examples=100, deadline=None)
@given(st.lists(batches, min_size=1, max_size=6))
def test_set_transforms_on_both_stores_agrees(history: list) -> None:
    """The same batches through `set_transforms` on both (the path of broadcasters, and of
    messages another CDR encoding brought)."""
    py = TfBuffer(WINDOW_S, compiled=False, clock=_ticks())
    compiled = TfBuffer(WINDOW_S, compiled=True, clock=_ticks())
    for static, raw in history:
        batch = [_stamped(*r) for r in raw]
        assert (_outcome(py.set_transforms, batch, static=static)
                == _outcome(compiled.set_transforms, batch, static=static))
    _compare(py, compiled, [0, S, S + S // 3, 5 * S])


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(batches, st.integers(0, 3 * S)), min_size=1, max_size=10))
def test_a_full_buffer_forgets_alike(history: list) -> None:
    """Four frames at most and receive times from a clock set by hand: both buffers forget
    the same frames (the rule is `TfBuffer`'s, on each store's receive ticks) and refuse
    the same ones."""
    now = [0]
    py = TfBuffer(WINDOW_S, compiled=False, max_frames=4, clock=lambda: now[0])
    compiled = TfBuffer(WINDOW_S, compiled=True, max_frames=4, clock=lambda: now[0])
    stamps = {0}
    for (static, raw), later in history:
        now[0] += later
        batch = [_stamped(*r) for r in raw]
        stamps.update(tr.stamp_ns for tr in batch if tr.stamp_ns >= 0)
        expected = _outcome(py.set_transforms, batch, static=static)
        got = _outcome(compiled.set_transforms_cdr, _cdr(batch), static=static)
        assert got == (expected if expected[0] == "error" else ("ok", expected[1]))
    times = sorted({max(0, s + d) for s in stamps for d in (-S // 7 - 3, 0)})
    _compare(py, compiled, times)


def test_a_long_history_is_pruned_alike() -> None:
    """Thousands of samples at 1 kHz through a 2 s window: the chunked pruning of both stores
    keeps the same samples, and interpolation between them gives the same bits."""
    py = TfBuffer(WINDOW_S, compiled=False)
    compiled = TfBuffer(WINDOW_S, compiled=True)
    for k in range(6000):
        angle = k * 1e-3
        q = (0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2))
        batch = [StampedTransform("base", "arm", k * S // 1000, (angle, 0.0, 1.0), q),
                 StampedTransform("arm", "tool", k * S // 1000 + 1, (0.0, angle, 0.0), q)]
        py.set_transforms(batch, static=False)
        compiled.set_transforms_cdr(_cdr(batch), static=False)
    assert py.frame_info() == compiled.frame_info()
    assert py.frame_info()[0].samples == 2001  # the window, not the history
    times = [0, 4 * S + 123_457, 5 * S + 999_999, 5_999 * S // 1000, 3_500_000_001]
    for t in times:
        assert (_outcome(py.lookup, "base", "tool", t)
                == _outcome(compiled.lookup, "base", "tool", t))
    assert _outcome(compiled.lookup, "base", "tool", 4 * S + 123_457)[0] == "ok"


def test_bytes_the_compiled_store_does_not_read_store_nothing() -> None:
    compiled = TfBuffer(WINDOW_S, compiled=True)
    good = _cdr([StampedTransform("w", "b", S, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))])
    for data in (b"", b"\x00\x01\x00\x00", b"\x01\x00" + good[2:], good[:-1],
                 good.replace(b"w\x00", b"\xff\x00")):
        assert compiled.set_transforms_cdr(data, static=False) is None
    assert compiled.frames() == []
    assert compiled.set_transforms_cdr(good, static=False) == {"b"}
    assert compiled.lookup("w", "b").translation == (1.0, 0.0, 0.0)


def test_the_pure_python_store_leaves_cdr_to_the_caller() -> None:
    py = TfBuffer(WINDOW_S, compiled=False)
    good = _cdr([StampedTransform("w", "b", S, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))])
    assert py.set_transforms_cdr(good, static=False) is None
    assert py.frames() == []


@settings(max_examples=400, deadline=None)
@given(st.lists(transforms, min_size=1, max_size=4),
       st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 255)), max_size=4),
       st.integers(0, 10_000))
def test_damaged_cdr_is_read_as_the_python_reader_reads_it(raw: list, flips: list,
                                                           cut: int) -> None:
    """Bytes changed or cut anywhere: where codecs/cdr.py's reader refuses them, the compiled
    store stores nothing (None, and the daemon reads them the ordinary way); where it reads
    them, both stores end up with the same frames."""
    from bridge.codecs.cdr import CdrError, read_tf_message
    from bridge.tf.capability import tf_cdr_to_transforms

    data = bytearray(_cdr([_stamped(*r) for r in raw]))
    for position, value in flips:
        data[position % len(data)] = value
    data = bytes(data[:max(0, len(data) - cut % (len(data) + 1))])
    compiled = TfBuffer(WINDOW_S, compiled=True)
    try:
        read_tf_message(data)
    except CdrError:
        assert compiled.set_transforms_cdr(data, static=False) is None
        assert compiled.frames() == []
        return
    py = TfBuffer(WINDOW_S, compiled=False)
    assert (_outcome(compiled.set_transforms_cdr, data, static=False)
            == _outcome(py.set_transforms, tf_cdr_to_transforms(data), static=False))
    assert py.frame_info() == compiled.frame_info()
