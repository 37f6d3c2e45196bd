"""Inverse dynamics of robots driven by pose drivers (docs/robots.md, "Inverse dynamics of a driven
robot"): the joint torques that produce a task-space motion.  The UR5's and the Panda's against
Pinocchio's ``rnea`` along the motion, the motion itself against Pinocchio's frame placements and
accelerations; the five-bar-robot (a closed chain) by the Lagrangian balance with numpy's
multipliers and by a forward simulation driven by its motor torques; ``cmbs inverse``; the
mistakes.

The analyses evaluate the compiled robot kernel from Python (no compiled loop; the simulation
runs with compiled=False)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

import cmbs
from cmbs.errors import CmbsError
from cmbs.model.robot import frame_placement
from cmbs.model.robot_closures import rpy_rotation
from test_robot import ROBOTS, URDFS, needs_pinocchio, pinocchio
from test_robot_ik import CENTRE, RADIUS, TOOL_POINT, _ur5_pose_file

LIBRARY = Path(cmbs.__file__).resolve().parent / "library"


# ------------------------------------------------------------------ UR5: a full pose along a circle
def _yaw(t):
    """The flange's yaw target (rad): 0.3 + 0.2 sin t, roll π, pitch 0 (the frame turns about world z)."""
    return 0.3 + 0.2 * np.sin(t)


def _ur5_task_file(folder: Path) -> Path:
    """The UR5's tool point (TOOL_POINT on tool0) on the circle of test_robot_ik (radius 0.1 m about
    CENTRE, 1 rad/s) with the flange pointing down and turning slowly about the vertical."""
    position = [f"{float(CENTRE[0])!r} + {RADIUS!r}*cos(t)", f"{float(CENTRE[1])!r} + {RADIUS!r}*sin(t)",
                float(CENTRE[2])]
    return _ur5_pose_file(folder, position, [np.pi, 0.0, "0.3 + 0.2*sin(t)"],
                          np.array([0.2, -1.6, 1.4, -1.4, -1.6, -1.7]))


def _rnea(urdf: Path, motion) -> np.ndarray:
    """Pinocchio's τ = rnea(q, q̇, q̈) at every instant of ``motion``."""
    robot = pinocchio.buildModelFromUrdf(str(urdf))
    data = robot.createData()
    return np.array([pinocchio.rnea(robot, data, q, qd, qdd) for q, qd, qdd in zip(motion.q, motion.qd, motion.qdd)])


@needs_pinocchio
def test_ur5_task_space_inverse_dynamics_is_pinocchios_rnea(tmp_path):
    """A 6-row pose trajectory (DOF 0): ``cmbs.inverse_dynamics`` picks method 'projected' and
    gives the torques of all six joints.  The motion is the target's, by Pinocchio at every
    instant: the tool point's position, velocity and classical acceleration (frame placement,
    Jacobian and ``getFrameClassicalAcceleration`` with q, q̇, q̈) equal the circle's, the frame's
    rotation, angular velocity and acceleration the target's (ψ̇ z, ψ̈ z), to 1e-9 of their size
    (measured 1.1e-12); the torques are Pinocchio's rnea(q, q̇, q̈) to 1e-9 relative (measured
    8e-16); the drivers carry no multiplier."""
    urdf = ROBOTS / URDFS["ur5"]
    model = cmbs.load(_ur5_task_file(tmp_path))
    times = np.linspace(0.0, 3.0, 7)
    result = cmbs.inverse_dynamics(model, times)
    motion = result.motion
    assert result.method == "projected" and result.driven_coordinates == model.coordinate_names
    robot = pinocchio.buildModelFromUrdf(str(urdf))
    data = robot.createData()
    frame = robot.getFrameId("tool0")
    z = np.array([0.0, 0.0, 1.0])
    worst = 0.0
    for t, q, qd, qdd in zip(times, motion.q, motion.qd, motion.qdd):
        pinocchio.forwardKinematics(robot, data, q, qd, qdd)
        pinocchio.updateFramePlacements(robot, data)
        pinocchio.computeJointJacobians(robot, data, q)
        rotation, origin = data.oMf[frame].rotation, data.oMf[frame].translation
        J = pinocchio.getFrameJacobian(robot, data, frame, pinocchio.LOCAL_WORLD_ALIGNED)
        acceleration = pinocchio.getFrameClassicalAcceleration(robot, data, frame, pinocchio.LOCAL_WORLD_ALIGNED)
        r = rotation @ TOOL_POINT
        omega, alpha = J[3:] @ qd, acceleration.angular
        point_velocity = J[:3] @ qd + np.cross(omega, r)
        point_acceleration = acceleration.linear + np.cross(alpha, r) + np.cross(omega, np.cross(omega, r))
        circle = np.array([np.cos(t), np.sin(t), 0.0])
        errors = [np.abs(origin + r - CENTRE - RADIUS * circle).max() / RADIUS,
                  np.abs(rotation - rpy_rotation([np.pi, 0.0, _yaw(t)])).max(),
                  np.abs(point_velocity - RADIUS * np.array([-circle[1], circle[0], 0.0])).max() / RADIUS,
                  np.abs(point_acceleration + RADIUS * circle).max() / RADIUS,
                  np.abs(omega - 0.2 * np.cos(t) * z).max() / 0.2,
                  np.abs(alpha + 0.2 * np.sin(t) * z).max() / 0.2]
        worst = max(worst, *errors)
    assert worst < 1e-9, worst
    expected = _rnea(urdf, motion)
    assert np.abs(result.forces - expected).max() < 1e-9 * np.abs(expected).max()
    assert not motion.extras["lam"].any()


