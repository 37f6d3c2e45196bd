"""Link poses of robots (cmbs.kinematics.body_poses on a URDF model) and their columns in result
files, along a short UR5 swing: against frame_placement, against Pinocchio's
framesForwardKinematics (oMf), and the quaternion columns against scipy's conversion of the
rotations; the HTML viewer's stick figure of the link origins."""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ElementTree

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import cmbs
from helpers import example_robots
from cmbs.cli import main
from cmbs.kinematics import POSE_COLUMNS, body_poses
from cmbs.model.robot import frame_placement

try:
    import pinocchio
except ImportError:
    pinocchio = None


UR5 = None if example_robots() is None else example_robots() / "ur_description/urdf/ur5_robot.urdf"
pytestmark = pytest.mark.skipif(UR5 is None, reason="needs example-robot-data (the UR5 URDF)")
#: the UR5's links that do not move: the root and the links fixed to it
GROUND_LINKS = {"world", "base_link", "base"}


@pytest.fixture(scope="module")
def swing():
    """The UR5 from q = 0.3 (every joint) with q̇ = 1 rad/s, 0.3 s under gravity: 31 states."""
    model = cmbs.load(UR5)
    run = cmbs.simulate(model, t_end=0.3, dt=0.01, q0=np.full(6, 0.3), qd0=np.ones(6), integrator="dop853",
                        rtol=1e-10, atol=1e-12)
    assert run.info["status"] == "success"
    return model, run


def test_the_bodies_are_the_moving_links(swing):
    model, _ = swing
    bodies = model.equations.bodies
    assert set(bodies) == set(model.point_names) - GROUND_LINKS
    assert list(bodies) == [link for link in model.point_names if link in bodies]      # the links' order
    assert {"shoulder_link", "wrist_3_link", "tool0", "ee_link"} <= set(bodies)          # fixed to moving ones too


def test_link_poses_are_the_frame_placements(swing):
    """Each moving link's origin and rotation at every state equal frame_placement's."""
    model, run = swing
    poses = body_poses(model, run.q)
    assert poses.names == model.equations.bodies
    assert poses.origins.shape == (run.t.size, len(poses.names), 3)
    assert poses.rotations.shape == (run.t.size, len(poses.names), 3, 3)
    for k, q in enumerate(run.q):
        for b, link in enumerate(poses.names):
            rotation, origin = frame_placement(model, q, link)
            assert np.array_equal(poses.rotations[k, b], rotation) and np.array_equal(poses.origins[k, b], origin)
    single = body_poses(model, run.q[7])
    assert np.array_equal(single.rotations, poses.rotations[7]) and np.array_equal(single.origins, poses.origins[7])
    broken = run.q[:3].copy()
    broken[1, 2] = np.nan
    partial = body_poses(model, broken)
    assert np.all(np.isnan(partial.origins[1])) and np.all(np.isnan(partial.quaternions[1]))
    assert np.array_equal(partial.origins[[0, 2]], poses.origins[[0, 2]])


@pytest.mark.skipif(pinocchio is None, reason="needs pinocchio (pip 'pin')")
def test_link_poses_match_pinocchio(swing):
    """oMf of every link frame (Pinocchio BODY frames) along the run, rotation and translation,
    to 1e-12; a point p in link coordinates is at o + R p, Pinocchio's oMf.act(p)."""
    model, run = swing
    reference = pinocchio.buildModelFromUrdf(str(UR5))
    data = reference.createData()
    poses = body_poses(model, run.q)
    point = np.array([0.1, -0.2, 0.3])
    worst = 0.0
    for k, q in enumerate(run.q):
        pinocchio.framesForwardKinematics(reference, data, q)
        for b, link in enumerate(poses.names):
            placement = data.oMf[reference.getFrameId(link, pinocchio.BODY)]
            worst = max(worst, np.abs(poses.rotations[k, b] - placement.rotation).max(),
                        np.abs(poses.origins[k, b] - placement.translation).max(),
                        np.abs(poses.origins[k, b] + poses.rotations[k, b] @ point - placement.act(point)).max())
    print(f"UR5 link poses vs Pinocchio oMf over {run.t.size} states: worst {worst:.1e}")
    assert worst < 1e-12


