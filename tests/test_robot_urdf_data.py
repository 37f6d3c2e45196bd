"""What a URDF file gives the robot model besides its dynamics: the initial configuration inside
the joint limits, and the links' visual geometry (``<visual>``: box, cylinder, sphere, mesh,
their origins and colours) kept as data; their refusals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import cmbs
from cmbs.errors import ModelError

LIMITED = """<robot name="limited">
  <link name="base"/>
  <link name="a"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="b"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="c"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="d"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="e"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="above" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/>
    <limit lower="0.4" upper="1.2" effort="10" velocity="1"/></joint>
  <joint name="below" type="prismatic"><parent link="a"/><child link="b"/><axis xyz="1 0 0"/>
    <limit lower="-0.5" upper="-0.1" effort="10" velocity="1"/></joint>
  <joint name="around" type="revolute"><parent link="b"/><child link="c"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="10" velocity="1"/></joint>
  <joint name="open" type="revolute"><parent link="c"/><child link="d"/><axis xyz="0 1 0"/>
    <limit lower="0.3" effort="10" velocity="1"/></joint>
  <joint name="free" type="continuous"><parent link="d"/><child link="e"/><axis xyz="0 1 0"/>
    <limit lower="0.3" upper="0.5" effort="10" velocity="1"/></joint>
</robot>
"""


def test_the_initial_configuration_is_inside_the_joint_limits(tmp_path: Path) -> None:
    """q0 is the value nearest 0 within each joint's limits: the lower limit when it is above 0,
    the upper when it is below 0 (a prismatic joint too), 0 between them; a lone lower limit
    bounds from below only; a continuous joint has no limits (URDF ignores its lower and
    upper)."""
    path = tmp_path / "limited.urdf"
    path.write_text(LIMITED)
    model = cmbs.load(path)
    assert model.coordinate_names == ("above", "below", "around", "open", "free")
    assert model.q0.tolist() == [0.4, -0.1, 0.0, 0.3, 0.0]
    assert model.qd0.tolist() == [0.0] * 5


def test_limits_that_exclude_every_value_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "crossed.urdf"
    path.write_text(LIMITED.replace('lower="-1" upper="1"', 'lower="1" upper="-1"'))
    with pytest.raises(ModelError, match=r"crossed\.urdf: joint 'around': limit lower 1 > upper -1$"):
        cmbs.load(path)
