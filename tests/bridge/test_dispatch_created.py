"""A create op's handler says whether its bridge was there already by returning `Created`;
the dispatcher alone turns that into the reply's ``existed`` and the quota's decision."""

from __future__ import annotations

import pytest

from bridge.core.dispatch import Created, _created
from bridge.core.heavy import LargeResult
from protocol import commands as c

CREATE = c.CreateSubscriber(topic="/x", type="String")
LIST = c.ListRobots()


def test_a_create_s_reply_says_whether_its_bridge_existed() -> None:
    bridge = c.TopicBridge("subscriber", "/x", "std_msgs/msg/String", "x", "STRING")
    assert _created(CREATE, Created(bridge, existed=True)) == (
        {**bridge.to_dict(), "existed": True}, True)
    assert _created(CREATE, Created(bridge, existed=False)) == (
        {"kind": "subscriber", "topic": "/x", "type": "std_msgs/msg/String", "device": "x",
         "igtl_type": "STRING", "messages": 0, "existed": False}, False)
    assert _created(LIST, c.ListRobotsResult(())) == ({"robots": []}, False)


def test_a_handler_that_breaks_the_convention_is_a_bug_named_by_its_op() -> None:
    with pytest.raises(TypeError, match="create_subscriber handler returned dict"):
        _created(CREATE, {"device": "x", "existed": True})
    with pytest.raises(TypeError, match="list_robots handler returned Created"):
        _created(LIST, Created(c.ListRobotsResult(()), existed=False))


def test_a_handler_returns_the_result_its_op_declares() -> None:
    """Issue 44: a reply is its op's typed result, never a dict built beside it."""
    with pytest.raises(TypeError, match="the list_robots handler returned dict: expected "
                                        "ListRobotsResult, the result its op declares"):
        _created(LIST, {"robots": []})
    with pytest.raises(TypeError, match="the create_subscriber handler returned "
                                        "TfBridgeRemoved: expected TopicBridge"):
        _created(CREATE, Created(c.TfBridgeRemoved("a", "b", "tf:a>b"), existed=False))
    # A listing's reply is encoded off the event loop (its result says it is large).
    listing, _ = _created(c.ListTopics(), c.ListTopicsResult(({"topic": "/a"},)))
    assert isinstance(listing, LargeResult) and listing == {"topics": [{"topic": "/a"}]}
