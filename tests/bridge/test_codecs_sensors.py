"""sensor_msgs JointState and Joy <-> STRING JSON."""

from __future__ import annotations

import json
from typing import Any

import pytest
from sensor_msgs.msg import JointState, Joy

from bridge.codecs import CodecError, codec_for
from protocol.messages import unpack_body


def _wire(body: Any) -> Any:
    return unpack_body(body.TYPE, body.pack())


def test_joint_state_round_trip() -> None:
    codec = codec_for("JointState")
    js = JointState(name=["shoulder", "elbow", "insertion"], position=[0.5, -1.25, 0.012],
                    velocity=[0.0, 0.1, 0.0], effort=[])
    js.header.frame_id = "psm1"
    enc = codec.encode(js)
    assert json.loads(enc.body.text) == {"name": ["shoulder", "elbow", "insertion"],
                                         "position": [0.5, -1.25, 0.012],
                                         "velocity": [0.0, 0.1, 0.0], "effort": []}
    assert codec.from_igtl(_wire(enc.body), frame_id="psm1") == js
    assert codec.from_value(codec.to_value(js), frame_id="psm1") == js


@pytest.mark.parametrize("value, field", [
    ({"name": ["a", "b"], "position": [1.0]}, "value.position"),
    ({"name": ["a"], "effort": ["x"]}, "value.effort[0]"),
    ({"name": "a"}, "value.name"),
    ({"name": ["a"], "positions": [1.0]}, "value.positions"),
    ([1.0], "value"),
])
def test_bad_joint_states(value: Any, field: str) -> None:
    with pytest.raises(CodecError) as err:
        codec_for("JointState").from_value(value)
    assert err.value.field == field


def test_joy_round_trip() -> None:
    codec = codec_for("Joy")
    joy = Joy(axes=[0.5, -1.0, 0.25], buttons=[0, 1, 1, 0])
    enc = codec.encode(joy)
    assert json.loads(enc.body.text) == {"axes": [0.5, -1.0, 0.25], "buttons": [0, 1, 1, 0]}
    assert codec.from_igtl(_wire(enc.body)) == joy
    assert codec.from_value(codec.to_value(joy)) == joy
    with pytest.raises(CodecError) as err:
        codec.from_value({"axes": [0.0], "buttons": [0.5]})
    assert err.value.field == "value.buttons[0]"
    with pytest.raises(CodecError) as err:
        codec.from_value({"axes": [0.0], "buttons": [2**31]})
    assert err.value.field == "value.buttons[0]"
