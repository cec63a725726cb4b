"""A plain OpenIGTLink reader, as 3D Slicer's connector is: no key, no heartbeat, no
keepalive, it never sends; on a lost connection it reconnects every 0.1 s (as
OpenIGTLinkIO's client connector does). It shows every pose that arrives.

usage: plain_pose_reader.py HOST PORT TOPIC
First makes the daemon-wide subscriber of TOPIC (PoseStamped) on a connection of its own
and keeps it (keep_bridge: it would end with that connection), then reads. Prints READY
<device>; CONNECTED / LOST <reason>; POSE <age in ms by the publisher's own stamp, in the
message's header> 1 for each pose. Each line starts with the wall-clock time. Runs until
SIGINT.
"""

import socket
import sys
import time

from protocol.framing import Decoder
from slicer_client.connection import Connection


def say(line: str) -> None:
    print(f"{time.time():.3f} {line}", flush=True)


def read(host: str, port: int, device: str) -> str:
    """One connection, read until it ends: why it ended."""
    try:
        sock = socket.create_connection((host, port))
    except OSError as error:
        return f"connect: {error}"
    say("CONNECTED")
    decoder = Decoder()
    try:
        while True:
            data = sock.recv(1 << 16)
            if not data:
                return "closed by the daemon"
            decoder.feed(data)
            for message in decoder.messages():
                if message.device_name == device and message.type_name == "TRANSFORM":
                    stamp = (message.timestamp >> 32) + (message.timestamp & 0xFFFFFFFF) / 2**32
                    say(f"POSE {(time.time() - stamp) * 1000:.1f} 1")
    except OSError as error:
        return str(error)
    finally:
        sock.close()


def main() -> None:
    host, port, topic = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    setup = Connection(host, port)
    try:
        reply = setup.command("create_subscriber", {"topic": topic, "type": "PoseStamped"})
        # Kept past this connection: the reader's connections come and go.
        setup.command("keep_bridge", {"kind": "subscriber", "topic": topic})
    finally:
        setup.close()
    device = reply["device"]
    say(f"READY {device}")
    try:
        while True:
            why = read(host, port, device)
            say(f"LOST {why}")
            time.sleep(0.1)
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    main()
