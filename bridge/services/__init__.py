"""Service bridges (`bridge.services.capability`): `call_service`, `advertise_service` and
`unadvertise_service`."""

from bridge.services.capability import ServiceBridges

__all__ = ["ServiceBridges"]
