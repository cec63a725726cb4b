"""Marker lifetimes, re-sent markers and markers that change their node class or parent,
through a real daemon, from a real rclpy publisher (tests/peers/marker_publisher.py) to a
real TCP client.

What a user sees: a marker re-sent unchanged keeps its device and lives on (its lifetime
renewed, nothing re-sent); a marker whose lifetime ends goes, whatever order the expiries
come in and however many renewals came before; a marker that turns from a cube into a text,
or from placed-once into frame-locked, keeps its device name with the new kind; an array
over the bound is refused whole, said on the topic's index; a topic removed while its
markers wait to expire does not disturb the others.
"""

from __future__ import annotations

import itertools
import json
import os
import time
from pathlib import Path
from typing import Any, Iterator

import pytest

from protocol.messages import Message, PolyData, String
from protocol.naming import KEY_MARKERS
from slicer_client.connection import Connection
from support import (Child, Processes, RunningDaemon, assert_clean_exit, scaled, start_daemon,
                     wait_until)

CUBE, SPHERE, TEXT = 1, 2, 9
DELETEALL = 3
SMALL = [0.1, 0.1, 0.1]


class Peer:
    """The marker publisher and its control file."""

    def __init__(self, processes: Processes, folder: Path) -> None:
        self.control = folder / "control.json"
        self.seq = itertools.count(1)
        self.child: Child = processes.python("markers", "marker_publisher.py",
                                             str(self.control))
        self.child.wait_for_output("READY", timeout=30)

    def send(self, **doc: Any) -> None:
        seq = next(self.seq)
        tmp = self.control.with_suffix(".tmp")
        tmp.write_text(json.dumps({"seq": seq, **doc}))
        os.replace(tmp, self.control)
        self.child.wait_for_output(f"APPLIED {seq}", timeout=30)


@pytest.fixture(scope="module")
def daemon(module_processes: Processes) -> Iterator[RunningDaemon]:
    running = start_daemon(module_processes)
    yield running
    # Markers with a long lifetime are still live: the daemon stops with their timer armed.
    assert_clean_exit(running)


@pytest.fixture(scope="module")
def peer(module_processes: Processes, tmp_path_factory: pytest.TempPathFactory) -> Peer:
    return Peer(module_processes, tmp_path_factory.mktemp("marker-lifetimes"))


@pytest.fixture(scope="module")
def client(daemon: RunningDaemon, peer: Peer) -> Iterator[Connection]:
    connection = daemon.connect()
    # The publisher's markers are in "base": until the daemon has its /tf_static world ->
    # base, a marker cannot be placed in the fixed frame, and a re-send once it can would
    # re-place it (a new model), which these tests read as something else.
    connection.command("lookup_transform", {"parent": "world", "child": "base",
                                            "timeout": 60.0})
    for topic, kind in (("/test_markers", "MarkerArray"), ("/test_marker", "Marker")):
        connection.command("create_marker_subscriber",
                           {"topic": topic, "type": kind, "fixed_frame": "world"})
    yield connection
    connection.close()


def rows(client: Connection, topic: str) -> dict[tuple[str, int], dict[str, Any]]:
    listing = client.command("list_markers", {"topic": topic})
    return {(r["ns"], r["id"]): r for r in listing["markers"]}


def subscriber(client: Connection, topic: str) -> dict[str, Any]:
    """The daemon's description of the marker subscriber of `topic` (list_bridges)."""
    bridges = client.command("list_bridges", {})["bridges"]
    return next(b for b in bridges if b["kind"] == "marker_subscriber" and b["topic"] == topic)


def wait_rows(client: Connection, topic: str, want: set[tuple[str, int]]
              ) -> dict[tuple[str, int], dict[str, Any]]:
    found: dict[tuple[str, int], dict[str, Any]] = {}

    def ready() -> bool:
        nonlocal found
        found = rows(client, topic)
        return set(found) == want
    wait_until(ready, 15, f"markers {sorted(want)} on {topic}")
    return found


def expiry(client: Connection, key: tuple[str, int]) -> float:
    """When the marker's lifetime ends, on the host's monotonic clock (the daemon's too;
    list_markers says how long it has left, to the ms), at most: counted from when the
    question was sent, so that a reply that was slow to come never pushes it later."""
    asked = time.monotonic()
    return asked + float(rows(client, "/test_markers")[key]["expires_in"]) - 0.0005


def resend_renews(client: Connection, peer: Peer, markers: list[dict[str, Any]],
                  key: tuple[str, int], lifetime: float) -> None:
    """Re-send `markers` and wait until `key`'s lifetime ends at least `lifetime` after the
    re-send: only a renewal moves it there (before, it ended `lifetime` after its last
    arrival, which came before the re-send). Compared with the end estimated before the
    re-send instead, a re-send that arrived 25 ms after the first looked like none (ci65)."""
    received = subscriber(client, "/test_markers")["messages"]
    sent = time.monotonic()
    peer.send(markers=markers)
    try:
        wait_until(lambda: expiry(client, key) >= sent + lifetime, 15,
                   f"the lifetime of {key} renewed by the re-sent array")
    except AssertionError as error:  # say whether the daemon received it
        raise AssertionError(
            f"{error}: it ends {expiry(client, key) - sent:.3f} s after the re-send; messages "
            f"received before {received}, now: {subscriber(client, '/test_markers')}") from None


