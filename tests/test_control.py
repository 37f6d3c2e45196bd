"""Controllers: computed torque reproduces the designed error dynamics, PD with inverse-dynamics
feed-forward recovers from a wrong initial state, zero-order hold samples and holds."""


import numpy as np
import pytest

import cmbs
from cmbs.control import PD, ComputedTorque, Reference, ZeroOrderHold
from cmbs.errors import CmbsError
from helpers import arm_on_slider_motion, library_four_bar_variant


@pytest.fixture(scope="module")
def four_bar():
    model = cmbs.load("four-bar")
    motion = cmbs.kinematic_analysis(model, np.linspace(0.0, 4.0, 801))
    free = model.without_drivers()
    start = free.q0.copy()
    start[free.coordinate_index("alpha")] += 0.1  # wrong initial state
    start = cmbs.assemble(free, start, fixed=["alpha"])
    return model, motion, free, start


def test_computed_torque_error_follows_the_designed_dynamics(four_bar):
    """ë + 20 ė + 100 e = 0 with e(0) = -0.1, ė(0) = 0: e(t) = -0.1 (1 + 10 t) exp(-10 t)."""
    model, motion, free, start = four_bar
    law = ComputedTorque(free, Reference(motion, ("alpha",)), kp=100.0, kd=20.0)
    run = cmbs.simulate(free, t_end=2.0, u=law, q0=start, qd0=np.zeros(free.n), rtol=1e-10, atol=1e-12, dt=0.01)
    error = motion["alpha"][:run.t.size * 2:2] - run["alpha"]
    designed = -0.1 * (1 + 10 * run.t) * np.exp(-10 * run.t)
    assert run.info["status"] == "success"
    assert np.abs(error - designed).max() < 1e-5


def test_pd_with_feed_forward_recovers_from_a_wrong_start(four_bar):
    model, motion, free, start = four_bar
    torque = cmbs.inverse_dynamics(model, motion).force("alpha")
    feed_forward = cmbs.SampledInput(motion.t, torque, "spline")
    law = PD(free, Reference(motion, ("alpha",)), kp=2000.0, kd=300.0, feed_forward=lambda t: feed_forward(t))
    run = cmbs.simulate(free, t_end=3.0, u=law, q0=start, qd0=np.zeros(free.n), rtol=1e-9, atol=1e-11, dt=0.01)
    error = np.abs(motion["alpha"][:run.t.size * 2:2] - run["alpha"])
    assert error[0] == pytest.approx(0.1)
    assert error[run.t >= 2.0].max() < 1e-3 * error[0]


def test_zero_order_hold_samples_and_holds():
    calls = []

    def law(t, q, qd):
        calls.append(t)
        return np.array([t])

    held = ZeroOrderHold(law, period=0.1)
    values = [held(t, None, None)[0] for t in (0.0, 0.05, 0.0999, 0.1, 0.17, 0.2)]
    assert values == [0.0, 0.0, 0.0, 0.1, 0.1, 0.2]
    assert len(calls) == 3
    # going back in time (a retried step, the recording of the run) returns what was applied then
    assert [held(t, None, None)[0] for t in (0.05, 0.15, 0.25)] == [0.0, 0.1, 0.2]
    assert len(calls) == 3
    assert held(0.31, None, None)[0] == 0.31 and len(calls) == 4   # a new sample, at its first call


def test_recorded_inputs_of_a_held_law_are_the_applied_ones():
    """Python RK4 with a 10 ms hold of a state-dependent law: run['u'] at t_k is the value the
    law returned when sample k was taken (not the law re-evaluated at the recorded state)."""
    model = cmbs.load("two-link-arm-joint")
    taken = {}

    def law(t, q, qd):
        value = np.array([-2.0 * qd[0], -1.0 * qd[1]])
        taken.setdefault(round(t / 0.01), value)
        return value

    run = cmbs.simulate(model, t_end=0.2, integrator="rk4", dt=0.01, u=ZeroOrderHold(law, 0.01), qd0=model.qd0 + 1.0,
                        compiled=False)
    applied = np.array([taken[k][0] for k in range(run.t.size)])
    np.testing.assert_array_equal(run["u"][:, 0], applied)
    fresh = np.array([law(t, q, qd)[0] for t, q, qd in zip(run.t, run.q, run.qd)])
    assert np.abs(fresh - applied).max() > 1e-6      # the reached states differ from the sampled ones


def test_controllers_need_actuators_on_the_reference_coordinates():
    model = cmbs.load("double-pendulum")
    motion = cmbs.kinematic_analysis(cmbs.load("four-bar"), np.linspace(0, 1, 11))
    with pytest.raises(CmbsError, match="no coordinate"):
        Reference(motion, ("theta1",))
    fake = cmbs.Trajectory(motion.t, np.zeros((11, 6)), np.zeros((11, 6)), np.zeros((11, 6)), model.coordinate_names)
    with pytest.raises(CmbsError, match="actuators cannot act"):
        PD(model, Reference(fake, ("theta1",)), kp=1.0, kd=1.0)