# ------------------------------------------------------------------ Panda: a redundant arm, joints held
PANDA_START = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785, 0.02, 0.02])


@needs_pinocchio
def test_panda_hand_pose_with_joint_drivers_is_pinocchios_rnea(tmp_path):
    """The Panda (9 coordinates) with its hand's pose driven (6 rows: a 4 cm circle in a vertical
    plane, the orientation held) leaves 3 DOF: the file prescribes them by joint drivers — the
    elbow's self-motion by panda_joint3 = 0.2 sin(2t), each finger held at 0.02 m.  The rule for
    such a mixed file: every driver prescribes motion, every joint carries torque, so the torques
    of all 9 joints (the held fingers' too) are Pinocchio's rnea(q, q̇, q̈) along the motion the
    kinematic analysis chose, to 1e-9 relative (measured 5e-16), with the hand at its target by
    Pinocchio (1e-9 m; measured 1.1e-14) and panda_joint3 on its driver."""
    urdf = ROBOTS / URDFS["panda"]
    robot = pinocchio.buildModelFromUrdf(str(urdf))
    data = robot.createData()
    pinocchio.framesForwardKinematics(robot, data, PANDA_START)
    frame = robot.getFrameId("panda_hand")
    start, rotation = data.oMf[frame].translation.copy(), data.oMf[frame].rotation.copy()
    rpy = ", ".join(repr(float(v)) for v in pinocchio.rpy.matrixToRpy(rotation))
    x, y, z = (float(v) for v in start)
    path = tmp_path / "panda-task.toml"
    path.write_text(
        f'[model]\nurdf = "{urdf}"\n\n[drivers.hand]\nkind = "pose"\nlink = "panda_hand"\n'
        f'position = ["{x!r} + 0.04*sin(t)", {y!r}, "{z!r} + 0.04*(1 - cos(t))"]\nrpy = [{rpy}]\n\n'
        '[drivers.self_motion]\ncoordinate = "panda_joint3"\nexpression = "0.2*sin(2*t)"\n\n'
        '[drivers.finger1]\ncoordinate = "panda_finger_joint1"\nexpression = "0.02"\n\n'
        '[drivers.finger2]\ncoordinate = "panda_finger_joint2"\nexpression = "0.02"\n\n[initial_positions]\n'
        + "".join(f"{name} = {value!r}\n" for name, value in zip(robot.names[1:], PANDA_START.tolist())))
    model = cmbs.load(path)
    times = np.linspace(0.0, 2.0, 5)
    result = cmbs.inverse_dynamics(model, times)
    motion = result.motion
    assert result.driven_coordinates == model.coordinate_names == tuple(robot.names[1:])
    for t, q in zip(times, motion.q):
        pinocchio.framesForwardKinematics(robot, data, q)
        target = start + 0.04 * np.array([np.sin(t), 0.0, 1.0 - np.cos(t)])
        assert np.abs(data.oMf[frame].translation - target).max() < 1e-9
        assert np.abs(data.oMf[frame].rotation - rotation).max() < 1e-9
        assert abs(q[2] - 0.2 * np.sin(2 * t)) < 1e-12
    expected = _rnea(urdf, motion)
    assert np.abs(result.forces - expected).max() < 1e-9 * np.abs(expected).max()


