"""Inverse dynamic analysis: driver multipliers and matrix-R Q_IDA agree, and replaying the
torques open-loop on the undriven model reproduces the prescribed motion."""

import math

import numpy as np
import pytest

import cmbs
from cmbs.cli import main
from cmbs.errors import CmbsError
from cmbs.inverse import inverse_dynamics
from cmbs.trajectory import Trajectory
from helpers import library_four_bar_variant


def test_lagrange_multipliers_and_matrix_r_agree():
    model = cmbs.load("four-bar")
    times = np.linspace(0.0, 2.0, 201)
    lagrange = inverse_dynamics(model, times, method="lagrange")
    matrix_r = inverse_dynamics(model, times, method="matrix-r")
    scale = np.abs(lagrange.force("alpha")).max()
    assert scale > 10.0  # a real torque, not zero
    np.testing.assert_allclose(matrix_r.force("alpha"), lagrange.force("alpha"), atol=1e-10 * scale)
    baumgarte = inverse_dynamics(model, times, method="baumgarte")
    np.testing.assert_allclose(baumgarte.force("alpha"), lagrange.force("alpha"), atol=1e-9 * scale)
    penalty = inverse_dynamics(model, times, method="penalty", alpha=1e8)
    np.testing.assert_allclose(penalty.force("alpha"), lagrange.force("alpha"), rtol=1e-5, atol=1e-5 * scale)


def test_replayed_torque_reproduces_the_motion():
    """Open loop over 1 s: the spline of the IDA torque (1 ms samples) drives the undriven
    four-bar along α(t) = (π/4) sin(πt - π/2) to within 1e-8 rad."""
    model = cmbs.load("four-bar")
    times = np.linspace(0.0, 1.0, 1001)
    torque = inverse_dynamics(model, times).forces
    run = cmbs.simulate(model.without_drivers(), t_end=1.0, u=cmbs.SampledInput(times, torque, "spline"),
                        rtol=1e-10, atol=1e-12, dt=0.01)
    prescribed = math.pi / 4 * np.sin(math.pi * run.t - math.pi / 2)
    assert np.abs(run["alpha"] - prescribed).max() < 1e-8


def test_static_balance_against_statics():
    """Held still (α constant), the crank torque balances gravity: computed independently from
    the virtual work of the weights along the mechanism's one-DOF motion (finite differences)."""
    held = library_four_bar_variant("four-bar-held", driver=-math.pi / 4)
    torque = inverse_dynamics(held, np.array([0.0, 0.1])).force("alpha")[0]
    free = held.without_drivers()

    def potential(alpha):
        guess = held.q0.copy()
        guess[4] = alpha
        q = cmbs.assemble(free, guess, fixed=["alpha"])
        return free.potential_energy(q)

    h = 1e-5
    assert torque == pytest.approx((potential(-math.pi / 4 + h) - potential(-math.pi / 4 - h)) / (2 * h), rel=1e-7)


def test_inverse_dynamics_errors():
    with pytest.raises(CmbsError, match="has no drivers"):
        inverse_dynamics(cmbs.load("pendulum"), np.linspace(0, 1, 3))
    with pytest.raises(CmbsError, match="unknown inverse-dynamics method"):
        inverse_dynamics(cmbs.load("four-bar"), np.linspace(0, 1, 3), method="newton")


def test_cli_inverse(tmp_path, capsys):
    out = tmp_path / "ida.npz"
    assert main(["inverse", "four-bar", "--t-end", "2", "--dt", "0.01", "--method", "matrix-r", "--out", str(out),
                 "--plot", str(tmp_path / "ida.png")]) == 0
    result = Trajectory.load(out)
    assert result.extras["driver_forces"].shape == (201, 1)
    assert (tmp_path / "ida.png").read_bytes()[:4] == b"\x89PNG"
    assert "alpha" in capsys.readouterr().out
    assert main(["inverse", "pendulum", "--t-end", "1", "--dt", "0.1"]) == 2


def test_cli_inverse_with_reactions(tmp_path, capsys):
    out = tmp_path / "ida.csv"
    assert main(["inverse", "four-bar", "--t-end", "1", "--dt", "0.1", "--reactions", "--out", str(out)]) == 0
    result = Trajectory.load(out)
    at_a = result.extras["reaction crank@A"]
    at_b = result.extras["reaction rocker@B"]
    assert at_a.shape == (11, 2)
    # the ground carries the weight and the inertia: total vertical ground force - weight = Σ m a_z
    assert np.all(np.isfinite(at_a)) and np.abs(at_a[:, 1] + at_b[:, 1]).max() > 50.0
    np.testing.assert_allclose(result.extras["joint torque alpha"], result.extras["driver_forces"][:, 0],
                               rtol=1e-9, atol=1e-9)
    assert "reaction coupler@P1" in capsys.readouterr().out


def test_every_method_reads_a_motion_by_one_rule():
    """A motion whose accelerations disagree with the drivers' (q̈ doubled) is refused by every
    method — lagrange used the drivers' f''(t) and matrix-r the motion's q̈, giving torques that
    differed by a factor of two — and an agreeing one gives the same torque to every method."""
    model = cmbs.load("four-bar")
    motion = cmbs.kinematic_analysis(model, np.linspace(0.0, 2.0, 41))
    doubled = Trajectory(motion.t, motion.q, motion.qd, 2 * motion.qdd, motion.names)
    moved = Trajectory(motion.t, motion.q + 1e-3, motion.qd, motion.qdd, motion.names)
    reference = inverse_dynamics(model, motion.t).force("alpha")
    for method in ("lagrange", "baumgarte", "penalty", "matrix-r"):
        with pytest.raises(CmbsError, match=r"accelerations differ from the drivers' by .* in P2\.x"):
            inverse_dynamics(model, doubled, method=method)
        with pytest.raises(CmbsError, match="positions violate its constraints"):
            inverse_dynamics(model, moved, method=method)
        np.testing.assert_allclose(inverse_dynamics(model, motion, method=method).force("alpha"), reference,
                                   rtol=1e-7, atol=1e-7 * np.abs(reference).max())


def test_inputs_act_during_inverse_dynamics():
    """A spring law u = -k θ on the two-link arm's joint actuators (a Python input, as in
    simulate): the drivers supply what the springs do not, τ(u) = τ(0) - u, by both methods."""
    from cmbs.motion import prescribe, read_motion

    arm = cmbs.load("two-link-arm-joint")
    driven = prescribe(arm, read_motion("theta1 = 0.3*sin(2*t); theta2 = 0.5*cos(3*t)", arm))
    stiffness = np.array([4.0, 7.0])
    columns = arm.coordinate_indices(["theta1", "theta2"])

    def springs(t, q, qd):
        return -stiffness * q[columns]

    times = np.linspace(0.0, 1.0, 21)
    for method in ("lagrange", "matrix-r"):
        free = inverse_dynamics(driven, times, method=method)
        loaded = inverse_dynamics(driven, times, method=method, u=springs)
        spring_torques = -stiffness * free.motion.q[:, columns]
        order = [loaded.driven_coordinates.index(name) for name in ("theta1", "theta2")]
        np.testing.assert_allclose(loaded.forces[:, order], free.forces[:, order] - spring_torques, atol=1e-10)
        np.testing.assert_allclose(loaded.motion["u"], spring_torques, atol=1e-12)
