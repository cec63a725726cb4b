"""A 7-joint arm for the motion tests, written for this project: the kinematic chain of a
Franka Panda (its published joint origins and limits), with the hand's two fingers (one a
mimic of the other) and simple collision shapes (cylinders, spheres, boxes) on each link.
No meshes: it loads anywhere."""

SEVEN_DOF_URDF = """<?xml version="1.0"?>
<robot name="seven_dof_arm">
  <link name="link0">
    <collision><origin xyz="0 0 0.05"/>
      <geometry><cylinder radius="0.09" length="0.1"/></geometry></collision>
  </link>
  <link name="link1">
    <collision><origin xyz="0 0 -0.17"/>
      <geometry><cylinder radius="0.06" length="0.2"/></geometry></collision>
  </link>
  <link name="link2">
    <collision><geometry><sphere radius="0.06"/></geometry></collision>
  </link>
  <link name="link3">
    <collision><origin xyz="0 0 -0.1"/>
      <geometry><cylinder radius="0.06" length="0.15"/></geometry></collision>
  </link>
  <link name="link4">
    <collision><geometry><sphere radius="0.06"/></geometry></collision>
  </link>
  <link name="link5">
    <collision><origin xyz="0 0 -0.14"/>
      <geometry><cylinder radius="0.05" length="0.2"/></geometry></collision>
  </link>
  <link name="link6">
    <collision><geometry><sphere radius="0.05"/></geometry></collision>
  </link>
  <link name="link7">
    <collision><origin xyz="0 0 0.05"/>
      <geometry><cylinder radius="0.04" length="0.08"/></geometry></collision>
  </link>
  <link name="flange"/>
  <link name="hand">
    <collision><origin xyz="0 0 0.03"/>
      <geometry><box size="0.05 0.2 0.06"/></geometry></collision>
  </link>
  <link name="left_finger">
    <collision><origin xyz="0 0.01 0.03"/>
      <geometry><box size="0.02 0.02 0.05"/></geometry></collision>
  </link>
  <link name="right_finger">
    <collision><origin xyz="0 -0.01 0.03"/>
      <geometry><box size="0.02 0.02 0.05"/></geometry></collision>
  </link>
  <link name="tcp"/>

  <joint name="joint1" type="revolute">
    <parent link="link0"/><child link="link1"/><origin xyz="0 0 0.333"/><axis xyz="0 0 1"/>
    <limit lower="-2.8973" upper="2.8973" effort="87" velocity="2.175"/>
  </joint>
  <joint name="joint2" type="revolute">
    <parent link="link1"/><child link="link2"/><origin rpy="-1.5707963267948966 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-1.7628" upper="1.7628" effort="87" velocity="2.175"/>
  </joint>
  <joint name="joint3" type="revolute">
    <parent link="link2"/><child link="link3"/>
    <origin xyz="0 -0.316 0" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2.8973" upper="2.8973" effort="87" velocity="2.175"/>
  </joint>
  <joint name="joint4" type="revolute">
    <parent link="link3"/><child link="link4"/>
    <origin xyz="0.0825 0 0" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3.0718" upper="-0.0698" effort="87" velocity="2.175"/>
  </joint>
  <joint name="joint5" type="revolute">
    <parent link="link4"/><child link="link5"/>
    <origin xyz="-0.0825 0.384 0" rpy="-1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2.8973" upper="2.8973" effort="12" velocity="2.61"/>
  </joint>
  <joint name="joint6" type="revolute">
    <parent link="link5"/><child link="link6"/><origin rpy="1.5707963267948966 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-0.0175" upper="3.7525" effort="12" velocity="2.61"/>
  </joint>
  <joint name="joint7" type="revolute">
    <parent link="link6"/><child link="link7"/>
    <origin xyz="0.088 0 0" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2.8973" upper="2.8973" effort="12" velocity="2.61"/>
  </joint>
  <joint name="flange_mount" type="fixed">
    <parent link="link7"/><child link="flange"/><origin xyz="0 0 0.107"/>
  </joint>
  <joint name="hand_mount" type="fixed">
    <parent link="flange"/><child link="hand"/><origin rpy="0 0 -0.7853981633974483"/>
  </joint>
  <joint name="finger_joint1" type="prismatic">
    <parent link="hand"/><child link="left_finger"/><origin xyz="0 0 0.0584"/>
    <axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="20" velocity="0.2"/>
  </joint>
  <joint name="finger_joint2" type="prismatic">
    <parent link="hand"/><child link="right_finger"/><origin xyz="0 0 0.0584"/>
    <axis xyz="0 -1 0"/><limit lower="0" upper="0.04" effort="20" velocity="0.2"/>
    <mimic joint="finger_joint1"/>
  </joint>
  <joint name="tcp_mount" type="fixed">
    <parent link="hand"/><child link="tcp"/><origin xyz="0 0 0.1034"/>
  </joint>
</robot>
"""
