"""The `describe_type` op: what an installed message, service or action type is made of
(a capability without bridges)."""

from bridge.types.capability import InterfaceTypes

__all__ = ["InterfaceTypes"]