# ------------------------------------------------------------------ the five-bar: a closed chain
def _five_bar_task_file(folder: Path) -> Path:
    """The library's five-bar-robot (its URDF path made absolute) with its tool point C driven in
    the plane x-z: x = 0.05 sin 2t, z = 0.4939 - 0.05 (1 - cos 3t), y = 0 (a redundant row)."""
    text = (LIBRARY / "five-bar-robot.toml").read_text().replace(
        'urdf = "five-bar-robot.urdf"', f'urdf = "{LIBRARY / "five-bar-robot.urdf"}"')
    path = folder / "five-bar-task.toml"
    path.write_text(text + '\n[drivers.tool]\nkind = "pose"\nlink = "tool"\n'
                           'position = ["0.05*sin(2*t)", 0.0, "0.4939 - 0.05*(1 - cos(3*t))"]\n')
    return path


def _balance(model, result) -> tuple[float, float]:
    """Worst |M q̈ + A_cᵀλ - Q(τ)| / |Q| on the undriven model, λ by numpy's least squares, and
    worst |A_c τ| / |τ| (zero for the minimum-norm torques: τ ⊥ range(A_cᵀ))."""
    free = model.without_drivers()
    motion = result.motion
    tau = np.zeros((motion.t.size, model.n))
    tau[:, model.coordinate_indices(result.driven_coordinates)] = result.forces
    balance = orthogonal = 0.0
    for t, q, qd, qdd, u in zip(motion.t, motion.q, motion.qd, motion.qdd, tau):
        terms = free.evaluate(q, qd, t, u)
        lam = np.linalg.lstsq(terms.A.T, terms.Q - terms.M @ qdd, rcond=None)[0]
        balance = max(balance, np.abs(terms.M @ qdd + terms.A.T @ lam - terms.Q).max() / np.abs(terms.Q).max())
        orthogonal = max(orthogonal, np.abs(terms.A @ u).max() / np.abs(u).max())
    return balance, orthogonal


def test_five_bar_tool_path_minimum_norm_and_motor_torques_balance(tmp_path):
    """The closed chain (4 joints, 2 closure rows) with its tool point driven (3 rows, the y one
    redundant): DOF 0.  With every joint actuated the torques are the minimum-norm ones: the
    undriven model's balance M q̈ + A_cᵀλ = Q(τ) holds with λ by numpy's least squares to
    1e-12 (measured 8e-16) and A_c τ = 0 (1e-12; measured 2e-16); the closure multipliers the
    result keeps are numpy's.  With the motors only actuated the elbows carry none and the balance
    holds as well (5e-16); the tool point follows its path (1e-12 m; measured 6e-16)."""
    model = cmbs.load(_five_bar_task_file(tmp_path))
    times = np.linspace(0.0, 1.0, 6)
    everywhere = cmbs.inverse_dynamics(model, times)
    assert everywhere.driven_coordinates == model.coordinate_names
    balance, orthogonal = _balance(model, everywhere)
    assert balance < 1e-12 and orthogonal < 1e-12, (balance, orthogonal)
    motors = cmbs.inverse_dynamics(model, times, actuated=["left_motor", "right_motor"])
    assert motors.driven_coordinates == ("left_motor", "right_motor")
    balance, orthogonal = _balance(model, motors)
    assert balance < 1e-12 and orthogonal > 0.1, (balance, orthogonal)
    free_rows = ~model.drivers
    for result in (everywhere, motors):
        lam = result.motion.extras["lam"]
        assert not lam[:, model.drivers].any() and np.abs(lam[:, free_rows]).min() > 0.0
    for t, q in zip(times, everywhere.motion.q):
        rotation, origin = frame_placement(model, q, "tool")
        assert np.abs(origin - [0.05 * np.sin(2 * t), 0.0, 0.4939 - 0.05 * (1 - np.cos(3 * t))]).max() < 1e-12


