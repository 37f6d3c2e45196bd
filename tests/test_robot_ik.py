"""Inverse kinematics of robots by pose drivers (docs/robots.md, "Inverse kinematics"): the rows'
A, Φ_t and γ against finite differences, the UR5 and the Panda of example-robot-data brought to
poses Pinocchio computes (``framesForwardKinematics``, ``oMf``), a moving target followed by
kinematic analysis, and the errors: a target out of reach, a spurious orientation root, bad
entries in a robot file.

The assemblies and analyses evaluate the compiled robot kernel from Python (no compiled loop)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import cmbs
from cmbs.model.robot import PoseDriver, frame_placement
from cmbs.model.urdf import load_urdf
from helpers import first_derivative_fd, jacobian_fd, second_derivative_fd, SmoothPath
from test_robot import ROBOTS, URDFS, needs_pinocchio, pinocchio
from test_robot_closures import UR5_JOINTS, _made_up_tree

DOCS = Path(__file__).resolve().parents[1] / "docs" / "robots.md"
#: a tool point on the UR5's flange frame (m)
TOOL_POINT = np.array([0.02, -0.01, 0.1])


# ------------------------------------------------------------------ the rows against finite differences
@pytest.mark.parametrize("parts", ["pose", "position", "orientation"])
def test_pose_driver_rows_against_finite_differences(parts):
    """A = ∂Φ/∂q, Φ_t = ∂Φ/∂t and γ = A q̈ - d²Φ/dt² against central differences (A step 1e-6,
    Φ_t four-point, d²Φ/dt² five-point along smooth random motions) at 5 random states of the
    made-up tree, for a target moving in position and orientation on a point of a link of the
    second branch (a fixed joint between its joints), and Φ is the geometry: p - p_t and the
    weld rows y·z_t, z·x_t, x·y_t of the link frame and the target's."""
    position = ("0.3 + 0.1*sin(2*t)", "0.2*cos(t)", "0.1*t*t") if parts != "orientation" else None
    rpy = ("0.2*sin(t)", "0.5 + 0.3*t", "cos(1.5*t)") if parts != "position" else None
    point = (0.1, -0.2, 0.3)
    model = _made_up_tree([], [PoseDriver("tool", "l4", point, position, rpy)])
    rng = np.random.default_rng(3)
    worst = np.zeros(3)
    for _ in range(5):
        path = SmoothPath(rng.uniform(-1.0, 1.0, model.n), rng, 0.5)
        t = float(rng.uniform(0.0, 2.0))
        q, qd, qdd = path.q(t), path.qd(t), path.qdd(t)
        A = model.jacobian(q, t)
        worst[0] = max(worst[0], np.abs(A - jacobian_fd(model, q, t)).max())
        worst[1] = max(worst[1], np.abs(model.constraints_t(q, t)
                                        - first_derivative_fd(lambda s: model.constraints(q, s), t)).max())
        gamma = A @ qdd - second_derivative_fd(lambda s: model.constraints(path.q(s), s), t)
        worst[2] = max(worst[2], np.abs(model.gamma(q, qd, t) - gamma).max())
    assert np.all(worst < [1e-8, 1e-9, 1e-6]), worst              # measured 1.5e-10, 2.1e-12, 7.7e-10
    R, o = frame_placement(model, q, "l4")
    expected = []
    if position is not None:
        expected += list(o + R @ point - [0.3 + 0.1 * np.sin(2 * t), 0.2 * np.cos(t), 0.1 * t * t])
    if rpy is not None:
        from cmbs.model.robot_closures import rpy_rotation

        target = rpy_rotation([0.2 * np.sin(t), 0.5 + 0.3 * t, np.cos(1.5 * t)])
        expected += [R[:, 1] @ target[:, 2], R[:, 2] @ target[:, 0], R[:, 0] @ target[:, 1]]
    np.testing.assert_allclose(model.constraints(q, t), expected, atol=1e-15)
    assert model.constraint_names == PoseDriver("tool", "l4", point, position, rpy).row_names
    assert model.drivers.all()


