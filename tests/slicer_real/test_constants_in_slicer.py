"""The stand-in's Slicer numbers (tests/slicer_constants.py) are slicer-core's, and Python
observers receive events as real VTK hands them."""

from __future__ import annotations

from slicer_constants import SLICER_CONSTANTS, event_as_observers_get_it


def test_every_constant_is_slicer_s_own(run_scene) -> None:
    got = run_scene("constants", keys=sorted(SLICER_CONSTANTS))
    assert got["values"] == SLICER_CONSTANTS
    # ModifiedEvent by name; a class's own event (TransformModifiedEvent) as 'NoEvent'.
    assert got["observed"] == ["ModifiedEvent", "NoEvent"]
    assert [event_as_observers_get_it(e) for e in (33, 15000)] == got["observed"]
