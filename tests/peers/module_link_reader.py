"""3D Slicer's ROS2Bridge module on a link that can be pulled: the module's own
ConnectorTransport and slicer_client's Client over Slicer's own OpenIGTLinkIF connector (a
real socket, no keepalive, never sends on its own, reconnects by itself), in a real MRML
scene. Runs in the Slicer peer's Python (tools/slicer_core/peer.py), not the daemon's.

usage: PEER_PYTHON module_link_reader.py HOST PORT TOPIC
Runs the loop Slicer would: its event loop (OpenIGTLinkIF's 5 ms connector timer) every
5 ms, the module's poll every 0.2 s and its spin every 20 ms. Prints READY <device>;
CONNECTED / LOST <reason> as the module's status line changes; STALE <lines> / LIVE as
its stale-streams label changes; POSE <age in ms> 1 each time the scene's transform node
takes a pose. The age is by the publisher's stamp, which stream_publisher.py --stamp-in-y
carries in the pose's y (seconds modulo 1000, shown in mm): Slicer's transform node keeps
no header time. Each line starts with the wall-clock time. Runs until SIGINT.
"""

import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository

from slicer_client.client import Client  # noqa: E402
from slicer_client.scene_plan import stale_lines  # noqa: E402
from tools.slicer_core.session import open_session  # noqa: E402

POLL_S, SPIN_S, PERIODIC_S = 0.2, 0.02, 0.005


def say(line: str) -> None:
    print(f"{time.time():.3f} {line}", flush=True)


def age_ms(stamp_mm: float) -> float:
    """Now minus the stamp the pose carries (seconds modulo 1000, in mm: ms)."""
    return ((time.time() % 1000.0) * 1000.0 - stamp_mm) % 1_000_000.0


def main() -> None:
    host, port, topic = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    session = open_session()
    import slicer
    import vtk
    connector = session.scene.AddNewNodeByClass("vtkMRMLIGTLConnectorNode", "daemon")
    connector.SetTypeClient(host, port)
    connector.Start()
    session.pump(60, until=lambda: connector.GetState()
                 == slicer.vtkMRMLIGTLConnectorNode.StateConnected, what="the daemon")
    transport = session.module.ConnectorTransport(connector)
    client = Client(transport, callbacks="spin")  # as the module's logic makes it
    client.on_connection_change(
        lambda up, reason: say("CONNECTED" if up else f"LOST {reason}"))
    device = client.subscribe(topic, "PoseStamped").device
    say(f"READY {device}")
    watched: list[Any] = []

    def shown(node: Any, event: Any) -> None:
        matrix = vtk.vtkMatrix4x4()
        node.GetMatrixTransformToParent(matrix)
        say(f"POSE {age_ms(matrix.GetElement(1, 3)):.1f} 1")

    polled = spun = time.monotonic()
    shown_stale: list[str] = []
    try:
        while True:
            session.slicer_app.processEvents()
            if not watched:  # the connector makes the node with the first pose
                node = session.scene.GetFirstNode(device, "vtkMRMLLinearTransformNode")
                if node is not None:
                    node.AddObserver(slicer.vtkMRMLTransformNode.TransformModifiedEvent, shown)
                    watched.append(node)
            now = time.monotonic()
            if now - polled >= POLL_S:
                polled = now
                transport.poll()
            if now - spun >= SPIN_S:
                spun = now
                client.Spin()
                stale = stale_lines(client.resources())  # the module's warning label
                if stale != shown_stale:
                    say(f"STALE {'; '.join(stale)}" if stale else "LIVE")
                    shown_stale = stale
            time.sleep(PERIODIC_S)
    except KeyboardInterrupt:
        pass
    finally:
        transport.close()
        connector.Stop()
        session.close()


if __name__ == "__main__":
    main()
