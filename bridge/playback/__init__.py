"""``slicer-ros2-bridge play BAG.mcap``: a recorded ROS 2 bag served to 3D Slicer over
OpenIGTLink as the live daemon serves ROS, without ROS.

    bag.py      the MCAP file: its index, messages in time order, the latest before a time,
                attachments; decoding with mcap-ros2-support from the bag's own schemas
    clock.py    the player's clock: bag time <- wall time, rate, pause, seek
    player.py   the playing thread and the capabilities clients talk to (topics, tf,
                robots, playback ops), on the daemon's own server, hub and dispatcher
    cli.py      the command line

Nothing here imports rclpy, nor any module that does: a laptop without ROS plays a bag.
"""
