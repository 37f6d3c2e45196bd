"""What a URDF file gives the robot model besides its dynamics: the initial configuration inside
the joint limits, and the links' visual geometry (``<visual>``: box, cylinder, sphere, mesh,
their origins and colours) kept as data; their refusals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import cmbs
from cmbs.errors import ModelError

INERTIAL = '<inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial>'
LIMITED = f"""<robot name="limited">
  <link name="base"/>
  <link name="a">{INERTIAL}</link>
  <link name="b">{INERTIAL}</link>
  <link name="c">{INERTIAL}</link>
  <link name="d">{INERTIAL}</link>
  <link name="e">{INERTIAL}</link>
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


SHAPES = f"""<robot name="shapes">
  <material name="teal"><color rgba="0 0.5 0.5 1"/></material>
  <link name="base">
    <visual><origin xyz="0 0 -0.05"/><geometry><box size="0.4 0.3 0.1"/></geometry>
      <material name="grey"><color rgba="0.5 0.5 0.5 1"/></material></visual>
  </link>
  <link name="arm">{INERTIAL}
    <visual><origin xyz="0 0 0.25" rpy="0 1.5707963267948966 0"/>
      <geometry><cylinder radius="0.05" length="0.5"/></geometry><material name="teal"/></visual>
    <visual><origin xyz="0.1 0.2 0.3"/><geometry><sphere radius="0.08"/></geometry></visual>
    <collision><geometry><box size="1 1 1"/></geometry></collision>
  </link>
  <link name="hand">
    <visual><origin xyz="0 0 0.02" rpy="0.1 0.2 0.3"/>
      <geometry><mesh filename="meshes/hand.stl" scale="0.001 0.002 0.003"/></geometry></visual>
    <visual><geometry><mesh filename="package://nowhere/hand.dae" scale="2"/></geometry>
      <material name="unknown"/></visual>
  </link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="10" velocity="1"/></joint>
  <joint name="wrist" type="fixed"><parent link="arm"/><child link="hand"/><origin xyz="0 0 0.5"/></joint>
</robot>
"""


def rpy(roll: float, pitch: float, yaw: float, xyz=(0.0, 0.0, 0.0)) -> np.ndarray:
    """URDF's origin Trans(xyz) Rz(yaw) Ry(pitch) Rx(roll), written out here."""
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    transform = np.eye(4)
    z = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    y = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    x = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    transform[:3, :3] = z @ y @ x
    transform[:3, 3] = xyz
    return transform


def test_the_visuals_are_read_as_data(tmp_path: Path) -> None:
    """Every <visual> of every link, in the link frame, in the file's order: shape, size (a mesh's
    scale, one number for three), origin, colour (its own, the top-level material of its name,
    or None) and a mesh's file resolved relative to the URDF (kept as written when not found);
    collisions are not visuals."""
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "hand.stl").write_text("solid empty\nendsolid empty\n")
    path = tmp_path / "shapes.urdf"
    path.write_text(SHAPES)
    visuals = cmbs.load(path).parameters["visuals"]
    assert list(visuals) == ["base", "arm", "hand"]
    expected = {
        "base": [("box", (0.4, 0.3, 0.1), rpy(0, 0, 0, (0, 0, -0.05)), (0.5, 0.5, 0.5, 1.0), None)],
        "arm": [("cylinder", (0.05, 0.5), rpy(0, np.pi / 2, 0, (0, 0, 0.25)), (0.0, 0.5, 0.5, 1.0), None),
                ("sphere", (0.08,), rpy(0, 0, 0, (0.1, 0.2, 0.3)), None, None)],
        "hand": [("mesh", (0.001, 0.002, 0.003), rpy(0.1, 0.2, 0.3, (0, 0, 0.02)), None,
                  str(tmp_path / "meshes" / "hand.stl")),
                 ("mesh", (2.0, 2.0, 2.0), np.eye(4), None, "package://nowhere/hand.dae")]}
    for link, items in expected.items():
        assert len(visuals[link]) == len(items)
        for visual, (shape, size, origin, rgba, filename) in zip(visuals[link], items):
            assert (visual.shape, visual.size, visual.rgba, visual.filename) == (shape, size, rgba, filename)
            np.testing.assert_allclose(visual.origin, origin, rtol=0, atol=1e-15)


@pytest.mark.parametrize("change, message", [
    ('<sphere radius="0.08"/>', r"link 'arm': <sphere radius='0\.8 m'>: expected 1 number$"),
    ('<box size="0.4 0.3 0.1"/>', r"link 'base': <box size='0\.4 0\.3'>: expected 3 numbers$"),
    ('scale="2"', r"link 'hand': <mesh scale='2 2'>: expected 1 or 3 numbers$"),
    ('<color rgba="0 0.5 0.5 1"/>', r"material 'teal': <color rgba='0 0\.5 0\.5'>: expected 4 numbers$"),
])
def test_visual_numbers_that_are_not_numbers_are_refused(tmp_path: Path, change: str, message: str) -> None:
    bad = {'<sphere radius="0.08"/>': '<sphere radius="0.8 m"/>', 'scale="2"': 'scale="2 2"',
           '<box size="0.4 0.3 0.1"/>': '<box size="0.4 0.3"/>',
           '<color rgba="0 0.5 0.5 1"/>': '<color rgba="0 0.5 0.5"/>'}[change]
    path = tmp_path / "shapes.urdf"
    path.write_text(SHAPES.replace(change, bad))
    with pytest.raises(ModelError, match=r"shapes\.urdf: " + message):
        cmbs.load(path)


@pytest.mark.parametrize("change, bad, message", [
    ('<sphere radius="0.08"/>', '<sphere radius="-0.08"/>',
     r"link 'arm' visual 2: sphere size must be >= 0, got \[-0\.08\]"),
    ('rgba="0.5 0.5 0.5 1"', 'rgba="0.5 0.5 1.5 1"',
     r"link 'base' visual 1: colour rgba must be 4 numbers in \[0, 1\], got \[0\.5, 0\.5, 1\.5, 1\.0\]"),
    ('scale="2"', 'scale="0"', r"link 'hand' visual 2: mesh scale must be nonzero, got \[0\.0, 0\.0, 0\.0\]"),
    ('<sphere radius="0.08"/>', '', r"link 'arm': <visual> 2: its <geometry> must hold one of box, cylinder, sphere, "
                                   r"mesh"),
    ('<box size="0.4 0.3 0.1"/>', '<box size="0.4 0.3 0.1"/><sphere radius="1"/>',
     r"link 'base': <visual> 1: its <geometry> must hold one of box, cylinder, sphere, mesh"),
    ('filename="meshes/hand.stl"', '', r"link 'hand': <visual> 1: <mesh> without a filename"),
])
def test_visuals_that_are_no_shapes_are_refused(tmp_path: Path, change: str, bad: str, message: str) -> None:
    path = tmp_path / "shapes.urdf"
    path.write_text(SHAPES.replace(change, bad))
    with pytest.raises(ModelError, match=r"shapes\.urdf: " + message + "$"):
        cmbs.load(path)
