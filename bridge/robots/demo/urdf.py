"""The demo robot's URDF, written for this project (kept in Python so it ships in any wheel).

A 6-axis arm on a base plate with a two-finger gripper: base, shoulder, upper arm, elbow,
forearm, wrist 1-3, tool flange, two fingers. It exercises every visual path of
`bridge.robots.model`:

- primitives: boxes, cylinders, spheres, rotated by visual origins;
- several visuals on one link (base, wrist 3, tool flange);
- meshes generated at first run (`meshgen`): a revolved STL (shoulder), an OBJ written in
  millimetres with ``scale="0.001 0.001 0.001"`` (upper arm), a COLLADA file in
  centimetres whose own material gives the colour (forearm: no URDF material), an
  extruded STL (wrist 2);
- named robot-level materials and inline colours;
- revolute joints with limits, two fixed joints, a prismatic finger and a mimic finger.

Lengths in metres, angles in radians, z up. The meshes are referenced as
``package://slicer_ros2_bridge_demo/meshes/...``.
"""

DEMO_PACKAGE = "slicer_ros2_bridge_demo"

DEMO_URDF = """<?xml version="1.0"?>
<robot name="slicer_ros2_bridge_demo_arm">

  <material name="steel"><color rgba="0.62 0.64 0.66 1.0"/></material>
  <material name="dark_grey"><color rgba="0.20 0.21 0.23 1.0"/></material>
  <material name="signal_blue"><color rgba="0.10 0.33 0.75 1.0"/></material>

  <link name="base_link">
    <visual name="base_plate">
      <origin xyz="0 0 0.005"/>
      <geometry><box size="0.24 0.24 0.01"/></geometry>
      <material name="dark_grey"/>
    </visual>
    <visual name="base_column">
      <origin xyz="0 0 0.035"/>
      <geometry><cylinder radius="0.07" length="0.05"/></geometry>
      <material name="steel"/>
    </visual>
  </link>

  <link name="shoulder_link">
    <visual>
      <geometry><mesh filename="package://slicer_ros2_bridge_demo/meshes/shoulder.stl"/></geometry>
      <material name="signal_blue"/>
    </visual>
  </link>

  <link name="upper_arm_link">
    <visual>
      <origin xyz="0 0 0.15"/>
      <geometry>
        <mesh filename="package://slicer_ros2_bridge_demo/meshes/upper_arm.obj"
              scale="0.001 0.001 0.001"/>
      </geometry>
      <material name="arm_orange"><color rgba="0.95 0.50 0.10 1.0"/></material>
    </visual>
  </link>

  <link name="elbow_link">
    <visual>
      <geometry><sphere radius="0.055"/></geometry>
      <material name="steel"/>
    </visual>
  </link>

  <link name="forearm_link">
    <visual>
      <origin xyz="0 0 0.15"/>
      <geometry><mesh filename="package://slicer_ros2_bridge_demo/meshes/forearm.dae"/></geometry>
    </visual>
  </link>

  <link name="wrist_1_link">
    <visual>
      <origin xyz="0 0 0" rpy="1.5707963267948966 0 0"/>
      <geometry><cylinder radius="0.035" length="0.07"/></geometry>
      <material name="dark_grey"/>
    </visual>
  </link>

  <link name="wrist_2_link">
    <visual>
      <geometry><mesh filename="package://slicer_ros2_bridge_demo/meshes/wrist_2.stl"/></geometry>
      <material name="arm_orange"/>
    </visual>
  </link>

  <link name="wrist_3_link">
    <visual name="wrist_3_disc">
      <origin xyz="0 0 0.01"/>
      <geometry><cylinder radius="0.03" length="0.02"/></geometry>
      <material name="steel"/>
    </visual>
    <visual name="wrist_3_marker">
      <origin xyz="0.026 0 0.01"/>
      <geometry><box size="0.012 0.008 0.022"/></geometry>
      <material name="signal_blue"/>
    </visual>
  </link>

  <link name="tool_flange">
    <visual name="flange_disc">
      <origin xyz="0 0 0.004"/>
      <geometry><cylinder radius="0.035" length="0.008"/></geometry>
      <material name="dark_grey"/>
    </visual>
    <visual name="flange_palm">
      <origin xyz="0 0 0.018"/>
      <geometry><box size="0.03 0.07 0.02"/></geometry>
      <material name="steel"/>
    </visual>
  </link>

  <link name="finger_left">
    <visual>
      <origin xyz="0 0.005 0.02"/>
      <geometry><box size="0.02 0.01 0.04"/></geometry>
      <material name="dark_grey"/>
    </visual>
  </link>

  <link name="finger_right">
    <visual>
      <origin xyz="0 -0.005 0.02"/>
      <geometry><box size="0.02 0.01 0.04"/></geometry>
      <material name="dark_grey"/>
    </visual>
  </link>

  <joint name="joint_1" type="revolute">
    <parent link="base_link"/>
    <child link="shoulder_link"/>
    <origin xyz="0 0 0.06"/>
    <axis xyz="0 0 1"/>
    <limit lower="-3.14159" upper="3.14159" effort="150" velocity="2.0"/>
  </joint>

  <joint name="joint_2" type="revolute">
    <parent link="shoulder_link"/>
    <child link="upper_arm_link"/>
    <origin xyz="0 0 0.10"/>
    <axis xyz="0 1 0"/>
    <limit lower="-1.8" upper="1.8" effort="150" velocity="2.0"/>
  </joint>

  <joint name="joint_3" type="revolute">
    <parent link="upper_arm_link"/>
    <child link="elbow_link"/>
    <origin xyz="0 0 0.30"/>
    <axis xyz="0 1 0"/>
    <limit lower="-2.4" upper="2.4" effort="100" velocity="2.5"/>
  </joint>

  <joint name="elbow_to_forearm" type="fixed">
    <parent link="elbow_link"/>
    <child link="forearm_link"/>
    <origin xyz="0 0 0.03"/>
  </joint>

  <joint name="joint_4" type="revolute">
    <parent link="forearm_link"/>
    <child link="wrist_1_link"/>
    <origin xyz="0 0 0.30"/>
    <axis xyz="0 0 1"/>
    <limit lower="-3.14159" upper="3.14159" effort="30" velocity="3.0"/>
  </joint>

  <joint name="joint_5" type="revolute">
    <parent link="wrist_1_link"/>
    <child link="wrist_2_link"/>
    <origin xyz="0 0 0.035"/>
    <axis xyz="0 1 0"/>
    <limit lower="-2.0" upper="2.0" effort="30" velocity="3.0"/>
  </joint>

  <joint name="joint_6" type="revolute">
    <parent link="wrist_2_link"/>
    <child link="wrist_3_link"/>
    <origin xyz="0 0 0.06"/>
    <axis xyz="0 0 1"/>
    <limit lower="-3.14159" upper="3.14159" effort="30" velocity="3.0"/>
  </joint>

  <joint name="flange" type="fixed">
    <parent link="wrist_3_link"/>
    <child link="tool_flange"/>
    <origin xyz="0 0 0.02"/>
  </joint>

  <joint name="finger_left_joint" type="prismatic">
    <parent link="tool_flange"/>
    <child link="finger_left"/>
    <origin xyz="0 0.002 0.028"/>
    <axis xyz="0 1 0"/>
    <limit lower="0.0" upper="0.025" effort="20" velocity="0.1"/>
  </joint>

  <joint name="finger_right_joint" type="prismatic">
    <parent link="tool_flange"/>
    <child link="finger_right"/>
    <origin xyz="0 -0.002 0.028"/>
    <axis xyz="0 -1 0"/>
    <limit lower="0.0" upper="0.025" effort="20" velocity="0.1"/>
    <mimic joint="finger_left_joint" multiplier="1.0" offset="0.0"/>
  </joint>
</robot>
"""
