"""Recording a session as a standard ROS 2 bag (MCAP): `definitions` (the ros2msg schema
texts), `bag` (the writer thread and the file), `recorder` (the raw ROS subscriptions),
`capability` (the daemon's recording ops), `cli` (`slicer-ros2-bridge record`)."""