def test_mass_fault_equals_the_heavier_mechanism_after_t0():
    from cmbs.control.faults import mass_fault

    nominal = cmbs.load("four-bar").without_drivers()
    faulty = mass_fault(nominal, "coupler", factor=1.025, t0=1.0)
    heavier = library_four_bar_variant("four-bar", coupler_mass=5.0 * 1.025, actuator=True)
    rng = np.random.default_rng(4)
    q, qd = nominal.q0 + 0.01 * rng.normal(size=nominal.n), rng.normal(size=nominal.n)
    before, after = faulty.evaluate(q, qd, 0.5), faulty.evaluate(q, qd, 1.5)
    np.testing.assert_allclose(before.M, nominal.mass_matrix(q), atol=1e-12)
    np.testing.assert_allclose(after.M, heavier.mass_matrix(q), atol=1e-12)
    np.testing.assert_allclose(after.Q, heavier.forces(q, qd, 1.5), atol=1e-12)
    with pytest.raises(CmbsError, match="no segment 'bar'"):
        mass_fault(nominal, "bar", factor=2.0)


def test_faults_disturb_computed_torque_tracking(four_bar):
    from cmbs.control.faults import ActuatorFault, SensorNoise, mass_fault

    model, motion, free, _ = four_bar
    reference = Reference(motion, ("alpha",))
    law = ComputedTorque(free, reference, kp=100.0, kd=20.0)
    settings = dict(t_end=2.0, rtol=1e-9, atol=1e-11, dt=0.01)

    def worst_error(run):
        return np.abs(motion["alpha"][:run.t.size * 2:2] - run["alpha"]).max()

    exact = worst_error(cmbs.simulate(free, u=law, **settings))
    heavier = worst_error(cmbs.simulate(mass_fault(free, "coupler", factor=1.025, t0=0.5), u=law, **settings))
    offset = worst_error(cmbs.simulate(free, u=ActuatorFault(law, t0=0.5, offset=5.0), **settings))
    assert exact < 1e-6
    assert 1e-5 < heavier < 0.05 and 1e-4 < offset < 0.05
    # a constant torque offset d gives the steady error e = d / (K_p m̄), m̄ the reduced inertia: bounded, not zero
    # noisy measurements through a 1 kHz digital controller, fixed-step RK4 at the sample period
    noisy = [cmbs.simulate(free, u=ZeroOrderHold(SensorNoise(law, position=1e-3, seed=7), period=1e-3), t_end=2.0,
                           integrator="rk4", dt=1e-3)["alpha"] for _ in range(2)]
    np.testing.assert_array_equal(noisy[0], noisy[1])  # seeded: reproducible
    assert 1e-6 < np.abs(noisy[0][::10] - motion["alpha"][:201 * 2:2]).max() < 0.05


