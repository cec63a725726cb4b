"""The rclpy adapter: the daemon's ROS nodes and what every capability asks of ROS.

- ros_node.py: the daemon's rclpy nodes and executors; the only module that starts or
  stops ROS.
- raw_reader.py: raw subscriptions read without the interpreter's lock, in a thread of
  their own, through the compiled _rcl_reader.pyx (typed by _rcl_reader.pyi).
- qos.py: the rclpy QoS profile for a bridge's QoS, and the tf topics' profiles.
- ros_clients.py: the cached rclpy service and action clients.
- ros_args.py: `--ros-args` mapped onto the daemon's own options.
- graph_types.py: one topic, one type: the check before a subscription or a publisher.
- service_calls.py: a ROS service called from the asyncio loop (services, parameters).
"""