# ------------------------------------------------------------------ inverse kinematics against Pinocchio
def _pinocchio_pose(urdf: Path, frame: str, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pinocchio's world rotation and origin of ``frame`` at q (framesForwardKinematics, oMf)."""
    model = pinocchio.buildModelFromUrdf(str(urdf))
    data = model.createData()
    pinocchio.framesForwardKinematics(model, data, q)
    placement = data.oMf[model.getFrameId(frame)]
    return placement.rotation.copy(), placement.translation.copy()


def _numbers(values) -> str:
    return ", ".join(repr(float(v)) for v in values)


def _ur5_pose_file(folder: Path, position, rpy, start: np.ndarray) -> Path:
    """A robot file driving the UR5's tool point (TOOL_POINT on tool0) to ``position`` and the
    flange frame to ``rpy`` (lists of numbers or expressions), assembly starting from ``start``."""
    def listed(values):
        return ", ".join(f'"{v}"' if isinstance(v, str) else repr(float(v)) for v in values)

    path = folder / "ur5-ik.toml"
    path.write_text(f'[model]\nurdf = "{ROBOTS / URDFS["ur5"]}"\n\n[drivers.tool]\nkind = "pose"\nlink = "tool0"\n'
                    f'point = [{_numbers(TOOL_POINT)}]\nposition = [{listed(position)}]\nrpy = [{listed(rpy)}]\n\n'
                    "[initial_positions]\n" + "".join(f"{name} = {value!r}\n"
                                                       for name, value in zip(UR5_JOINTS, start.tolist())))
    return path


@needs_pinocchio
def test_ur5_inverse_kinematics_reaches_pinocchios_pose(tmp_path):
    """For 3 random joint vectors q*, the pose of the UR5's tool (Pinocchio's oMf of tool0, the
    tool point oMf.act(p)) as a pose driver's constant target in a robot file; loading assembles
    from q* + 0.1 rad per joint: the tool's pose at the solution, by Pinocchio, is the target to
    1e-10 (measured 4.3e-14 m and 3.4e-13 in the rotation matrix: assembly stops at residuals
    below 1e-12 of the size), and the solution is q* (6 DOF, near guess) to 1e-9 (measured
    4.7e-13); DOF 0."""
    urdf = ROBOTS / URDFS["ur5"]
    rng = np.random.default_rng(11)
    for _ in range(3):
        target = rng.uniform(-2.5, 2.5, 6)
        rotation, origin = _pinocchio_pose(urdf, "tool0", target)
        rpy = pinocchio.rpy.matrixToRpy(rotation)
        model = cmbs.load(_ur5_pose_file(tmp_path, origin + rotation @ TOOL_POINT, rpy, target + 0.1))
        assert model.constraint_names == ("tool.x", "tool.y", "tool.z", "tool.rx", "tool.ry", "tool.rz")
        assert cmbs.constraint_report(model, model.q0).dof == 0
        reached_rotation, reached_origin = _pinocchio_pose(urdf, "tool0", model.q0)
        assert np.abs(reached_origin + reached_rotation @ TOOL_POINT - origin - rotation @ TOOL_POINT).max() < 1e-10
        assert np.abs(reached_rotation - rotation).max() < 1e-10
        assert np.abs(model.q0 - target).max() < 1e-9


@needs_pinocchio
def test_panda_inverse_kinematics_of_a_redundant_arm(tmp_path):
    """The Panda (7 arm joints and 2 finger joints, 9 coordinates) with its hand's pose driven to
    Pinocchio's pose of panda_hand at a random q* (3 times): ``cmbs.assemble`` from q* plus up to
    0.2 rad per joint reaches the pose to 1e-10 (Pinocchio at the solution; measured 1.3e-14 m,
    1.7e-13), with 3 DOF left (the elbow's self-motion and the fingers): q is up to 0.2 rad from q*."""
    urdf = ROBOTS / URDFS["panda"]
    rng = np.random.default_rng(5)
    for _ in range(3):
        target = np.concatenate([rng.uniform(-1.5, 1.5, 7), [0.02, 0.02]])
        rotation, origin = _pinocchio_pose(urdf, "panda_hand", target)
        driver = PoseDriver("hand", "panda_hand", position=tuple(origin), rpy=tuple(pinocchio.rpy.matrixToRpy(rotation)))
        model = load_urdf(urdf, drivers=[driver])
        q = cmbs.assemble(model, target + rng.uniform(-0.2, 0.2, 9))
        assert cmbs.constraint_report(model, q).dof == 3
        reached_rotation, reached_origin = _pinocchio_pose(urdf, "panda_hand", q)
        assert np.abs(reached_origin - origin).max() < 1e-10 and np.abs(reached_rotation - rotation).max() < 1e-10


@needs_pinocchio
def test_panda_inverse_kinematics_within_its_joint_limits():
    """The Panda's hand driven to Pinocchio's pose at q* drawn within the URDF's joint limits (40
    times), assembly from q* plus up to 0.6 rad per arm joint: wherever Newton alone ends outside
    the limits (at least 4 times; at 150 rad once), the model loaded with ``joint_limits=True``
    reaches the pose to 1e-10 (Pinocchio at the solution; measured below 1e-15) with every joint
    within its limits (``Model.coordinate_limits``, bounded least squares in
    :func:`cmbs.assemble`)."""
    urdf = ROBOTS / URDFS["panda"]
    joints = load_urdf(urdf).equations.joints
    lower, upper = np.array([j.lower for j in joints]), np.array([j.upper for j in joints])
    rng = np.random.default_rng(3)
    outside = 0
    for _ in range(40):
        target = np.concatenate([rng.uniform(lower[:7] + 0.05, upper[:7] - 0.05), [0.02, 0.02]])
        rotation, origin = _pinocchio_pose(urdf, "panda_hand", target)
        driver = PoseDriver("hand", "panda_hand", position=tuple(origin), rpy=tuple(pinocchio.rpy.matrixToRpy(rotation)))
        guess = target + np.concatenate([rng.uniform(-0.6, 0.6, 7), [0.0, 0.0]])
        try:
            q = cmbs.assemble(load_urdf(urdf, drivers=[driver]), guess)
        except cmbs.ConvergenceError:
            continue
        if np.all((q >= lower) & (q <= upper)):
            continue
        outside += 1
        model = load_urdf(urdf, drivers=[driver], joint_limits=True)
        np.testing.assert_array_equal(model.coordinate_limits[0], lower)
        q = cmbs.assemble(model, guess)
        assert np.all((q >= lower) & (q <= upper))
        reached_rotation, reached_origin = _pinocchio_pose(urdf, "panda_hand", q)
        assert np.abs(reached_origin - origin).max() < 1e-10 and np.abs(reached_rotation - rotation).max() < 1e-10
    assert outside >= 4


def test_joint_limits_in_a_robot_file(tmp_path):
    """``[model] joint_limits = true`` gives the model the URDF's limits (continuous joints
    unlimited); a value that is not a boolean is a one-line error naming the field."""
    path = _ur5_pose_file(tmp_path, [0.3, 0.2, 0.4], [np.pi, 0.0, 0.3], np.array([0.2, -1.6, 1.4, -1.4, -1.6, -1.7]))
    text = path.read_text()
    path.write_text(text.replace("[model]\n", "[model]\njoint_limits = true\n"))
    model = cmbs.load(path)
    lower, upper = model.coordinate_limits
    expected = [(j.lower, j.upper) for j in model.equations.joints]
    assert [(float(a), float(b)) for a, b in zip(lower, upper)] == expected and np.all(np.isfinite(lower))
    assert np.all((model.q0 >= lower) & (model.q0 <= upper))
    path.write_text(text.replace("[model]\n", '[model]\njoint_limits = "yes"\n'))
    with pytest.raises(cmbs.ModelError) as error:
        cmbs.load(path)
    assert "model: joint_limits must be true or false, got 'yes'" in str(error.value)
    assert "\n" not in str(error.value)


#: the moving target: the tool point on a circle of radius 0.1 m about CENTRE in a horizontal
#: plane at 1 rad/s, the flange frame's orientation held at RPY
CENTRE, RADIUS, RPY = np.array([0.35, 0.2, 0.4]), 0.1, np.array([np.pi, 0.0, 0.3])


def _circle(t: np.ndarray) -> np.ndarray:
    return CENTRE + RADIUS * np.stack([np.cos(t), np.sin(t), np.zeros_like(t)], axis=-1)


def _circle_file(folder: Path) -> Path:
    """The UR5 robot file of the moving target, assembly starting near a configuration that
    reaches the circle's start (elbow up, wrist down)."""
    position = [f"{float(CENTRE[0])!r} + {RADIUS!r}*cos(t)", f"{float(CENTRE[1])!r} + {RADIUS!r}*sin(t)", float(CENTRE[2])]
    return _ur5_pose_file(folder, position, RPY, np.array([0.2, -1.6, 1.4, -1.4, -1.6, -1.7]))


@needs_pinocchio
def test_ur5_follows_a_moving_target_by_kinematic_analysis(tmp_path):
    """The tool point driven around a circle (1 rad/s), the orientation held: kinematic analysis
    over a full turn (25 instants) gives at every instant the pose by Pinocchio at q(t) to 1e-10
    (measured 2.2e-13 m, 3.8e-13), the tool point's velocity by Pinocchio's frame Jacobian times
    q̇ equal to the circle's (measured 7e-16 m/s), and q̈ the central difference of q̇ (step
    1e-4 s) to 1e-8 rad/s² (measured 3.5e-10; q̈ up to 0.18)."""
    urdf = ROBOTS / URDFS["ur5"]
    model = cmbs.load(_circle_file(tmp_path))
    times = np.linspace(0.0, 2.0 * np.pi, 25)
    motion = cmbs.kinematic_analysis(model, times)
    robot = pinocchio.buildModelFromUrdf(str(urdf))
    data = robot.createData()
    frame = robot.getFrameId("tool0")
    expected_rotation = cmbs.model.robot_closures.rpy_rotation(RPY)
    worst = np.zeros(3)
    for t, q, qd in zip(times, motion.q, motion.qd):
        pinocchio.computeJointJacobians(robot, data, q)
        pinocchio.framesForwardKinematics(robot, data, q)
        rotation, origin = data.oMf[frame].rotation, data.oMf[frame].translation
        J = pinocchio.getFrameJacobian(robot, data, frame, pinocchio.LOCAL_WORLD_ALIGNED)
        tool = origin + rotation @ TOOL_POINT
        velocity = J[:3] @ qd + np.cross(J[3:] @ qd, rotation @ TOOL_POINT)
        worst = np.maximum(worst, [np.abs(tool - _circle(t)).max(), np.abs(rotation - expected_rotation).max(),
                                   np.abs(velocity - RADIUS * np.array([-np.sin(t), np.cos(t), 0.0])).max()])
    assert np.all(worst < 1e-10), worst
    fine = cmbs.kinematic_analysis(model, np.array([1.0 - 1e-4, 1.0, 1.0 + 1e-4]), q0=motion.q[4])
    np.testing.assert_allclose(fine.qdd[1], (fine.qd[2] - fine.qd[0]) / 2e-4, atol=1e-8)


def test_the_documented_example_follows_its_circle(tmp_path):
    """docs/robots.md's pose-driver example (its urdf path made absolute) loads and, over a
    quarter turn, carries its tool point (0.1 m along tool0's z) around its circle to 1e-10 m
    with the flange's orientation held."""
    if ROBOTS is None:
        pytest.skip("needs example-robot-data")
    text = next(block.split("```")[0] for block in DOCS.read_text().split("```toml\n") if "[drivers.tool]" in block)
    path = tmp_path / "ur5-circle.toml"
    path.write_text(text.replace('urdf = "ur5_robot.urdf"', f'urdf = "{ROBOTS / URDFS["ur5"]}"'))
    model = cmbs.load(path)
    motion = cmbs.kinematic_analysis(model, np.linspace(0.0, np.pi / 2, 5))
    for t, q in zip(motion.t, motion.q):
        rotation, origin = frame_placement(model, q, "tool0")
        circle = [0.35 + 0.1 * np.cos(t), 0.2 + 0.1 * np.sin(t), 0.4]
        assert np.abs(origin + rotation @ [0.0, 0.0, 0.1] - circle).max() < 1e-10
        assert np.abs(rotation - cmbs.model.robot_closures.rpy_rotation([np.pi, 0.0, 0.3])).max() < 1e-10


def test_cmbs_kinematics_command_on_a_pose_driven_ur5(tmp_path, capsys):
    """``cmbs kinematics FILE --out run.npz`` on the circle file: the result's pose columns of the
    flange (tool0) carry the tool point around the circle (to 1e-10 m)."""
    if ROBOTS is None:
        pytest.skip("needs example-robot-data")
    from cmbs.cli import main

    out = tmp_path / "circle.npz"
    assert main(["kinematics", str(_circle_file(tmp_path)), "--t-end", "1", "--dt", "0.25", "--out", str(out)]) == 0
    assert "kinematics of 5 instants" in capsys.readouterr().out
    with np.load(out) as saved:
        origin = np.stack([saved[f"tool0.origin.{c}"] for c in "xyz"], axis=1)
        quaternion = np.stack([saved[f"tool0.{c}"] for c in ("qw", "qx", "qy", "qz")], axis=1)
        t = saved["t"]
    from scipy.spatial.transform import Rotation

    rotation = Rotation.from_quat(quaternion[:, [1, 2, 3, 0]]).as_matrix()
    assert np.abs(origin + rotation @ TOOL_POINT - _circle(t)).max() < 1e-10


# ------------------------------------------------------------------ refused targets and entries
def test_a_target_out_of_reach_is_a_one_line_error(tmp_path):
    """A tool target 3 m from the base (the UR5 reaches about 0.95 m): loading fails naming the
    driver's entry and its row, no configuration is returned; ``cmbs.assemble`` of the same
    model in Python raises ConvergenceError."""
    if ROBOTS is None:
        pytest.skip("needs example-robot-data")
    path = _ur5_pose_file(tmp_path, [3.0, 0.0, 0.5], RPY, np.zeros(6))
    with pytest.raises(cmbs.ModelError) as error:
        cmbs.load(path)
    message = str(error.value)
    assert "\n" not in message and message.startswith(f"{path}: drivers.tool: cannot be assembled")
    assert "in constraint 'tool." in message
    model = load_urdf(ROBOTS / URDFS["ur5"], drivers=[PoseDriver("tool", "tool0", position=(3.0, 0.0, 0.5))])
    with pytest.raises(cmbs.ConvergenceError, match="did not converge"):
        cmbs.assemble(model)


def test_a_frame_turned_half_a_turn_from_its_target_is_refused():
    """The orientation rows vanish too with the frame half a turn about the target's x axis:
    assembly started there converges at once but refuses it, naming the driver and the angle."""
    model = _made_up_tree([], [PoseDriver("tool", "l4", rpy=(0.0, 0.0, 0.0))])
    q = np.array([0.3, -0.2, 0.5, 0.7, -0.4])
    R, _ = frame_placement(model, q, "l4")
    turned = R @ np.diag([1.0, -1.0, -1.0])          # the target: the frame turned by π about its x axis
    roll, pitch, yaw = np.arctan2(turned[2, 1], turned[2, 2]), -np.arcsin(turned[2, 0]), \
        np.arctan2(turned[1, 0], turned[0, 0])
    model = _made_up_tree([], [PoseDriver("tool", "l4", rpy=(roll, pitch, yaw))])
    np.testing.assert_allclose(model.constraints(q), 0.0, atol=1e-15)
    with pytest.raises(cmbs.ConvergenceError, match=r"turned the frame of pose driver 'tool' by 180 degrees"):
        cmbs.assemble(model, q)


BAD_DRIVERS = [
    ('link = "tool0"', 'link = "tool9"', "drivers.tool: link: unknown link 'tool9' (did you mean 'tool0'?)"),
    ('link = "tool0"', 'link = "base_link"', "drivers.tool: link: 'base_link' does not move"),
    ('kind = "pose"', 'kind = "posture"', "drivers.tool: kind: unknown kind 'posture'"),
    ('position = [', 'positon = [', "drivers.tool: unknown key(s) 'positon' (did you mean 'position'?)"),
    ('position = [0.4, 0.1, 0.5]', 'position = [0.4, 0.1]',
     "drivers.tool: position must be a list of 3 numbers or expressions of t, got [0.4, 0.1]"),
    ('position = [0.4, 0.1, 0.5]', 'position = [0.4, "foo(t)", 0.5]', "drivers.tool.position.y: unknown name 'foo'"),
    ('position = [0.4, 0.1, 0.5]', 'position = [0.4, "1/t", 0.5]', "drivers.tool.position.y: "),
    ('point = [0.0, 0.0, 0.1]', 'point = [0.0, 0.1]', "drivers.tool: point must be a list of 3 finite numbers"),
    ('position = [0.4, 0.1, 0.5]\nrpy = [3.0, 0.0, 0.0]\n', '',
     "drivers.tool: give the target's 'position', its orientation 'rpy', or both"),
    ('link = "tool0"\n', '', "drivers.tool: missing key(s) 'link'"),
]


@pytest.mark.parametrize("replace, replacement, expected", BAD_DRIVERS)
def test_pose_driver_mistakes_are_one_line_errors(tmp_path, replace, replacement, expected):
    if ROBOTS is None:
        pytest.skip("needs example-robot-data")
    text = (f'[model]\nurdf = "{ROBOTS / URDFS["ur5"]}"\n\n[drivers.tool]\nkind = "pose"\nlink = "tool0"\n'
            'point = [0.0, 0.0, 0.1]\nposition = [0.4, 0.1, 0.5]\nrpy = [3.0, 0.0, 0.0]\n')
    assert replace in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(replace, replacement))
    with pytest.raises(cmbs.ModelError) as error:
        cmbs.load(path)
    message = str(error.value)
    assert "\n" not in message and message.startswith(f"{path}: ") and expected in message, message
