"""tf broadcasters and lookups through the real daemon, the parts a client gets wrong or does
twice: creating a broadcaster again, removing a static one (later subscribers no longer get
it), a STRING sent to a broadcaster's device, a frame id that maps to nothing. Real TCP
clients, a real rclpy echo peer; plus the STATUS an error too long for its name field gets."""

from __future__ import annotations

import itertools
import json
from typing import Any

import numpy as np
import pytest

from bridge.tf import InvalidArgumentError
from bridge.tf.capability import status_for_error
from protocol.messages import Message, Status, StatusCode, String
from slicer_client.connection import CommandRefusedError, Connection
from support import Processes, RunningDaemon, scaled, wait_until

_prefixes = itertools.count()


def fresh(stem: str) -> str:
    return f"{stem}{next(_prefixes)}_"


def test_an_error_name_too_long_for_status_is_shortened() -> None:
    status = status_for_error(InvalidArgumentError("target_frame", "a frame id (str)", "int"))
    assert isinstance(status, Status)
    assert status.error_name == "INVALID_ARGUMENT"  # INVALID_ARGUMENT_ERROR is 22 bytes
    assert "target_frame" in status.text


def test_creating_a_broadcaster_again_gives_the_existing_one(
        daemon: RunningDaemon, client: Connection) -> None:
    p = fresh("again")
    first = client.command("create_tf_broadcaster", {"parent": p + "world", "child": p + "a"})
    second = client.command("create_tf_broadcaster", {"parent": p + "world", "child": p + "a"})
    assert (first["existed"], second["existed"]) == (False, True)
    assert second["device"] == first["device"]
    client.command("remove_tf_broadcaster", {"parent": p + "world", "child": p + "a"})


def test_a_string_sent_to_a_broadcaster_device_is_refused_with_a_status(
        daemon: RunningDaemon, client: Connection) -> None:
    p = fresh("string")
    device = client.command("create_tf_broadcaster", {"parent": p + "world",
                                                      "child": p + "probe"})["device"]
    client.send(Message(device, String("[[1, 0, 0, 0]]")))
    status = client.wait_for(device, lambda m: isinstance(m.body, Status), timeout=scaled(10))
    assert status.body.code == StatusCode.CONFIG_ERROR
    assert "not broadcast on /tf" in status.body.text
    assert "a TRANSFORM (4x4 matrix in mm)" in status.body.text and "STRING" in status.body.text
    client.command("remove_tf_broadcaster", {"parent": p + "world", "child": p + "probe"})


def test_a_frame_id_that_maps_to_nothing_is_refused(daemon: RunningDaemon,
                                                    client: Connection) -> None:
    with pytest.raises(CommandRefusedError) as refused:
        client.command("create_tf_lookup", {"parent": "/", "child": "tool"})
    assert refused.value.error.code.name == "OUT_OF_RANGE"
    assert refused.value.error.field == "parent"


def _static_children(echo: Any) -> list[list[str]]:
    out = []
    for line in echo.lines():
        if line.startswith("MSG "):
            out.append([t["child_frame_id"] for t in json.loads(line[4:])["transforms"]])
    return out


def test_a_removed_static_broadcaster_is_gone_for_later_subscribers(
        daemon: RunningDaemon, client: Connection, processes: Processes) -> None:
    p = fresh("static")
    keep, drop = p + "kept", p + "dropped"
    for child in (keep, drop):
        client.command("create_tf_broadcaster", {"parent": p + "world", "child": child,
                                                 "static": True})
        client.command("broadcast_transform", {"parent": p + "world", "child": child,
                                               "matrix": np.eye(4).tolist()})
    removed = client.command("remove_tf_broadcaster", {"parent": p + "world", "child": drop})
    assert (removed["parent"], removed["child"]) == (p + "world", drop)
    # A subscriber started now gets the latched /tf_static: the kept frame, not the other.
    echo = processes.python("echo", "echo_subscriber.py", "/tf_static",
                            "tf2_msgs/msg/TFMessage", "--transient-local")
    echo.wait_for_output("READY")
    wait_until(lambda: any(keep in children for children in _static_children(echo)),
               timeout=20, what="the latched /tf_static with the kept frame")
    latest = _static_children(echo)[-1]
    assert keep in latest and drop not in latest
    client.command("remove_tf_broadcaster", {"parent": p + "world", "child": keep})
