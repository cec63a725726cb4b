"""3D Slicer's ROS2Bridge module on a link that can be pulled: the module's own
ConnectorTransport and slicer_client's Client, over tests/slicer_standin.py's TcpConnector
(OpenIGTLinkIO's client connector as read: a real socket, no keepalive, never sends on its
own, reconnects every 0.1 s). 3D Slicer itself cannot run here.

usage: module_link_reader.py HOST PORT TOPIC
Runs the loop Slicer would: the connector's PeriodicProcess every 5 ms (OpenIGTLinkIF's
timer), the module's poll every 0.2 s and its spin every 20 ms. Prints READY <device>;
CONNECTED / LOST <reason> as the module's status line changes; STALE <lines> / LIVE as
its stale-streams label changes; POSE <age in ms by the
message's header time> 1 each time the scene's transform node takes a pose. Each line
starts with the wall-clock time. Runs until SIGINT.
"""

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests/: the stand-ins

from slicer_client.client import Client  # noqa: E402
from slicer_client.scene_plan import stale_lines  # noqa: E402
from slicer_standin import TcpConnector, load_module  # noqa: E402

POLL_S, SPIN_S, PERIODIC_S = 0.2, 0.02, 0.005


def say(line: str) -> None:
    print(f"{time.time():.3f} {line}", flush=True)


def main() -> None:
    host, port, topic = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    module = load_module(sys.modules.__setitem__)
    device = [""]

    def shown(node, message) -> None:
        if message.type_name == "TRANSFORM" and message.device_name == device[0]:
            stamp = (message.timestamp >> 32) + (message.timestamp & 0xFFFFFFFF) / 2**32
            say(f"POSE {(time.time() - stamp) * 1000:.1f} 1")

    connector = TcpConnector(host, port, shown)
    while connector.GetState() != connector.StateConnected:
        connector.PeriodicProcess()
        time.sleep(PERIODIC_S)
    transport = module.ConnectorTransport(connector)
    client = Client(transport, callbacks="spin")  # as the module's logic makes it
    client.on_connection_change(
        lambda up, reason: say("CONNECTED" if up else f"LOST {reason}"))
    device[0] = client.subscribe(topic, "PoseStamped").device
    say(f"READY {device[0]}")
    polled = spun = time.monotonic()
    shown_stale: list = []
    try:
        while True:
            connector.PeriodicProcess()
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
        connector.stop()


if __name__ == "__main__":
    main()