def test_five_bar_motor_torques_reproduce_the_motion_in_a_simulation(tmp_path):
    """The motor torques of the tool path on 101 instants over 0.5 s, interpolated by a cubic
    spline (error about (5/384) h⁴ max|τ⁗| ≈ 1e-10 N m at h = 5 ms), drive the undriven five-bar
    (its elbows free) from the motion's start: a DOP853 run (rtol 1e-11, compiled=False) follows
    the kinematic motion to 1e-7 rad (measured 1.8e-10)."""
    model = cmbs.load(_five_bar_task_file(tmp_path))
    times = np.linspace(0.0, 0.5, 101)
    result = cmbs.inverse_dynamics(model, times, actuated=["left_motor", "right_motor"])
    spline = CubicSpline(times, result.forces)

    def torques(t, q, qd):
        return np.array([spline(t)[0], 0.0, spline(t)[1], 0.0])

    free = model.without_drivers()
    run = cmbs.simulate(free, t_end=0.5, dt=0.05, integrator="dop853", rtol=1e-11, atol=1e-12, u=torques,
                        q0=result.motion.q[0], qd0=result.motion.qd[0], compiled=False)
    assert run.info["status"] == "success"
    assert np.abs(run.q - result.motion.q[::10]).max() < 1e-7


# ------------------------------------------------------------------ cmbs inverse
@needs_pinocchio
def test_cmbs_inverse_command_on_a_pose_driven_ur5(tmp_path, capsys):
    """``cmbs inverse FILE --out x.npz`` on the pose-driven UR5: exit 0, the six joint torques
    printed and written, equal to the API's (1e-12 relative) and to Pinocchio's rnea."""
    from cmbs.cli import main

    path, out = _ur5_task_file(tmp_path), tmp_path / "torques.npz"
    assert main(["inverse", str(path), "--t-end", "1", "--dt", "0.5", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "inverse dynamics (projected) over 3 instants" in printed
    assert "force on wrist_3_joint" in printed and "force on shoulder_pan_joint" in printed
    api = cmbs.inverse_dynamics(cmbs.load(path), np.array([0.0, 0.5, 1.0]))
    with np.load(out) as saved:
        assert np.abs(saved["driver_forces"] - api.forces).max() < 1e-12 * np.abs(api.forces).max()
        expected = _rnea(ROBOTS / URDFS["ur5"], api.motion)
        assert np.abs(saved["driver_forces"] - expected).max() < 1e-9 * np.abs(expected).max()


def test_cmbs_inverse_actuated_joints_of_the_five_bar(tmp_path, capsys):
    """``--actuated left_motor,right_motor`` prints the two motor torques, those of the API."""
    from cmbs.cli import main

    path = _five_bar_task_file(tmp_path)
    assert main(["inverse", str(path), "--t-end", "0.2", "--dt", "0.1", "--actuated", "left_motor,right_motor",
                 "--out", str(tmp_path / "motors.npz")]) == 0
    printed = capsys.readouterr().out
    assert "force on left_motor" in printed and "force on left_elbow" not in printed
    api = cmbs.inverse_dynamics(cmbs.load(path), np.array([0.0, 0.1, 0.2]), actuated=["left_motor", "right_motor"])
    with np.load(tmp_path / "motors.npz") as saved:
        np.testing.assert_allclose(saved["driver_forces"], api.forces, rtol=1e-12)


@needs_pinocchio
def test_projected_on_a_joint_driven_ur5_equals_the_driver_forces(tmp_path):
    """Method 'projected' asked for on a robot driven joint by joint: the same torques as the
    drivers' multipliers (lagrange) and Pinocchio's rnea, to 1e-12 relative."""
    from test_robot_closures import _ur5_file

    model = cmbs.load(_ur5_file(tmp_path))
    times = np.linspace(0.0, 1.0, 3)
    projected = cmbs.inverse_dynamics(model, times, method="projected")
    lagrange = cmbs.inverse_dynamics(model, times)
    assert lagrange.method == "lagrange" and projected.driven_coordinates == lagrange.driven_coordinates
    assert np.abs(projected.forces - lagrange.forces).max() < 1e-12 * np.abs(lagrange.forces).max()


# ------------------------------------------------------------------ joint reactions of pose-driven robots
@needs_pinocchio
def test_reactions_of_a_pose_driven_ur5_are_pinocchios_rnea_forces(tmp_path):
    """The UR5's task-space motion (6 pose rows, no closure): at every instant the joint reactions
    (the pose rows carry no force) equal Pinocchio's ``data.f`` after rnea(q, q̇, q̈) in world
    axes, and each joint's force along its axis the projected torque, to 1e-10 of the largest
    force; no closure is listed."""
    from cmbs.inverse import joint_reaction_history
    from test_robot_reactions import _pinocchio_joint_forces

    urdf = ROBOTS / URDFS["ur5"]
    model = cmbs.load(_ur5_task_file(tmp_path))
    result = cmbs.inverse_dynamics(model, np.linspace(0.0, 1.0, 6))
    reactions = joint_reaction_history(model, result.motion)
    assert reactions["closures"] == {}
    robot = pinocchio.buildModelFromUrdf(str(urdf))
    data = robot.createData()
    for i, (q, qd, qdd) in enumerate(zip(result.motion.q, result.motion.qd, result.motion.qdd)):
        tau, expected = _pinocchio_joint_forces(robot, data, q, qd, qdd)
        scale = max(np.abs(force).max() for force, _ in expected.values())
        for name, (force, moment) in expected.items():
            np.testing.assert_allclose(reactions["forces"][name][i], force, rtol=0, atol=1e-10 * scale)
            np.testing.assert_allclose(reactions["moments"][name][i], moment, rtol=0, atol=1e-10 * scale)
        np.testing.assert_allclose([reactions["joint_forces"][name][i] for name in model.coordinate_names],
                                   result.forces[i], rtol=0, atol=1e-10 * scale)


def test_cmbs_inverse_reactions_of_the_pose_driven_five_bar(tmp_path, capsys):
    """``cmbs inverse five-bar-task.toml --reactions``: the closed chain's tool point driven; each
    joint's force along its axis is its minimum-norm torque (the pose rows carry no force, the
    closure C its multipliers), to 1e-10 of the largest; the closure's rows, not the pose rows,
    are listed; a nonzero pose multiplier is refused."""
    from cmbs.cli import main
    from cmbs.inverse.robot_reactions import robot_reactions

    out = tmp_path / "reactions.npz"
    path = _five_bar_task_file(tmp_path)
    assert main(["inverse", str(path), "--t-end", "0.4", "--dt", "0.1", "--reactions", "--out", str(out)]) == 0
    capsys.readouterr()
    model = cmbs.load(path)
    with np.load(out) as saved:
        torques = saved["driver_forces"]
        for i, name in enumerate(model.coordinate_names):
            np.testing.assert_allclose(saved[f"joint force {name}"], torques[:, i], rtol=0,
                                       atol=1e-10 * np.abs(torques).max())
        assert {"closure force C.line1", "closure force C.line2"} <= set(saved.files)
        assert not any(key.startswith("closure force tool") for key in saved.files)
    motion = cmbs.inverse_dynamics(model, np.linspace(0.0, 0.4, 5)).motion
    lam = motion.extras["lam"][1].copy()
    lam[model.constraint_names.index("tool.z")] = 1.0
    with pytest.raises(CmbsError, match="a pose driver's multipliers are not zero"):
        robot_reactions(model, motion.q[1], motion.qd[1], motion.qdd[1], lam)


# ------------------------------------------------------------------ mistakes
@pytest.mark.parametrize("arguments, expected", [
    (["--method", "matrix-r"], "a pose driver prescribes a link's pose, not a joint's force: its joint torques come "
                               "from method 'projected'"),
    (["--actuated", "left_motr"], "has no coordinate 'left_motr' (did you mean 'left_motor'?)"),
    (["--actuated", "left_motor,left_motor"], "actuated names 'left_motor' more than once"),
    (["--actuated", "left_motor"], "passive coordinate(s) left_elbow, right_motor, right_elbow cannot be left "
                                   "unactuated"),
    (["--method", "projected", "--option", "alpha=1e8"], "method 'projected' takes no formulation options"),
])
def test_inverse_dynamics_mistakes_are_one_line_errors(tmp_path, capsys, arguments, expected):
    from cmbs.cli import main

    status = main(["inverse", str(_five_bar_task_file(tmp_path)), "--t-end", "0.2", "--dt", "0.1", *arguments])
    printed = capsys.readouterr()
    error = printed.err
    assert status != 0 and expected in error and len(error.strip().splitlines()) == 1, error
    if "passive" not in expected:       # refused before the analysis: nothing printed
        assert printed.out == ""


def test_projected_needs_a_robot_and_actuated_needs_projected():
    """Method 'projected' on a natural-coordinate model, ``actuated`` with another method: one line each."""
    with pytest.raises(CmbsError, match="method 'projected' gives a robot's joint torques; this model is not a robot"):
        cmbs.inverse_dynamics(cmbs.load("four-bar"), [0.0], method="projected")
    with pytest.raises(CmbsError, match="actuated is for method 'projected'"):
        cmbs.inverse_dynamics(cmbs.load("four-bar"), [0.0], actuated=["theta"])
