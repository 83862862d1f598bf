"""A 6R arm on a linear track: the prismatic joint the tests of the kinematics and of
the twin's physics share (a URDF, for ``import_urdf``)."""

#: A UR10-sized arm on a 3 m track along the cell's x axis, slightly tilted.
TRACK_ROBOT = """<robot name="track_ur">
  <link name="floor"/><link name="carriage"><inertial><mass value="40"/>
    <origin xyz="0 0 0.1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>
  </link>
  <link name="l1"><inertial><mass value="7"/><origin xyz="0 0 0.05"/>
    <inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <link name="l2"><inertial><mass value="12"/><origin xyz="-0.3 0 0.1"/>
    <inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <link name="l3"><inertial><mass value="4"/><origin xyz="-0.28 0 0.02"/>
    <inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <link name="l4"/><link name="l5"/><link name="l6"/><link name="tool0"/>
  <joint name="track" type="prismatic"><parent link="floor"/><child link="carriage"/>
    <origin xyz="0 0.2 0.3" rpy="0.001 -0.002 0"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j1" type="revolute"><parent link="carriage"/><child link="l1"/>
    <origin xyz="0 0 0.1273" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-6.28" upper="6.28" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0 0" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-6.28" upper="6.28" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="-0.612 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3.14" upper="3.14" effort="1" velocity="1"/></joint>
  <joint name="j4" type="revolute"><parent link="l3"/><child link="l4"/>
    <origin xyz="-0.5723 0 0.163941" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-6.28" upper="6.28" effort="1" velocity="1"/></joint>
  <joint name="j5" type="revolute"><parent link="l4"/><child link="l5"/>
    <origin xyz="0 -0.1157 0" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-6.28" upper="6.28" effort="1" velocity="1"/></joint>
  <joint name="j6" type="revolute"><parent link="l5"/><child link="l6"/>
    <origin xyz="0 0.0922 0" rpy="-1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-6.28" upper="6.28" effort="1" velocity="1"/></joint>
  <joint name="l6-tool0" type="fixed"><parent link="l6"/><child link="tool0"/>
    <origin xyz="0 0 0" rpy="0 0 0"/></joint>
</robot>
"""
