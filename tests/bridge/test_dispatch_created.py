"""A create op's handler says whether its bridge was there already by returning `Created`;
the dispatcher alone turns that into the reply's ``existed`` and the quota's decision."""

from __future__ import annotations

import pytest

from bridge.core.dispatch import Created, _created
from protocol import commands as c

CREATE = c.CreateSubscriber(topic="/x", type="String")
LIST = c.ListRobots()


def test_a_create_s_reply_says_whether_its_bridge_existed() -> None:
    assert _created(CREATE, Created({"device": "x"}, existed=True)) == (
        {"device": "x", "existed": True}, True)
    assert _created(CREATE, Created({"device": "x"}, existed=False)) == (
        {"device": "x", "existed": False}, False)
    assert _created(LIST, {"robots": []}) == ({"robots": []}, False)


def test_a_handler_that_breaks_the_convention_is_a_bug_named_by_its_op() -> None:
    with pytest.raises(TypeError, match="create_subscriber handler returned dict"):
        _created(CREATE, {"device": "x", "existed": True})
    with pytest.raises(TypeError, match="list_robots handler returned Created"):
        _created(LIST, Created({}, existed=False))
