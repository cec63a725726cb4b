"""A plain OpenIGTLink reader, as 3D Slicer's connector is: no key, no heartbeat, reads no
freshness stamps; it makes a subscriber bridge, prints each pose's age as it arrives, and
reconnects (making the bridge again) when the daemon closes its connection.

usage: plain_reader.py HOST PORT TOPIC
Prints READY once streaming; POSE <age in ms by the publisher's own stamp> for each pose;
LOST when the connection closes; CONNECTED when it is back. Each line starts with the
wall-clock time. Runs until SIGINT.
"""

import sys
import threading
import time

from slicer_client.connection import Connection, DaemonUnreachableError


def main() -> None:
    host, port, topic = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    lock = threading.Lock()
    closed = threading.Event()
    device = [""]

    def say(line: str) -> None:
        with lock:
            print(f"{time.time():.3f} {line}", flush=True)

    def on_message(message) -> None:
        if message.device_name == device[0] and message.type_name == "TRANSFORM":
            stamp = (message.timestamp >> 32) + (message.timestamp & 0xFFFFFFFF) / 2 ** 32
            say(f"POSE {(time.time() - stamp) * 1000:.1f}")

    first = True
    try:
        while True:
            closed.clear()
            try:
                connection = Connection(host, port, on_message=on_message,
                                        on_close=lambda error: closed.set())
            except DaemonUnreachableError:
                time.sleep(0.2)
                continue
            try:
                device[0] = connection.command("create_subscriber", {
                    "topic": topic, "type": "PoseStamped"})["device"]
            except Exception as error:  # noqa: BLE001 - closed while asking: try again
                say(f"LOST {error}")
                connection.close()
                continue
            say("READY" if first else "CONNECTED")
            first = False
            closed.wait()
            say("LOST")
            connection.close()
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    main()
