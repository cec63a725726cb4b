"""Motion: kinematics and collisions of a loaded robot on pinocchio and coal.

What the daemon calls::

    model = MotionModel(robot_model)              # a bridge.robots.RobotModel (its URDF)
    result = solve_ik(model, target_m, "tool_flange", seed=current_positions)
    result.positions if result.ok else result.failure   # unreachable / joint_limit / collision
    world = CollisionWorld(model)                  # links' collision geometry (or visuals)
    world.set_obstacle("skull", vertices_m, triangles, pose_m)
    world.distances(theta, "tool_flange")          # metres to each obstacle

Lengths are METRES here (ROS's unit); the op and the client speak millimetres, converted
by `protocol.conversions` at the edge. pinocchio and coal (~80 MB of wheels) are imported
with the first robot a motion query touches, never at daemon start: this package imports
nothing; its modules are `model` (MotionModel), `ik` (solve_ik, IkResult), `collisions`
(CollisionWorld), `errors` and `capability` (the daemon's ops, which imports pinocchio only
in its handlers).
"""

