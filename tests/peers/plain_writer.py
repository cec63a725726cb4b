"""A plain OpenIGTLink client with no key, as a hand-written one on the network would be:
tries the moves that change ROS and prints what the daemon answered, one line each.

usage: plain_writer.py HOST PORT [--expect-refusal]
Prints `hello writes=<bool>`, then `<op> <CODE> <message>` for create_publisher,
call_service (another node's use_sim_time) and send_goal (a joint trajectory).
--expect-refusal: the daemon should close this connection at once; prints
`refused: <what its STATUS said>`. Exits 0 when it could try everything.
"""

import argparse
import socket
import sys

from protocol.framing import Decoder
from slicer_client.connection import CommandRefusedError, Connection


def refused(host: str, port: int) -> int:
    decoder = Decoder()
    with socket.create_connection((host, port), timeout=20) as sock:
        while True:
            data = sock.recv(65536)
            if not data:
                break
            decoder.feed(data)
    for message in decoder.messages():
        if message.type_name == "STATUS":
            print(f"refused: {message.body.text}", flush=True)
            return 0
    print("closed without a word", flush=True)
    return 1


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("host")
    parser.add_argument("port", type=int)
    parser.add_argument("--expect-refusal", action="store_true")
    args = parser.parse_args()
    if args.expect_refusal:
        return refused(args.host, args.port)
    tries = [
        ("create_publisher", {"topic": "/cmd_vel", "type": "geometry_msgs/msg/Twist"}),
        ("call_service", {"service": "/demo_motion/set_parameters",
                          "type": "rcl_interfaces/srv/SetParameters",
                          "request": {"parameters": [{"name": "use_sim_time", "value": {
                              "type": 1, "bool_value": True}}]}}),
        ("send_goal", {"action": "/arm_controller/follow_joint_trajectory",
                       "type": "control_msgs/action/FollowJointTrajectory",
                       "goal": {"trajectory": {"joint_names": ["joint_1"], "points": [
                           {"positions": [1.2], "time_from_start": {"sec": 1}}]}}}),
    ]
    connection = Connection(args.host, args.port)
    try:
        hello = connection.command("hello", {})
        print(f"hello writes={hello['auth']['writes']}", flush=True)
        for op, arguments in tries:
            try:
                connection.command(op, arguments)
                print(f"{op} ACCEPTED", flush=True)
            except CommandRefusedError as error:
                print(f"{op} {error.code.name} {error}", flush=True)
    finally:
        connection.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
