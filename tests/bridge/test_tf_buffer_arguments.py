"""TfBuffer's argument checks as a caller or a peer can get them wrong: lookups in one batch
with one bad pair, frame ids that are not strings, bool or numpy times and stamps, a bad
transform hidden in a flood toward a looked-up frame, and frame ids YAML must quote.
Runs on both tf stores (tests/bridge/conftest.py). No ROS, except the CDR of a TFMessage."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from bridge.tf import (
    InvalidArgumentError,
    RejectedTransformsError,
    StampedTransform,
    TfBuffer,
    TfError,
    TfLookupError,
)

pytestmark = pytest.mark.usefixtures("tf_store")

S = 1_000_000_000
IDQ = (0.0, 0.0, 0.0, 1.0)


def tf(parent: object, child: object, stamp: object = 5 * S,
       t: tuple[float, float, float] = (0.0, 0.0, 1.0)) -> StampedTransform:
    return StampedTransform(parent, child, stamp, t, IDQ)  # type: ignore[arg-type]


def _cdr(batch: list[StampedTransform]) -> bytes:
    """A TFMessage's CDR bytes, as the daemon receives /tf."""
    from geometry_msgs.msg import TransformStamped
    from rclpy.serialization import serialize_message
    from tf2_msgs.msg import TFMessage

    msg = TFMessage()
    for tr in batch:
        ts = TransformStamped()
        ts.header.stamp.sec = tr.stamp_ns // S
        ts.header.frame_id, ts.child_frame_id = tr.parent, tr.child
        ts.transform.translation.z = tr.translation[2]
        ts.transform.rotation.w = 1.0
        msg.transforms.append(ts)
    return serialize_message(msg)


@pytest.fixture
def chain() -> TfBuffer:
    buffer = TfBuffer()
    buffer.set_transforms([tf("world", "base"), tf("base", "tool", t=(1.0, 0.0, 0.0))],
                          static=False)
    return buffer


def test_a_batch_of_lookups_with_one_bad_pair_answers_each_pair(chain: TfBuffer) -> None:
    results = chain.lookup_latest_many([("world", "tool"), ("", "tool"), ("world", "nowhere")])
    assert isinstance(results[0], StampedTransform)
    assert results[0].translation == (1.0, 0.0, 1.0)
    assert isinstance(results[1], InvalidArgumentError)
    assert "target_frame" in str(results[1])
    assert isinstance(results[2], TfLookupError) and isinstance(results[2], TfError)
    assert "nowhere" in str(results[2])


def test_frame_ids_that_are_not_strings_are_refused(chain: TfBuffer) -> None:
    with pytest.raises(InvalidArgumentError) as raised:
        chain.lookup(5, "tool")  # type: ignore[arg-type]
    assert "target_frame" in str(raised.value) and "a frame id (str)" in str(raised.value)
    with pytest.raises(InvalidArgumentError) as raised:
        chain.set_transforms([tf("world", "a"), tf(7, "b")], static=False)
    assert "transforms[1] frame ids" in str(raised.value) and "int, str" in str(raised.value)


def test_times_are_integers_not_bools_numpy_integers_welcome(chain: TfBuffer) -> None:
    with pytest.raises(InvalidArgumentError) as raised:
        chain.lookup("world", "tool", True)  # type: ignore[arg-type]
    assert "time_ns" in str(raised.value) and "bool" in str(raised.value)
    assert chain.lookup("world", "tool", np.int64(5 * S)).stamp_ns == 5 * S


def test_stamps_are_integers_not_bools_numpy_integers_welcome() -> None:
    buffer = TfBuffer()
    assert buffer.set_transforms([tf("w", "a", np.int64(3 * S))], static=False) == {"a"}
    assert buffer.lookup("w", "a").stamp_ns == 3 * S
    for stamp, shown in [(True, "bool"), (3.5, "float")]:
        with pytest.raises(RejectedTransformsError) as raised:
            buffer.set_transforms([tf("w", "b", stamp)], static=False)
        assert "transforms[0].stamp_ns" in str(raised.value) and shown in str(raised.value)
    assert not buffer.has_frame("b")
    # A static transform has no time: its stamp is not looked at.
    assert buffer.set_transforms([tf("w", "c", "whenever")], static=True) == {"c"}


def test_has_frame_strips_the_leading_slash(chain: TfBuffer) -> None:
    assert chain.has_frame("tool") and chain.has_frame("/tool") and chain.has_frame("world")
    assert not chain.has_frame("nowhere")


def test_frame_ids_yaml_would_misread_are_quoted() -> None:
    buffer = TfBuffer()
    buffer.set_transforms([tf("world", "-arm"), tf("world", "a b: c"),
                           tf("world", "it's")], static=False)
    doc = yaml.safe_load(buffer.all_frames_as_yaml(current_time_ns=6 * S))
    assert set(doc) == {"-arm", "a b: c", "it's"}
    assert doc["a b: c"]["parent"] == "world"


def test_a_bad_transform_toward_a_looked_up_frame_in_a_flood_is_not_stored() -> None:
    """Past the few worded refusals of a flood, transforms toward a looked-up frame are
    judged again: a bad one among them is counted and left out, a good one stored."""
    buffer = TfBuffer(max_frames=20, looked_up_reserve=20)
    buffer.look_up(["tip"])
    batch = [tf("junk", f"j{i}") for i in range(100)] + [tf("tip", "tip"), tf("base", "tip")]
    try:
        changed = buffer.set_transforms_cdr(_cdr(batch), static=False)
    except RejectedTransformsError as raised:
        # junk and j0..j18 fill the 20 frames: 81 junk frames refused, and tip -> tip.
        assert raised.count == 82
        assert "tip" in raised.changed
    else:
        assert changed is None  # the pure Python store: the daemon deserializes instead
        return
    assert buffer.lookup("base", "tip").translation == (0.0, 0.0, 1.0)
    assert buffer.lookup("tip", "tip").translation == (0.0, 0.0, 0.0)  # identity, not stored
