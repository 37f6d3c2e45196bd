"""Inverse dynamics, tracking control and sweeps on spatial natural-coordinate models, against
closed forms and single simulations."""

import numpy as np
import pytest

import cmbs
from cmbs.sweep import Variant, sweep

ARM = """
[model]
name = "arm-3d"
dimension = 3
gravity = [0.0, 0.0, -9.81]

[points]
O = { position = [0.0, 0.0, 0.0], fixed = true }

[vectors]
x = { direction = [1.0, 0.0, 0.0], fixed = true }
y = { direction = [0.0, 1.0, 0.0], fixed = true }
u = { direction = [0.0, 1.0, 0.0] }
v = { direction = [0.0, 0.0, 1.0] }

[bodies.arm]
origin = "O"
basis = ["x", "u", "v"]
mass = 2.0
com = [0.0, 0.3, 0.0]
inertia = [0.05, 0.01, 0.05]

[angles.theta]
reference = "y"
vector = "u"
axis = "x"

[drivers.swing]
coordinate = "theta"
expression = "0.5 * sin(2 * t)"

[actuators]
motor = { coordinate = "theta" }
"""
MASS, ARM_LENGTH, INERTIA_X, G = 2.0, 0.3, 0.05, 9.81


@pytest.fixture
def arm(tmp_path):
    """A body turning about the horizontal ground axis x at O, its centre of mass 0.3 m along u,
    driven θ = 0.5 sin 2t, with a motor on θ."""
    path = tmp_path / "arm.toml"
    path.write_text(ARM)
    return path


def test_inverse_dynamics_of_a_spatial_arm_is_the_pendulum_torque(arm):
    """τ = I_O θ̈ + m g d cos θ with I_O = I_x + m d² (θ from the horizontal y towards z)."""
    model = cmbs.load(arm)
    times = np.linspace(0.0, 2.0, 21)
    result = cmbs.inverse_dynamics(model, times)
    theta = 0.5 * np.sin(2.0 * times)
    expected = (INERTIA_X + MASS * ARM_LENGTH**2) * (-2.0 * np.sin(2.0 * times)) + MASS * G * ARM_LENGTH * np.cos(theta)
    np.testing.assert_allclose(result.force("theta"), expected, atol=1e-9)


def test_computed_torque_tracking_of_a_spatial_arm_has_its_closed_form_error(arm, tmp_path):
    """`cmbs track` with computed torque (gains ω² and 2ω, ω = 10 rad/s) from 0.1 rad off the
    reference, at rest: the error obeys ë + 2ω ė + ω² e = 0, e(t) = (e₀ + (ė₀ + ω e₀) t) e^(-ωt)
    with e₀ = 0.1, ė₀ = -θ̇_ref(0) = -1."""
    from cmbs.cli import main

    out = tmp_path / "track.npz"
    assert main(["track", str(arm), "--controller", "ctc", "--initial-error", "0.1", "--t-end", "1.5",
                 "--out", str(out)]) == 0
    run = cmbs.Trajectory.load(out)
    error = run["theta"] - 0.5 * np.sin(2.0 * run.t)
    omega, e0, rate0 = 10.0, 0.1, -1.0
    expected = (e0 + (rate0 + omega * e0) * run.t) * np.exp(-omega * run.t)
    np.testing.assert_allclose(error, expected, atol=1e-6)
    assert run.t[-1] == pytest.approx(1.5)


@pytest.mark.parametrize("workers", [1, 2])
def test_a_sweep_of_a_spatial_model_equals_its_single_simulations(workers):
    """The spatial slider-crank at three crank speeds (a library parameter), serial or on a
    process pool: each variant's motion is that of its own simulation."""
    rates = (4.0, 6.0, 8.0)
    result = sweep("spatial-slider-crank", [Variant(parameters={"crank_rate": rate}) for rate in rates],
                   t_end=0.5, dt=1e-3, every=10, integrator="rk4", workers=workers)
    assert set(result.status) == {"success"}
    for v, rate in enumerate(rates):
        run = cmbs.simulate(cmbs.load("spatial-slider-crank", crank_rate=rate), t_end=0.5, dt=1e-3,
                            integrator="rk4")
        np.testing.assert_allclose(result.q[v], run.q[::10], rtol=0, atol=1e-12)
    assert np.ptp(result.q[:, -1, result.names.index("x_slider")]) > 1e-3     # the variants differ


