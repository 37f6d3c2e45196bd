"""Tracking control of a robot (the UR5 from example-robot-data, named by a robot file whose
drivers give each joint's reference motion; its joint torques are the actuators): computed
torque against the closed form of its error, through `cmbs track` and the Python API; PD
regulation against its Lyapunov function."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import cumulative_simpson

import cmbs
from helpers import example_robots
from cmbs.cli import main
from cmbs.control import PD, ComputedTorque, Reference, track

try:
    import pinocchio
except ImportError:
    pinocchio = None


UR5 = None if example_robots() is None else example_robots() / "ur_description/urdf/ur5_robot.urdf"
pytestmark = pytest.mark.skipif(UR5 is None, reason="needs example-robot-data (the UR5 URDF)")

#: each joint's reference: the driver's expression, the function and its rate at t = 0
REFERENCES = {
    "shoulder_pan_joint": ("0.1 + 0.5 * sin(t)", lambda t: 0.1 + 0.5 * np.sin(t), 0.5),
    "shoulder_lift_joint": ("-1.0 + 0.3 * sin(2 * t)", lambda t: -1.0 + 0.3 * np.sin(2 * t), 0.6),
    "elbow_joint": ("1.2 + 0.4 * cos(t)", lambda t: 1.2 + 0.4 * np.cos(t), 0.0),
    "wrist_1_joint": ("-0.5 + 0.2 * sin(3 * t)", lambda t: -0.5 + 0.2 * np.sin(3 * t), 0.6),
    "wrist_2_joint": ("0.3 * sin(t)", lambda t: 0.3 * np.sin(t), 0.3),
    "wrist_3_joint": ("0.2 * cos(2 * t)", lambda t: 0.2 * np.cos(2 * t), 0.0),
}
JOINTS = tuple(REFERENCES)


def robot_file(path: Path, drivers: dict[str, str], gravity: str = "[0.0, 0.0, -9.81]") -> Path:
    """A robot file naming the UR5 URDF with one driver per joint (joint = expression)."""
    text = f'[model]\nname = "ur5-tracking"\nurdf = {str(UR5)!r}\ngravity = {gravity}\n'
    for joint, expression in drivers.items():
        text += f'\n[drivers.{joint}]\ncoordinate = "{joint}"\nexpression = "{expression}"\n'
    path.write_text(text)
    return path


@pytest.fixture
def moving(tmp_path):
    return robot_file(tmp_path / "ur5-tracking.toml", {joint: r[0] for joint, r in REFERENCES.items()})


def closed_form_error(t: np.ndarray, omega: float, e0: float, rate0: float) -> np.ndarray:
    """The solution of ë + 2ω ė + ω² e = 0 from e(0) = e0, ė(0) = rate0 (critically damped):
    e(t) = (e0 + (rate0 + ω e0) t) e^(-ωt)."""
    return (e0 + (rate0 + omega * e0) * t) * np.exp(-omega * t)


def test_the_robot_file_s_joints_are_its_actuators(moving):
    model = cmbs.load(moving)
    assert model.actuator_names == model.coordinate_names == JOINTS
    assert model.driver_names == JOINTS
    np.testing.assert_allclose(model.q0, [f(0.0) for _, f, _ in REFERENCES.values()], atol=1e-12)


def test_computed_torque_tracking_of_the_ur5_has_its_closed_form_error_cli(moving, tmp_path):
    """`cmbs track` with computed torque (default gains 100 = ω², 20 = 2ω, ω = 10 rad/s), the
    first joint 0.1 rad off its reference, the robot at rest: each joint's error q - q_ref
    obeys ë + 2ω ė + ω² e = 0 with e0 = 0.1 on the first joint (0 on the others) and
    ė0 = -q̇_ref(0); the result file has the link poses."""
    out = tmp_path / "track.npz"
    assert main(["track", str(moving), "--controller", "ctc", "--initial-error", "0.1", "--t-end", "1.5",
                 "--out", str(out)]) == 0
    run = cmbs.Trajectory.load(out)
    assert run.t[-1] == pytest.approx(1.5) and run.t.size == 151
    worst = 0.0
    for k, (joint, (_, reference, rate)) in enumerate(REFERENCES.items()):
        expected = closed_form_error(run.t, 10.0, 0.1 if k == 0 else 0.0, -rate)
        worst = max(worst, np.abs(run[joint] - reference(run.t) - expected).max())
    print(f"UR5 computed torque (cmbs track): worst error deviation from the closed form {worst:.1e} rad")
    assert worst < 1e-6
    assert {"tool0.origin.x", "tool0.qw", "wrist_3_link.qz"} <= set(run.extras)


def test_computed_torque_tracking_of_the_ur5_has_its_closed_form_error_api(moving):
    """ComputedTorque with a gain pair per joint, ω_j = 6 ... 16 rad/s (kp = ω², kd = 2ω), every
    joint started off its reference by its own error, at rest: each error is its own closed form."""
    driven = cmbs.load(moving)
    plant = driven.without_drivers()
    motion = cmbs.kinematic_analysis(driven, np.linspace(0.0, 1.5, 151))
    omega = np.array([6.0, 8.0, 10.0, 12.0, 14.0, 16.0])
    offsets = np.array([0.1, -0.08, 0.05, 0.12, -0.1, 0.07])
    law = ComputedTorque(plant, Reference(motion, JOINTS), kp=omega**2, kd=2 * omega)
    result = track(plant, law, motion, JOINTS, t_end=1.5, q0=motion.q[0] + offsets, integrator="dop853",
                   rtol=1e-10, atol=1e-12)
    assert result.succeeded
    run = result.run
    worst = 0.0
    for k, (joint, (_, reference, rate)) in enumerate(REFERENCES.items()):
        expected = closed_form_error(run.t, omega[k], offsets[k], -rate)
        worst = max(worst, np.abs(run[joint] - reference(run.t) - expected).max())
    print(f"UR5 computed torque (API): worst error deviation from the closed form {worst:.1e} rad")
    assert worst < 1e-6


@pytest.mark.skipif(pinocchio is None, reason="needs pinocchio (pip 'pin') for M(q)")
def test_pd_regulation_of_the_ur5_decreases_its_lyapunov_function(tmp_path):
    """PD (τ = K_p e + K_d ė) holding a constant reference without gravity, from 0.1 rad off on
    the first joint: with M q̈ + C q̇ = τ and Ṁ - 2C skew, V = ½ q̇ᵀ M(q) q̇ + ½ K_p |e|² has
    V̇ = -K_d |q̇|² (Takegaki and Arimoto, J. Dyn. Sys. Meas. Control 103, 1981): V never
    increases, V(0) - V(t) = K_d ∫|q̇|² dt, and |e(t)| <= sqrt(2 V(0) / K_p) = |e(0)|.
    M(q) from Pinocchio's CRBA, the integral by Simpson's rule on the 1 ms output grid (the
    light wrist joints' fast modes need it)."""
    setpoints = {"shoulder_pan_joint": "0.2", "shoulder_lift_joint": "-1.0", "elbow_joint": "1.2",
                 "wrist_1_joint": "-0.5", "wrist_2_joint": "0.3", "wrist_3_joint": "0.0"}
    driven = cmbs.load(robot_file(tmp_path / "ur5-hold.toml", setpoints, gravity="[0.0, 0.0, 0.0]"))
    plant = driven.without_drivers()
    motion = cmbs.kinematic_analysis(driven, np.linspace(0.0, 3.0, 3001))
    kp, kd, e0 = 100.0, 20.0, 0.1
    start = motion.q[0].copy()
    start[0] += e0
    run = cmbs.simulate(plant, t_end=3.0, dt=0.001, u=PD(plant, Reference(motion, JOINTS), kp=kp, kd=kd), q0=start,
                        integrator="dop853", rtol=1e-11, atol=1e-12)
    assert run.info["status"] == "success"
    reference = pinocchio.buildModelFromUrdf(str(UR5))
    data = reference.createData()
    q, qd = run.q[:, [run.names.index(j) for j in JOINTS]], run.qd[:, [run.names.index(j) for j in JOINTS]]
    error = np.array([float(value) for value in setpoints.values()]) - q
    kinetic = np.array([0.5 * v @ pinocchio.crba(reference, data, p) @ v for p, v in zip(q, qd)])
    V = kinetic + 0.5 * kp * np.sum(error**2, axis=1)
    assert V[0] == pytest.approx(0.5 * kp * e0**2, rel=1e-12)
    power = kd * np.sum(qd**2, axis=1)
    dissipated = cumulative_simpson(power, x=run.t, initial=0.0)
    print(f"UR5 PD regulation: V(T)/V(0) = {V[-1] / V[0]:.2e}, max V increase {np.diff(V).max():.1e}, "
          f"max |V(0) - V - Kd∫|q̇|²| / V(0) = {np.abs(V[0] - V - dissipated).max() / V[0]:.1e}, "
          f"final |e| {np.abs(error[-1]).max():.1e}")
    assert np.diff(V).max() <= 1e-12 * V[0]
    assert np.abs(V[0] - V - dissipated).max() < 1e-6 * V[0]
    assert np.linalg.norm(error, axis=1).max() <= e0 * (1 + 1e-9)
    assert V[-1] < 1e-3 * V[0]
