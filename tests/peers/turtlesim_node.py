"""A stand-in for turtlesim's node (C++/Qt, not on PyPI): what tests talk to, no window.

Node /turtlesim with turtlesim's integer parameters background_r=69, background_g=86,
background_b=255 (settable through the standard parameter services, as `ros2 param set`
does), and its services /spawn (turtlesim/srv/Spawn) and /kill (turtlesim/srv/Kill).
As in turtlesim, turtle1 exists from the start; a spawn with an empty name gets turtle2,
turtle3, ...; a name in use or an unknown name to kill is logged as an error and answered
with an empty response.

usage: turtlesim_node.py [--ros-args ...]
Needs the turtlesim interfaces (tests/interfaces/turtlesim, built by the test session).
Prints READY once its services exist, then `CALL spawn {...}` / `CALL kill {...}` per call
and `PARAM {"name": ..., "value": ...}` per parameter change. Stops on SIGINT or SIGTERM,
printing STOPPED once its node is gone.
"""

import json
import sys

from rclpy.node import Node

from bridge.robots._spin import ros_session, spin_until_signal

try:
    from turtlesim.srv import Kill, Spawn
except ImportError as error:
    sys.exit(f"turtlesim_node: the turtlesim interfaces are not importable ({error}); "
             f"build tests/interfaces/turtlesim (the test session's turtlesim fixture does)")


class Turtlesim(Node):
    def __init__(self) -> None:
        super().__init__("turtlesim")
        for name, value in (("background_r", 69), ("background_g", 86), ("background_b", 255)):
            self.declare_parameter(name, value)
        self.turtles = {"turtle1"}
        self.last_id = 1
        self.add_post_set_parameters_callback(self.changed)
        self.create_service(Spawn, "spawn", self.spawn)
        self.create_service(Kill, "kill", self.kill)

    def spawn(self, request: Spawn.Request, response: Spawn.Response) -> Spawn.Response:
        print("CALL spawn " + json.dumps({"x": request.x, "y": request.y, "theta": request.theta,
                                          "name": request.name}), flush=True)
        name = request.name
        while not name or (not request.name and name in self.turtles):
            self.last_id += 1  # as turtlesim's counter: never reused, even after a kill
            name = f"turtle{self.last_id}"
        if name in self.turtles:
            self.get_logger().error(f"A turtle named [{name}] already exists")
            return response
        self.turtles.add(name)
        response.name = name
        return response

    def kill(self, request: Kill.Request, response: Kill.Response) -> Kill.Response:
        print("CALL kill " + json.dumps({"name": request.name}), flush=True)
        if request.name not in self.turtles:
            self.get_logger().error(f"Tried to kill turtle [{request.name}], which does not "
                                    f"exist")
        self.turtles.discard(request.name)
        return response

    def changed(self, parameters: list) -> None:
        for parameter in parameters:
            print("PARAM " + json.dumps({"name": parameter.name, "value": parameter.value}),
                  flush=True)


def main() -> None:
    # The daemon's own children's way to stop. With rclpy's signal handlers, a SIGTERM shut
    # the context down under the spinning executor, which then now and then raised an
    # RCLError or kept waiting in rcl_wait (2 in ~100 stops here; fresh-clone runs ci56, ci64).
    with ros_session(args=sys.argv) as session:
        spin_until_signal(session, [Turtlesim()], on_ready=lambda: print("READY", flush=True))
    print("STOPPED", flush=True)


if __name__ == "__main__":
    main()