def test_result_file_has_link_origins_and_quaternions(swing, tmp_path):
    """`cmbs simulate robot.urdf --out run.npz` writes seven columns per moving link; the
    quaternion columns (scalar first) are scipy's conversion of the link rotations up to the
    sign, the origins the frame placements."""
    model, _ = swing
    out = tmp_path / "run.npz"
    assert main(["simulate", str(UR5), "--t-end", "0.2", "--dt", "0.02", "--integrator", "dop853",
                 "--out", str(out)]) == 0
    run = cmbs.Trajectory.load(out)
    for link in GROUND_LINKS:
        assert f"{link}.qw" not in run.extras
    worst = 0.0
    for link in model.equations.bodies:
        origin = np.stack([run[f"{link}.origin.{axis}"] for axis in "xyz"], axis=1)
        quaternion = np.stack([run[f"{link}.{name}"] for name in ("qw", "qx", "qy", "qz")], axis=1)
        rotations = np.array([frame_placement(model, q, link)[0] for q in run.q])
        origins = np.array([frame_placement(model, q, link)[1] for q in run.q])
        expected = Rotation.from_matrix(rotations).as_quat()[:, [3, 0, 1, 2]]
        sign = np.sign(np.einsum("ki,ki->k", quaternion, expected))
        assert np.all(sign != 0)
        worst = max(worst, np.abs(quaternion - sign[:, None] * expected).max(), np.abs(origin - origins).max())
        assert np.all(np.einsum("ki,ki->k", quaternion[1:], quaternion[:-1]) > 0)       # continuous sign
    assert worst < 1e-12
    assert POSE_COLUMNS == ("origin.x", "origin.y", "origin.z", "qw", "qx", "qy", "qz")


@pytest.mark.skipif(pinocchio is None, reason="needs pinocchio (pip 'pin')")
def test_the_viewer_draws_the_links_as_a_stick_figure(tmp_path):
    """`cmbs simulate FILE --animate x.html` on a robot file with gravity along -y: the embedded
    JSON has the URDF's links as points, its joints (parent, child) as lines, the origins that do
    not move as ground, "up" against gravity, and each frame the link origins (Pinocchio's
    oMf translations at the states interpolated at the frame times, within half the unit)."""
    robot = tmp_path / "ur5-sideways.toml"
    robot.write_text(f'[model]\nurdf = {str(UR5)!r}\ngravity = [0.0, -9.81, 0.0]\n\n[initial_velocities]\n'
                     'shoulder_pan_joint = 1.0\nelbow_joint = -1.0\n')
    page, out = tmp_path / "ur5.html", tmp_path / "ur5.npz"
    assert main(["simulate", str(robot), "--t-end", "0.5", "--dt", "0.01", "--integrator", "dop853", "--out",
                 str(out), "--animate", str(page)]) == 0
    run = cmbs.Trajectory.load(out)
    found = re.findall(r'<script id="cmbs-data" type="application/json">(.*?)</script>',
                       page.read_text(encoding="utf-8"), re.DOTALL)
    assert len(found) == 1
    data = json.loads(found[0])
    urdf = ElementTree.parse(UR5).getroot()
    links = [link.get("name") for link in urdf.findall("link")]
    assert data["points"] == links and data["planar"] is False
    pairs = {(joint.find("parent").get("link"), joint.find("child").get("link")) for joint in urdf.findall("joint")}
    assert {(links[i], links[j]) for i, j in data["lines"]} == pairs and len(data["lines"]) == len(pairs)
    # the viewer's ground points are those whose position does not move: the links fixed to the
    # root and the shoulder link, whose origin is on the shoulder pan axis
    assert {link for link, ground in zip(links, data["ground"]) if ground} == GROUND_LINKS | {"shoulder_link"}
    assert data["up"] == [0.0, 1.0, 0.0]
    times = np.array(data["times"])
    assert times[0] == 0.0 and times[-1] == pytest.approx(0.5)
    reference = pinocchio.buildModelFromUrdf(str(UR5))
    pin_data = reference.createData()
    frames = np.array(data["frames"], dtype=float).reshape(len(times), len(links), 3) * data["unit"]
    columns = [run.names.index(name) for name in reference.names[1:]]
    worst = 0.0
    for k, t in enumerate(times):
        q = np.array([np.interp(t, run.t, run.q[:, c]) for c in columns])
        pinocchio.framesForwardKinematics(reference, pin_data, q)
        origins = np.array([pin_data.oMf[reference.getFrameId(link, pinocchio.BODY)].translation for link in links])
        worst = max(worst, np.abs(frames[k] - origins).max())
    assert worst <= 0.5 * data["unit"] + 1e-12
    assert np.ptp(frames[:, links.index("tool0")], axis=0).max() > 0.05             # the arm moves
