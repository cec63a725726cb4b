"""The module's ConnectorTransport over Slicer's own OpenIGTLinkIF connector node, connected
to an OpenIGTLink peer in this process (igtl_peer.py: it stays silent, leaves a command
unanswered and counts what it is sent, on cue): commands through vtkSlicerOpenIGTLinkCommand,
each text and point list sent exactly once, a loss reported once, a silent heartbeat taken
for a lost link and its return for the link back; and the module's defaults."""

from __future__ import annotations

import time
from types import SimpleNamespace
from typing import Any, Callable

import slicer

from igtl_peer import IgtlPeer
from protocol.liveness import HEARTBEAT_DEVICE, stream_condition
from protocol.messages import Message, Status, String
from scene_tools import error_of
from slicer_client.send_plan import plan_send


def until(condition: Callable[[], bool], what: str, step: Callable[[], Any],
          seconds: float = 20.0) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {seconds} s: {what}")
        step()
        time.sleep(0.005)


def main(session: Any, args: dict[str, Any]) -> dict[str, Any]:
    module, scene = session.module, session.scene
    peer = IgtlPeer()
    connector = scene.AddNewNodeByClass("vtkMRMLIGTLConnectorNode", "peer")
    connector.SetTypeClient("127.0.0.1", peer.port)
    connector.Start()
    State = slicer.vtkMRMLIGTLConnectorNode  # noqa: N806
    session.pump(20, until=lambda: connector.GetState() == State.StateConnected,
                 what="the connector connected to the peer")
    now = [100.0]
    transport = module.ConnectorTransport(connector, clock=lambda: now[0])
    out: dict[str, Any] = {"watches_silence": transport.watches_silence,
                           "drops_late_values": transport.drops_late_values,
                           "default_frame": module.DEFAULT_FRAME,
                           "robot_name": session.logic.getParameterNode().robotName}

    # Commands: sent as vtkSlicerOpenIGTLinkCommand; unanswered, expired at the timeout.
    # (Answered: the self-test's round trip, test_selftest_in_slicer.py.)
    started = time.monotonic()
    out["expired"] = error_of(lambda: transport.command("list_bridges", timeout=1.0))
    out["expired_after_s"] = time.monotonic() - started
    # The peer's thread may read it after the timeout on a busy machine: wait for it.
    until(lambda: bool(peer.of_type("COMMAND")), "the command at the peer", session.pump)
    out["command_names"] = [m.body.name for m in peer.of_type("COMMAND")]

    # Each send is one message, whether the text changed or not.
    for text in ("a", "a", "b"):
        transport.send(Message("pub:cmd", String(text)))
    def texts() -> list[str]:
        return [m.body.text for m in peer.of_type("STRING", "pub:cmd")]
    until(lambda: len(texts()) >= 3, "three texts at the peer", session.pump)
    session.pump(0.3)  # a fourth would be here by now
    out["texts"] = texts()
    outgoing = [connector.GetOutgoingMRMLNode(i)
                for i in range(connector.GetNumberOfOutgoingMRMLNodes())]
    out["outgoing"] = [(n.GetClassName(), n.GetName(), n.GetEncoding()) for n in outgoing]
    out["not_ascii"] = error_of(lambda: transport.send(Message("pub:cmd", String("caf\u00e9"))))

    # A point list: one POINT message per send, world positions and labels.
    source = scene.AddNewNodeByClass("vtkMRMLMarkupsFiducialNode", "F")
    source.AddControlPoint(1.0, 2.0, 3.0, "entry")
    source.AddControlPoint(4.0, 5.0, 6.0, "target")
    out["node_kind"] = module.nodeKind(source)
    plan = plan_send("vtkMRMLMarkupsFiducialNode", "/slicer/points")
    for _ in range(2):
        transport.sendNode("pub:slicer/points", plan, source)

    def points() -> list[Any]:
        return [[[list(map(float, e.position)), e.name] for e in m.body.points]
                for m in peer.of_type("POINT", "pub:slicer/points")]
    until(lambda: len(points()) >= 2, "two point lists at the peer", session.pump)
    session.pump(0.3)
    out["points"] = points()

    # The listener: told of a loss once, of the link's return once.
    seen: list[list[Any]] = []
    messages: list[Message] = []
    listener = SimpleNamespace(
        on_connected=lambda command, first: (seen.append(["up", first]),
                                             transport.expect_data_within(3.0)),
        on_disconnected=lambda reason: seen.append(["down", reason]),
        on_message=messages.append)
    transport.set_listener(listener)

    # Heartbeats: the daemon's STATUS, once a second (the clock here is the test's).
    def heartbeat(at: float) -> None:
        now[0] = at
        before = transport.heartbeats
        peer.send(Message(HEARTBEAT_DEVICE, Status()))
        until(lambda: transport.heartbeats > before, f"the heartbeat at {at}", transport.poll)

    peer.send(Message("or_pose", Status(code=13, error_name="stale",
                                        text="no publisher of /or_pose")))
    for at in (101.0, 102.0, 103.0):
        heartbeat(at)
    until(lambda: len(messages) >= 1, "the stream's condition", transport.poll)
    status_nodes = {n.GetName(): n for n in (
        connector.GetIncomingMRMLNode(i) for i in range(connector.GetNumberOfIncomingMRMLNodes()))
        if n is not None and n.IsA("vtkMRMLIGTLStatusNode")}
    out["heartbeat"] = {"count": transport.heartbeats, "connected": transport.connected,
                        "hidden": status_nodes[HEARTBEAT_DEVICE].GetHideFromEditors(),
                        "stream_hidden": status_nodes["or_pose"].GetHideFromEditors()}
    out["stale_message"] = [messages[0].device_name, messages[0].body.code,
                            messages[0].body.error_name, messages[0].body.text]
    peer.send(Message("or_pose", Status(code=1, error_name="live")))
    until(lambda: len(messages) >= 2, "the stream live again", transport.poll)
    out["live_condition"] = [stream_condition(messages[-1]), len(messages)]

    now[0] = 106.1  # 3.1 s after the last heartbeat
    transport.poll()
    commands_before = len(peer.of_type("COMMAND"))
    out["silent"] = {"seen": list(seen), "connected": transport.connected,
                     "silent": transport.silent,
                     "command": error_of(lambda: transport.command("list_bridges")),
                     "commands_sent": len(peer.of_type("COMMAND")) - commands_before}
    now[0] = 108.0
    transport.poll()
    out["said_once"] = [event[0] for event in seen]
    heartbeat(108.5)  # the same socket carries data again
    transport.poll()
    out["back"] = {"last": seen[-1], "connected": transport.connected,
                   "silent": transport.silent}

    # The socket closed by the peer: the loss found by poll() (the connector's events come
    # only while it is connected), its return by the connector's ConnectedEvent; a second
    # ConnectedEvent changes nothing.
    seen.clear()
    peer.drop()
    until(lambda: connector.GetState() != State.StateConnected, "the connector's loss",
          lambda: session.pump(0.01))
    transport.poll()
    peer.resume()
    until(lambda: connector.GetState() == State.StateConnected, "the connector back",
          lambda: session.pump(0.01))
    until(lambda: len(seen) >= 2, "the link back at the listener", lambda: session.pump(0.01))
    connector.InvokeEvent(State.ConnectedEvent)
    out["loss"] = [event[:1] + ([event[1]] if event[0] == "up" else []) for event in seen]

    # A silent link whose socket the daemon resets while the connector reconnects at once
    # (a pulled cable put back: the daemon's knock). OpenIGTLinkIO's connection thread makes
    # the new socket within one turn, so no Disconnected/ConnectedEvent comes; data flows
    # on the new socket (a stream), no heartbeat (the daemon sends one after a hello only).
    events: list[str] = []
    for name in ("ConnectedEvent", "DisconnectedEvent"):
        connector.AddObserver(getattr(State, name), lambda c, e, n=name: events.append(n))
    now[0] += 3.5
    transport.poll()  # silent: the link is lost
    seen.clear()
    connections = peer.connections
    peer.kick()
    until(lambda: peer.connections > connections, "the connector's new socket",
          lambda: session.pump(0.01))
    peer.send(Message("or_pose", Status(code=1, error_name="live")))
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline and not seen:
        session.pump(0.05)
        transport.poll()
    out["quick_reconnect"] = {"connector_events": events, "told": list(seen),
                              "silent": transport.silent}

    # Stopped: commands are refused at once.
    transport.close()
    connector.Stop()
    out["stopped"] = error_of(lambda: transport.command("list_bridges"))
    peer.close()
    return out