def test_renewed_lifetimes_expire_in_order(client: Connection, peer: Peer) -> None:
    peer.send(markers=[{"action": DELETEALL}])
    wait_rows(client, "/test_markers", set())
    long_lived = [{"ns": "long", "id": i, "type": CUBE, "scale": SMALL, "lifetime": 120.0}
                  for i in range(20)]
    peer.send(markers=long_lived)
    found = wait_rows(client, "/test_markers", {("long", i) for i in range(20)})
    device = found[("long", 0)]["device"]
    first_model = client.wait_for(device, timeout=scaled(10))
    # Re-sent unchanged: the lifetime is renewed (its end moves later), the device and its
    # model stay: nothing is re-sent.
    for _ in range(4):
        resend_renews(client, peer, long_lived, ("long", 0), 120.0)
    assert client.latest(device) is first_model
    assert rows(client, "/test_markers")[("long", 0)]["device"] == device

    # A short-lived marker: its expiry comes before those armed, renewed once (its first
    # expiry is then stale); it goes on its own, the long-lived ones stay.
    short = {"ns": "short", "id": 1, "type": SPHERE, "scale": SMALL, "lifetime": 3.0}
    peer.send(markers=[short])
    wait_rows(client, "/test_markers", {("long", i) for i in range(20)} | {("short", 1)})
    resend_renews(client, peer, [short], ("short", 1), 3.0)
    left = wait_rows(client, "/test_markers", {("long", i) for i in range(20)})
    assert all(r["expires_in"] > 60 for r in left.values())
    index_device = client.command("list_markers", {"topic": "/test_markers"})["device"]
    index = client.wait_for(index_device, lambda m: len(json.loads(
        m.metadata[KEY_MARKERS])) == 20, timeout=scaled(10))
    assert json.loads(index.body.text)["markers"] == 20


def test_a_topic_removed_before_its_markers_expire(client: Connection, peer: Peer) -> None:
    """A marker on another topic, whose subscriber is removed before it would expire: the
    daemon's expiry timer comes to a topic that is no more, and the others' markers still
    expire."""
    live = set(rows(client, "/test_markers"))
    peer.send(marker={"ns": "gone", "id": 1, "type": CUBE, "scale": SMALL, "lifetime": 4.0})
    wait_rows(client, "/test_marker", {("gone", 1)})
    removed = client.command("remove_marker_subscriber", {"topic": "/test_marker"})
    assert removed["topic"] == "/test_marker" and len(removed["devices"]) == 2
    # Sent after it, expiring after it: once this one is gone, so is the removed topic's
    # expiry (skipped: its topic is no more).
    peer.send(markers=[{"ns": "late", "id": 1, "type": CUBE, "scale": SMALL,
                        "lifetime": 4.5}])
    wait_until(lambda: ("late", 1) in rows(client, "/test_markers"), 15, "the late marker")
    wait_rows(client, "/test_markers", live)


def test_a_marker_that_changes_kind_or_parent_keeps_its_device(client: Connection,
                                                              peer: Peer) -> None:
    cube = {"ns": "morph", "id": 1, "type": CUBE, "scale": SMALL, "frame": "base"}
    peer.send(markers=[cube])
    row = wait_rows(client, "/test_markers", set(rows(client, "/test_markers"))
                    | {("morph", 1)})[("morph", 1)]
    assert row["placed"] is True and row["type"] == "cube"
    device = row["device"]
    assert isinstance(client.wait_for(device, timeout=scaled(10)).body, PolyData)

    # Now frame-locked: its model is in its own frame, not placed in the fixed frame.
    peer.send(markers=[dict(cube, locked=True)])
    wait_until(lambda: rows(client, "/test_markers")[("morph", 1)]["placed"] is False, 15,
               "the marker to follow its frame")
    locked = rows(client, "/test_markers")[("morph", 1)]
    assert locked["device"] == device and locked["frame"] == "base"
    assert locked["frame_device"] != row["frame_device"]

    # Now a text: another node class, the same device name, a STRING.
    peer.send(markers=[dict(cube, locked=True, type=TEXT, text="hello")])

    def is_text(message: Message) -> bool:
        return isinstance(message.body, String) and message.body.text == "hello"
    client.wait_for(device, is_text, timeout=scaled(10))
    assert rows(client, "/test_markers")[("morph", 1)]["type"] == "text_view_facing"


def test_an_array_over_the_bound_is_refused_whole(client: Connection, peer: Peer) -> None:
    device = client.command("list_markers", {"topic": "/test_markers"})["device"]
    before = set(rows(client, "/test_markers"))
    peer.send(markers=[{"ns": "flood", "id": i, "type": CUBE} for i in range(20_001)])
    index = client.wait_for(device, lambda m: "message refused" in json.loads(
        m.body.text)["error"], timeout=scaled(20))
    error = json.loads(index.body.text)["error"]
    assert "a MarkerArray of at most 20000 markers" in error and "20001 markers" in error
    assert set(rows(client, "/test_markers")) == before  # nothing of it shown