def test_a_batched_sweep_of_a_spatial_model_equals_its_single_simulations():
    """State-only variants (the slider-crank's start velocities scaled) take the batched compiled
    path, whose lanes evaluate the spatial kernel: the motions of the single simulations."""
    model = cmbs.load("spatial-slider-crank")
    factors = (0.5, 1.0, 1.5)
    result = sweep(model, [Variant(qd0=model.qd0 * f) for f in factors], t_end=0.5, dt=1e-3, every=10,
                   integrator="rk4")
    assert result.info["mode"] == "batched" and set(result.status) == {"success"}
    for v, factor in enumerate(factors):
        run = cmbs.simulate(model, t_end=0.5, dt=1e-3, integrator="rk4", qd0=model.qd0 * factor)
        np.testing.assert_allclose(result.q[v], run.q[::10], rtol=0, atol=1e-12)


def test_a_mass_fault_on_a_spatial_body_is_the_body_built_heavier(arm):
    """`mass_fault(model, "arm", factor=1.5)` from t = 0 moves the undriven arm as the arm built
    with 1.5 times its mass and inertia (its share of M and gravity scaled: FreeBody), and the
    tracking CLI takes the fault by name."""
    from cmbs.cli import main
    from cmbs.control.faults import mass_fault

    nominal = cmbs.load(arm).without_drivers()
    start = np.zeros(nominal.n)
    start[nominal.coordinate_index("theta")] = 1.0
    start = cmbs.velocities(nominal, nominal.q0, qd=start, fixed=["theta"])
    faulty = mass_fault(nominal, "arm", factor=1.5)
    heavier_file = arm.parent / "heavier.toml"
    heavier_file.write_text(ARM.replace("mass = 2.0", "mass = 3.0").replace("inertia = [0.05, 0.01, 0.05]",
                                                                             "inertia = [0.075, 0.015, 0.075]"))
    heavier = cmbs.load(heavier_file).without_drivers()
    options = dict(t_end=1.0, dt=0.05, qd0=start, integrator="dop853", rtol=1e-11, atol=1e-12)
    run, reference = cmbs.simulate(faulty, **options), cmbs.simulate(heavier, **options)
    assert run.info["status"] == reference.info["status"] == "success"
    np.testing.assert_allclose(run.q, reference.q, atol=1e-9)
    assert np.ptp(run["theta"]) > 0.5
    with pytest.raises(cmbs.CmbsError, match="no body 'ram' \\(did you mean 'arm'\\?\\); bodies and rods: arm"):
        mass_fault(nominal, "ram", factor=1.5)
    assert main(["track", str(arm), "--t-end", "0.5", "--fault", "mass:arm:1.2"]) == 0


def test_the_passive_joint_law_puts_the_whole_torque_on_the_spatial_arm_s_motor(arm):
    """passive_joint_torque with θ the only actuated coordinate: zero on the unit vectors'
    coordinates and, on θ, the pendulum torque I_O θ̈ + m g d cos θ of the driven motion."""
    from cmbs.inverse import passive_joint_torque

    driven = cmbs.load(arm)
    motion = cmbs.kinematic_analysis(driven, np.linspace(0.0, 1.0, 6))
    free = driven.without_drivers()
    theta = free.coordinate_index("theta")
    for k, t in enumerate(motion.t):
        torque = passive_joint_torque(free, motion.q[k], motion.qd[k], motion.qdd[k], t, actuated=["theta"])
        angle, acceleration = 0.5 * np.sin(2.0 * t), -2.0 * np.sin(2.0 * t)
        expected = (INERTIA_X + MASS * ARM_LENGTH**2) * acceleration + MASS * G * ARM_LENGTH * np.cos(angle)
        assert torque[theta] == pytest.approx(expected, abs=1e-9)
        assert np.abs(np.delete(torque, theta)).max() < 1e-12          # zero up to rounding
