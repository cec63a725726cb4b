"""The schema's QoS maps onto the rclpy profile it names, and back."""

from __future__ import annotations

import json

import pytest
from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy

from bridge.ros.qos import qos_profile, qos_to_dict
from protocol.commands import CommandError, CreateSubscriber, QoS


def test_defaults_are_rclpy_defaults() -> None:
    profile = qos_profile(QoS())
    assert profile.history == HistoryPolicy.KEEP_LAST and profile.depth == 10
    assert profile.reliability == ReliabilityPolicy.RELIABLE
    assert profile.durability == DurabilityPolicy.VOLATILE


def test_latched_best_effort_profile_round_trips() -> None:
    qos = QoS(depth=1, reliability="best_effort", durability="transient_local")
    profile = qos_profile(qos)
    assert profile.depth == 1
    assert profile.reliability == ReliabilityPolicy.BEST_EFFORT
    assert profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert qos_to_dict(profile) == qos.to_dict()


@pytest.mark.parametrize("qos, field", [
    ({"depth": 0}, "qos.depth"),
    ({"reliability": "sometimes"}, "qos.reliability"),
    ({"durability": "forever"}, "qos.durability"),
    ({"deadline": 3}, "qos.deadline"),
])
def test_bad_qos_in_a_request_names_the_key(qos: dict, field: str) -> None:
    with pytest.raises(CommandError) as error:
        CreateSubscriber.from_json(json.dumps({"topic": "/t", "type": "String", "qos": qos}))
    assert error.value.field == field