def test_cli_track(tmp_path, capsys):
    from cmbs.cli import main

    out = tmp_path / "track.npz"
    assert main(["track", "four-bar", "--controller", "ctc", "--initial-error", "0.1", "--t-end", "1.5",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "NRMSE" in text and "settling time (1 %) 0.6" in text  # (1 + 10t) e^{-10t} = 0.01 at t ≈ 0.66 s
    assert cmbs.Trajectory.load(out).t[-1] == pytest.approx(1.5)
    assert main(["track", "four-bar", "--t-end", "1", "--fault", "bogus"]) == 2
    assert main(["track", "pendulum", "--t-end", "1"]) == 2
    assert "expected mass:SEGMENT" in capsys.readouterr().err


def driven_arm(arm, drivers):
    """The library arm on a slider with drivers on some joint angles (for a reference motion)."""
    from cmbs.model.joints import JointModelBuilder

    lengths, masses = (0.5, 0.5, 0.25), (3.0, 2.0, 0.8)
    builder = JointModelBuilder("arm-driven", gravity=(0.0, 0.0))
    parent = None
    for k, (length, mass, angle) in enumerate(zip(lengths, masses, arm.q0), start=1):
        builder.add_link(f"link{k}", parent=parent, coordinate=f"theta{k}",
                         origin=(0.0, 0.0) if parent is None else (lengths[k - 2], 0.0), length=length, mass=mass,
                         com=(length / 2, 0.0), inertia=mass * length**2 / 12, q0=angle)
        parent = f"link{k}"
    builder.add_closure("slider", point="link3.end", to=(0.0, 0.5), directions="z")
    for coordinate, function in drivers.items():
        builder.add_driver(coordinate, function)
    return builder.build()


def test_pidc_tracks_with_the_designed_error_dynamics_and_minimum_norm_torque():
    from cmbs.control import PIDC

    arm = cmbs.load("arm-on-slider")
    q0 = arm.q0
    reference_model = driven_arm(arm, {"theta2": f"{float(q0[1])!r} + 0.2*sin(2*t)",
                                       "theta3": f"{float(q0[2])!r} - 0.1*sin(3*t)"})
    motion = cmbs.kinematic_analysis(reference_model, np.linspace(0.0, 1.5, 301))
    start = motion.q[0].copy()
    start[1] += 0.05  # theta2 wrong by 0.05 rad
    start = cmbs.assemble(arm, start, fixed=["theta2", "theta3"])
    qd_start = cmbs.velocities(arm, start, qd=motion.qd[0], fixed=["theta2", "theta3"])
    law = PIDC(arm, Reference(motion, ("theta2", "theta3")), kp=100.0, kd=20.0)
    run = cmbs.simulate(arm, t_end=1.5, u=law, q0=start, qd0=qd_start, rtol=1e-10, atol=1e-12, dt=0.005)
    assert run.info["status"] == "success"
    error = motion["theta2"] - run["theta2"]
    designed = -0.05 * (1 + 10 * run.t) * np.exp(-10 * run.t)
    assert np.abs(error - designed).max() < 1e-5
    for k in range(0, run.t.size, 50):  # the actuation lies in null(A)
        A = arm.jacobian(run.q[k])
        assert abs((A @ run["u"][k])[0]) < 1e-8 * max(1.0, np.abs(run["u"][k]).max())


def designed_accelerations_hold(model, reference, kp, kd, fixed, offsets, rates, t):
    """At the reference's state at t moved by ``offsets`` in the tracked coordinates (the others
    assembled) and with velocities ``rates`` of them, the law's inputs u (Python call and compiled
    kernel), applied to the model, give the accelerations of the designed error dynamics: the
    forward dynamics by Lagrange's multipliers (not matrix R, on which the law is built) has
    z̈ = z̈_ref + K_d (ż_ref - ż) + K_p (z_ref - z), with z_ref and its derivatives from the
    reference's spline (scipy)."""
    from cmbs.control.compiled_torque import computed_torque_kernel
    from cmbs.dynamics import formulation

    law = ComputedTorque(model, reference, kp=kp, kd=kd)
    columns = model.coordinate_indices(list(fixed))
    z_ref, zd_ref, zdd_ref = reference(t)
    q = reference.motion.q[np.searchsorted(reference.motion.t, t)].copy()
    q[columns] = z_ref + offsets
    q = cmbs.assemble(model, q, t, fixed=list(fixed))
    qd = np.zeros(model.n)
    qd[columns] = zd_ref + rates
    qd = cmbs.velocities(model, q, t, qd=qd, fixed=list(fixed))
    designed = zdd_ref + np.asarray(kd) * (zd_ref - qd[columns]) + np.asarray(kp) * (z_ref - q[columns])
    inputs = [law(t, q, qd)]
    kernel = computed_torque_kernel(law, held=False)
    if kernel is not None:
        inputs.append(np.zeros(model.n_u))
        kernel.apply(kernel, 0, 0, q, qd, t, inputs[-1])
    lagrange = formulation("lagrange").bind(model)
    for u in inputs:
        qdd = lagrange.accelerations(model.evaluate(q, qd, t, u), q, qd, t).qdd
        np.testing.assert_allclose(qdd[columns], designed, rtol=1e-9, atol=1e-9 * np.abs(designed).max())
    return inputs


def test_computed_torque_gives_the_designed_accelerations_off_the_reference(four_bar):
    """The four-bar's crank 0.1 rad and 0.5 rad/s off its reference, and on it at a sample of the
    reference's motion: zero error, where the inputs are the motion's inverse dynamics (to the
    spline's z̈_ref, 2e-5 of the motion's α̈ there with samples 5 ms apart; the difference goes as
    their spacing squared)."""
    model, motion, free, _ = four_bar
    reference = Reference(motion, ("alpha",))
    sample = 260
    for offset, rate in ((0.1, 0.5), (0.0, 0.0)):
        inputs = designed_accelerations_hold(free, reference, 100.0, 20.0, ("alpha",), offset, rate,
                                             motion.t[sample])
    inverse = cmbs.inverse_dynamics(model, motion).force("alpha")[sample]
    for u in inputs:
        assert u[0] == pytest.approx(inverse, rel=1e-4)


def test_computed_torque_gives_the_designed_accelerations_of_two_coordinates():
    """The arm on a slider tracking two coordinates named out of the model's order, per-coordinate
    gains, off the reference in both."""
    arm, motion = arm_on_slider_motion()
    reference = Reference(motion, ("theta3", "theta2"))
    designed_accelerations_hold(arm, reference, [400.0, 100.0], [40.0, 20.0], ("theta3", "theta2"),
                                np.array([0.02, -0.03]), np.array([0.1, -0.2]), 0.4)
