"""A Slicer-side client for the operating-room tests: connects with the writers' key,
subscribes to a pose topic and prints, one line each, what a user of it would see.

usage: or_client.py HOST PORT KEY_FILE TOPIC
Prints READY; CONNECTED / LOST <reason>; POSE <age in ms by the publisher's own stamp>
<1 if made current, 0 if dropped as late>, for each pose as it is read;
STALE <reason> / LIVE; and every 0.5 s LATE <values dropped as late so far>. Each line
starts with the wall-clock time. Runs until SIGINT.
"""

import sys
import threading
import time

import slicer_client
from slicer_client.client import Client


def main() -> None:
    host, port, key_file, topic = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
    lock = threading.Lock()

    def say(line: str) -> None:
        with lock:
            print(f"{time.time():.3f} {line}", flush=True)

    devices = set()
    receive = Client.on_message

    def on_message(self, message) -> None:  # each message as the receive thread reads it
        dropped = self.late_dropped
        receive(self, message)
        if message.device_name in devices and message.type_name == "TRANSFORM":
            stamp = (message.timestamp >> 32) + (message.timestamp & 0xFFFFFFFF) / 2 ** 32
            shown = int(self.late_dropped == dropped)
            say(f"POSE {(time.time() - stamp) * 1000:.1f} {shown}")

    Client.on_message = on_message
    ros = slicer_client.connect(host, port, key_file=key_file)
    pose = ros.subscribe(topic, "PoseStamped")
    devices.add(pose.device)
    pose.add_stale_callback(lambda reason: say(f"STALE {reason}" if reason else "LIVE"))
    ros.on_connection_change(lambda up, reason: say("CONNECTED" if up else f"LOST {reason}"))
    say(f"READY writes={ros.may_write}")
    try:
        while True:
            time.sleep(0.5)
            say(f"LATE {ros.late_dropped}")
    except KeyboardInterrupt:
        pass
    finally:
        ros.close()


if __name__ == "__main__":
    main()
