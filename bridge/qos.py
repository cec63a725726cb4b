"""QoS of a subscription or publisher, from a client's spec dict to an rclpy `QoSProfile`.

A spec is a JSON object with any of::

    {"depth": 10, "reliability": "reliable" | "best_effort",
     "durability": "volatile" | "transient_local"}

Missing keys take the defaults below (rclpy's own: keep-last 10, reliable, volatile).
Spellings are case-insensitive and ``-`` may replace ``_`` ("best-effort"). Anything else
raises `QosError` naming the key, what was accepted and what came.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from protocol.errors import ProtocolError

__all__ = ["QosError", "QosSpec", "parse_qos", "qos_to_dict"]

DEFAULT_DEPTH = 10
MAX_DEPTH = 1_000_000  # a bigger history is a typo, and would reserve that much memory

_RELIABILITY = {"reliable": ReliabilityPolicy.RELIABLE,
                "best_effort": ReliabilityPolicy.BEST_EFFORT}
_DURABILITY = {"volatile": DurabilityPolicy.VOLATILE,
               "transient_local": DurabilityPolicy.TRANSIENT_LOCAL}
_KEYS = ("depth", "reliability", "durability")


class QosError(ProtocolError):
    """A QoS spec cannot be used; ``field`` is ``qos.<key>``."""


@dataclass(frozen=True)
class QosSpec:
    """A validated QoS spec; `profile()` gives the rclpy profile (keep-last ``depth``)."""

    depth: int = DEFAULT_DEPTH
    reliability: str = "reliable"
    durability: str = "volatile"

    def profile(self) -> QoSProfile:
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=self.depth,
                          reliability=_RELIABILITY[self.reliability],
                          durability=_DURABILITY[self.durability])

    def to_dict(self) -> dict[str, Any]:
        return {"depth": self.depth, "reliability": self.reliability,
                "durability": self.durability}


def _choice(spec: Mapping[str, Any], key: str, allowed: Mapping[str, Any], default: str) -> str:
    if key not in spec:
        return default
    value = spec[key]
    expected = " or ".join(repr(a) for a in allowed)
    if not isinstance(value, str):
        raise QosError(field=f"qos.{key}", expected=expected, got=f"{type(value).__name__} "
                       f"{value!r}")
    norm = value.strip().lower().replace("-", "_")
    if norm not in allowed:
        raise QosError(field=f"qos.{key}", expected=expected, got=repr(value))
    return norm


def parse_spec(spec: Mapping[str, Any] | None) -> QosSpec:
    """Validate a spec dict (``None`` or ``{}`` = defaults) into a `QosSpec`."""
    if spec is None:
        return QosSpec()
    if not isinstance(spec, Mapping):
        raise QosError(field="qos", expected="an object with depth, reliability, durability",
                       got=type(spec).__name__)
    unknown = sorted(str(k) for k in spec if k not in _KEYS)
    if unknown:
        raise QosError(field=f"qos.{unknown[0]}", expected="one of " + ", ".join(_KEYS),
                       got="an unknown key")
    depth = spec.get("depth", DEFAULT_DEPTH)
    # bool is an int subclass: refuse it explicitly.
    if isinstance(depth, bool) or not isinstance(depth, int) or not 1 <= depth <= MAX_DEPTH:
        raise QosError(field="qos.depth", expected=f"an integer in [1, {MAX_DEPTH}]",
                       got=f"{type(depth).__name__} {depth!r}")
    return QosSpec(depth=depth,
                   reliability=_choice(spec, "reliability", _RELIABILITY, "reliable"),
                   durability=_choice(spec, "durability", _DURABILITY, "volatile"))


def parse_qos(spec: Mapping[str, Any] | None) -> QoSProfile:
    """A spec dict (``None`` = defaults) -> rclpy `QoSProfile`; `QosError` if invalid."""
    return parse_spec(spec).profile()


def qos_to_dict(profile: QoSProfile) -> dict[str, Any]:
    """The spec form of a profile (for replies and logs); unknown policies named as-is."""
    rel = {v: k for k, v in _RELIABILITY.items()}.get(profile.reliability,
                                                       str(profile.reliability.name).lower())
    dur = {v: k for k, v in _DURABILITY.items()}.get(profile.durability,
                                                     str(profile.durability.name).lower())
    return {"depth": int(profile.depth), "reliability": rel, "durability": dur}
