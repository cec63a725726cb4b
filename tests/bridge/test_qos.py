"""QoS spec parsing into rclpy profiles."""

from __future__ import annotations

from typing import Any

import pytest
from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy

from bridge.qos import QosError, QosSpec, parse_qos, parse_spec, qos_to_dict
from protocol.errors import ProtocolError


def test_defaults() -> None:
    for spec in (None, {}):
        profile = parse_qos(spec)
        assert profile.depth == 10
        assert profile.history == HistoryPolicy.KEEP_LAST
        assert profile.reliability == ReliabilityPolicy.RELIABLE
        assert profile.durability == DurabilityPolicy.VOLATILE


def test_full_spec() -> None:
    profile = parse_qos({"depth": 1, "reliability": "best_effort",
                         "durability": "transient_local"})
    assert profile.depth == 1
    assert profile.reliability == ReliabilityPolicy.BEST_EFFORT
    assert profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert qos_to_dict(profile) == {"depth": 1, "reliability": "best_effort",
                                    "durability": "transient_local"}


def test_spellings_are_forgiving() -> None:
    assert parse_spec({"reliability": "Best-Effort", "durability": "TRANSIENT_LOCAL"}) == \
        QosSpec(10, "best_effort", "transient_local")


@pytest.mark.parametrize("spec, field", [
    ({"depth": 0}, "qos.depth"),
    ({"depth": -3}, "qos.depth"),
    ({"depth": 2.5}, "qos.depth"),
    ({"depth": True}, "qos.depth"),
    ({"depth": "10"}, "qos.depth"),
    ({"depth": 10**9}, "qos.depth"),
    ({"reliability": "sometimes"}, "qos.reliability"),
    ({"reliability": 1}, "qos.reliability"),
    ({"durability": "persistent"}, "qos.durability"),
    ({"history": "keep_all"}, "qos.history"),
    ([1, 2], "qos"),
])
def test_bad_specs_name_the_key(spec: Any, field: str) -> None:
    with pytest.raises(QosError) as err:
        parse_qos(spec)
    assert err.value.field == field
    assert isinstance(err.value, ProtocolError)
    assert err.value.expected
