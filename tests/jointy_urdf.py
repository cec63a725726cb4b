"""A small URDF for joint tests: revolute, continuous and prismatic joints with limits, a
prismatic mimic of the prismatic one (multiplier 0.5), no meshes (loads anywhere)."""

JOINTY_URDF = """<robot name="jointy">
  <link name="base"/><link name="a"/><link name="b"/><link name="c"/><link name="d"/>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="a"/>
    <axis xyz="0 0 1"/><limit lower="-1.5" upper="1.5" effort="10" velocity="2"/></joint>
  <joint name="spin" type="continuous"><parent link="a"/><child link="b"/>
    <axis xyz="0 0 1"/></joint>
  <joint name="slide" type="prismatic"><parent link="b"/><child link="c"/>
    <axis xyz="1 0 0"/><limit lower="0" upper="0.04" effort="5" velocity="0.1"/></joint>
  <joint name="twin" type="prismatic"><parent link="c"/><child link="d"/>
    <axis xyz="1 0 0"/><limit lower="0" upper="0.02" effort="5" velocity="0.1"/>
    <mimic joint="slide" multiplier="0.5" offset="0"/></joint>
</robot>"""
