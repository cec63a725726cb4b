"""The joints a client drives (`bridge.robots.joints`): names and limits from the URDF,
mimic joints computed from their leader, refusals naming the joint and its limit; and the
demo's idle motion yielding to another publisher (`MotionHold`)."""

from __future__ import annotations

import math

import pytest

from bridge.robots.demo.motion_hold import MotionHold
from bridge.robots.description import parse_urdf
from bridge.robots.joints import describe_joints, joint_positions
from jointy_urdf import JOINTY_URDF
from protocol.commands import OutOfRangeError

URDF = JOINTY_URDF.replace("</robot>", """
  <link name="e"/><link name="f"/>
  <joint name="grandtwin" type="revolute"><parent link="d"/><child link="e"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>
    <mimic joint="twin" multiplier="10" offset="0.1"/></joint>
  <joint name="weld" type="fixed"><parent link="e"/><child link="f"/></joint>
</robot>""")


@pytest.fixture(scope="module")
def joints():
    return parse_urdf(URDF).joints


def test_description_lists_types_limits_and_mimics(joints) -> None:
    table = {j["name"]: j for j in describe_joints(joints)}
    assert list(table) == ["shoulder", "spin", "slide", "twin", "grandtwin", "weld"]
    assert (table["shoulder"]["lower"], table["shoulder"]["upper"]) == (-1.5, 1.5)
    assert table["shoulder"]["velocity"] == 2 and table["shoulder"]["actuated"]
    assert (table["spin"]["lower"], table["spin"]["upper"], table["spin"]["actuated"]) == (
        None, None, True)
    assert table["twin"]["mimic"] == {"joint": "slide", "multiplier": 0.5, "offset": 0.0}
    assert not table["twin"]["actuated"] and not table["weld"]["actuated"]


def test_positions_add_mimics_in_chain(joints) -> None:
    out = joint_positions(joints, [("shoulder", 1.0), ("spin", 12.0), ("slide", 0.03)])
    assert out["shoulder"] == 1.0 and out["spin"] == 12.0  # continuous: unlimited
    assert out["twin"] == pytest.approx(0.015)
    assert out["grandtwin"] == pytest.approx(10 * 0.015 + 0.1)


def test_mimics_of_joints_not_given_are_left_out(joints) -> None:
    assert joint_positions(joints, [("shoulder", 0.2)]) == {"shoulder": 0.2}


@pytest.mark.parametrize("requested, field, words", [
    ([("shoulder", 1.6)], "positions.shoulder",
     "[-1.5, 1.5] (the URDF <limit> of revolute joint 'shoulder')"),
    ([("slide", -0.001)], "positions.slide", "[0, 0.04]"),
    ([("twin", 0.01)], "positions.twin", "mimics 'slide', set that one"),
    ([("weld", 0.0)], "positions.weld", "a moving joint"),
    ([("elbow", 0.0)], "positions.elbow", "shoulder, spin, slide"),
    ([("shoulder", math.nan)], "positions.shoulder", "finite"),
])
def test_refusals_name_the_joint_and_its_limit(joints, requested, field, words) -> None:
    with pytest.raises(OutOfRangeError) as caught:
        joint_positions(joints, requested)
    assert caught.value.field == field
    assert words in str(caught.value)


def test_a_leader_driving_a_mimic_out_of_its_limits_is_refused() -> None:
    text = URDF.replace('multiplier="10" offset="0.1"', 'multiplier="100" offset="0.1"')
    with pytest.raises(OutOfRangeError) as caught:
        joint_positions(parse_urdf(text).joints, [("slide", 0.04)])
    assert caught.value.field == "positions.slide"
    assert "'grandtwin' mimics 'twin'" in str(caught.value)
    assert "[-1, 1]" in str(caught.value)


def test_values_at_a_limit_within_rounding_are_clamped(joints) -> None:
    assert joint_positions(joints, [("shoulder", 1.5 + 1e-12)]) == {"shoulder": 1.5}


def test_motion_hold_yields_after_a_foreign_state_and_while_paused() -> None:
    hold = MotionHold(yield_s=3.0)
    assert not hold.yields(100.0)
    assert hold.foreign_state(100.0) is True  # starts a yield
    assert hold.foreign_state(101.0) is False  # prolongs it, to 104
    assert hold.yields(103.9) and not hold.yields(104.0)
    assert hold.foreign_state(104.0) is True
    hold.pause("goal")
    hold.pause("sliders")
    hold.resume("goal")
    assert hold.yields(500.0)
    hold.resume("sliders")
    assert not hold.yields(500.0)
    with pytest.raises(ValueError):
        MotionHold(yield_s=-1)
