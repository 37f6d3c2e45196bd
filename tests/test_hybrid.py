"""Constraint-force and hybrid motion/force control (Aghili 2005 §VII-C): the force part is
impotent and sets the multipliers, the motion keeps the designed error dynamics, the sampled PI
loop follows its difference equation and removes a disturbance, and PIDC needs the least torque
at every instant of a closed-loop run (Aghili §IX, Fig. 8(D)).

Independent references: the KKT system [M Aᵀ; A 0][q̈; λ] = [Q + τ; γ] solved here with numpy,
closed-form error responses and the roots of the loop's characteristic polynomial."""

import numpy as np
import pytest

import cmbs
from cmbs.control import PIDC, ComputedTorque, Reference
from cmbs.control.faults import ActuatorFault
from cmbs.control.hybrid import ConstraintForceControl, ForceSensor, Hybrid, hybrid_torque, split
from cmbs.errors import CmbsError

STEP = 2e-3  # rk4 step = force-loop sample period in the closed-loop tests


def kkt(model, q, qd, tau, t=0.0):
    """q̈, λ of M q̈ + Aᵀλ = Q + τ, A q̈ = γ (Q with zero inputs), by a dense solve."""
    terms = model.evaluate(np.asarray(q, float), np.asarray(qd, float), t)
    n, m = model.n, model.m
    matrix = np.block([[terms.M, terms.A.T], [terms.A, np.zeros((m, m))]])
    solution = np.linalg.solve(matrix, np.concatenate([terms.Q + tau, terms.gamma]))
    return solution[:n], solution[n:]


def consistent_state(model, rng, independent):
    qd = cmbs.velocities(model, model.q0, qd=rng.normal(size=model.n), fixed=independent)
    qdd = cmbs.accelerations(model, model.q0, qd, qdd=rng.normal(size=model.n), fixed=independent)
    return model.q0, qd, qdd


@pytest.fixture(scope="module")
def arm_reference():
    """θ2, θ3 sinusoids about the library start, θ1 by assembly: a motion of the arm on the slider."""
    arm = cmbs.load("arm-on-slider")
    times = np.linspace(0.0, 2.0, 401)
    q = np.tile(arm.q0, (times.size, 1))
    q[:, 1] += 0.2 * np.sin(2 * times)
    q[:, 2] -= 0.1 * np.sin(3 * times)
    for k in range(times.size):
        q[k] = cmbs.assemble(arm, q[k], fixed=["theta2", "theta3"])
    motion = cmbs.Trajectory(times, q, np.zeros_like(q), np.zeros_like(q), arm.coordinate_names)
    return arm, Reference(motion, ("theta2", "theta3"))


def start_with_error(arm, reference, error):
    """θ2 wrong by ``error`` rad, ż = ż_ref(0): the designed response is error·(1 + 10t)e^{-10t}."""
    start = reference.motion.q[0].copy()
    start[1] += error
    start = cmbs.assemble(arm, start, fixed=["theta2", "theta3"])
    qd = np.zeros(arm.n)
    qd[1:] = reference(0.0)[1]
    return start, cmbs.velocities(arm, start, qd=qd, fixed=["theta2", "theta3"])


@pytest.mark.parametrize("name, options, independent", [
    ("arm-on-slider", {}, ["theta2", "theta3"]),  # 1 constraint, joint angles
    ("slider-crank", {}, ["theta1"]),  # natural coordinates, massless angle coordinates
    ("chain", {"links": 3, "closed": True}, ["P1.x"]),  # 3 constraints, 1 DOF
])
def test_force_part_is_impotent_and_sets_the_multipliers(name, options, independent):
    model = cmbs.load(name, **options)
    rng = np.random.default_rng(5)
    q, qd, qdd = consistent_state(model, rng, independent)
    lam = rng.normal(size=model.m)
    motion, force = hybrid_torque(model, q, qd, qdd, lam)
    A = model.jacobian(q)
    scale = np.abs(motion).max() + np.abs(force).max()
    assert abs(motion @ force) < 1e-10 * scale**2  # orthogonal parts
    assert np.abs(A @ motion).max() < 1e-10 * scale  # motion part in null(A)
    coefficients = np.linalg.lstsq(A.T, force, rcond=None)[0]
    np.testing.assert_allclose(A.T @ coefficients, force, atol=1e-10 * scale)  # force part in range(Aᵀ)
    produced, multipliers = kkt(model, q, qd, motion + force)
    np.testing.assert_allclose(produced, qdd, atol=1e-8 * max(1.0, np.abs(qdd).max()))
    np.testing.assert_allclose(multipliers, lam, atol=1e-8 * max(1.0, np.abs(lam).max()))
    np.testing.assert_allclose(kkt(model, q, qd, motion)[0], qdd, atol=1e-8 * max(1.0, np.abs(qdd).max()))


def test_hybrid_motion_keeps_the_designed_error_and_the_force_loop_its_difference_equation(arm_reference):
    """Motion: e(t) = -0.05 (1 + 10t) e^{-10t} whatever the force part does.  Force: with an exact
    model the sample-k measurement is the previous command, so x_k = λ_c,k - λ_d solves
    x_k = (1 - K_f - K_i h) x_k-1 + K_f x_k-2, i.e. x_k = c1 r1^k + c2 r2^k; the first sample
    measures λ with zero input (x_0 = (K_f + K_i h) e_0)."""
    arm, reference = arm_reference
    start, qd_start = start_with_error(arm, reference, 0.05)
    kf, ki, desired = 0.5, 10.0, 5.0
    law = Hybrid(arm, reference, kp=100.0, kd=20.0, force_reference=desired, kf=kf, ki=ki, period=STEP)
    run = cmbs.simulate(arm, t_end=1.0, u=law, q0=start, qd0=qd_start, integrator="rk4", dt=STEP,
                        formulation="projection")
    assert run.info["status"] == "success"
    error = np.array([reference(t)[0][0] for t in run.t]) - run["theta2"]
    designed = -0.05 * (1 + 10 * run.t) * np.exp(-10 * run.t)
    assert np.abs(error - designed).max() < 1e-8

    e0 = desired - kkt(arm, start, qd_start, np.zeros(3))[1][0]
    x0 = (kf + ki * STEP) * e0
    x1 = -kf * x0 + ki * STEP * (e0 - x0)
    roots = np.roots([1.0, kf - 1.0 + ki * STEP, -kf])
    assert np.abs(roots).max() < 1
    c = np.linalg.solve(np.array([[1.0, 1.0], roots]), [x0, x1])
    k = np.arange(run.t.size)
    expected = desired + np.real(c[0] * roots[0] ** k + c[1] * roots[1] ** k)
    assert abs(e0) > 1.0  # a real transient to follow
    np.testing.assert_allclose(run["lam"][:, 0], expected, atol=1e-8 * abs(e0))
    assert abs(run["lam"][-1, 0] - desired) < 1e-3


def test_command_is_sampled_once_per_period_and_remembered():
    model = cmbs.load("slider-crank-joint", crank_speed=0.0)
    readings = []

    def sensor(t, q, qd, u):
        readings.append(t)
        return np.array([1.0])  # a constant reading: error 2 - 1 = 1 at every sample

    control = ConstraintForceControl(model, 2.0, kf=0.5, ki=5.0, period=0.1, measure=sensor)
    q, qd = model.q0, np.zeros(2)
    at = split(model, q, qd, ForceSensor(model).acceleration(0.0, q, qd))
    commands = {t: control.command(t, q, qd, at)[0] for t in (0.0, 0.05, 0.1, 0.15, 0.3)}
    assert readings == [0.0, 0.1, 0.3]  # RK stages inside a period do not sample
    assert commands[0.0] == commands[0.05] == pytest.approx(2 + 0.5 + 5 * 0.1)
    assert commands[0.1] == commands[0.15] == pytest.approx(2 + 0.5 + 5 * 0.2)
    assert commands[0.3] == pytest.approx(2 + 0.5 + 5 * 0.4)  # two periods elapsed since the last sample
    assert control.command(0.12, q, qd, at)[0] == commands[0.1]  # a retried step
    assert readings == [0.0, 0.1, 0.3] and control.integral[0] == pytest.approx(0.4)


def test_integral_action_removes_the_force_error_of_an_actuator_offset(arm_reference):
    """The plant receives u + d.  Motion: the same as PIDC's under the same offset (the force part
    moves nothing).  Force: with K_i = 0 the steady error is δ/(1 + K_f), δ = λ change due to d
    (Aghili's P law), with K_i > 0 it vanishes."""
    arm, reference = arm_reference
    hold = Reference(cmbs.Trajectory(np.linspace(0, 1, 5), np.tile(arm.q0, (5, 1)), np.zeros((5, 3)),
                                     np.zeros((5, 3)), arm.coordinate_names), ("theta2", "theta3"))
    offset = np.array([0.3, -0.2, 0.1])
    plant = ForceSensor(arm)

    def measure(t, q, qd, u):
        return plant(t, q, qd, u + offset)

    step = 5e-3  # K_i h = 0.1: well inside the stable range
    settings = dict(t_end=1.5, integrator="rk4", dt=step, formulation="projection")
    runs = {ki: cmbs.simulate(arm, u=ActuatorFault(Hybrid(arm, hold, kp=100.0, kd=20.0, force_reference=5.0, kf=0.5,
                                                          ki=ki, period=step, measure=measure), offset=offset),
                              **settings) for ki in (0.0, 20.0)}
    pidc = cmbs.simulate(arm, u=ActuatorFault(PIDC(arm, hold, kp=100.0, kd=20.0), offset=offset), **settings)
    for run in runs.values():
        assert run.info["status"] == "success"
        np.testing.assert_allclose(run.q, pidc.q, atol=1e-10)
    q_end = pidc.q[-1]
    assert np.abs(q_end - arm.q0).max() > 1e-3  # the offset did move the arm
    delta = kkt(arm, q_end, np.zeros(3), offset)[1][0] - kkt(arm, q_end, np.zeros(3), np.zeros(3))[1][0]
    assert abs(delta) > 0.05
    assert runs[0.0]["lam"][-1, 0] - 5.0 == pytest.approx(delta / 1.5, rel=1e-5)
    # K_i > 0: only the lag behind δ(q), which still drifts with the settling motion (∝ t e^{-10t})
    assert abs(runs[20.0]["lam"][-1, 0] - 5.0) < 1e-4 * abs(delta)


def test_constraint_force_control_alone_leaves_the_motion_free():
    arm = cmbs.load("arm-on-slider")
    qd = cmbs.velocities(arm, arm.q0, qd=np.array([0.0, 0.8, -0.5]), fixed=["theta2", "theta3"])
    settings = dict(t_end=1.0, integrator="rk4", dt=STEP, formulation="projection", qd0=qd)
    free = cmbs.simulate(arm, **settings)
    controlled = cmbs.simulate(arm, u=ConstraintForceControl(arm, -3.0, kf=0.3, ki=20.0, period=STEP), **settings)
    np.testing.assert_allclose(controlled.q, free.q, atol=1e-10)
    assert np.abs(free["lam"][:, 0] + 3.0).min() > 0.1  # the free motion has another force
    error = np.abs(controlled["lam"][:, 0] + 3.0)
    assert error[-1] < 1e-5 * error[0]  # slowest mode of the loop: 1 - K_i h / (1 + K_f) per sample
    assert np.abs(controlled["u"]).max() > 1.0


def test_pidc_needs_the_least_torque_at_every_instant(arm_reference):
    """Along one PIDC closed-loop run, the hybrid and the computed-torque laws evaluated at the same
    states give the same acceleration (they differ by Aᵀμ) and never less torque (Aghili Fig. 8(D))."""
    arm, reference = arm_reference
    start, qd_start = start_with_error(arm, reference, 0.05)
    pidc = PIDC(arm, reference, kp=100.0, kd=20.0)
    run = cmbs.simulate(arm, t_end=2.0, u=pidc, q0=start, qd0=qd_start, rtol=1e-9, atol=1e-11, dt=0.01)
    assert run.info["status"] == "success"
    ctc = ComputedTorque(arm, reference, kp=100.0, kd=20.0)
    hybrid = Hybrid(arm, reference, kp=100.0, kd=20.0, force_reference=5.0, kf=0.5, ki=10.0, period=0.01)
    margins = {"hybrid": [], "ctc": []}
    for t, q, qd in zip(run.t, run.q, run.qd):
        tau = pidc(t, q, qd)
        qdd, _ = kkt(arm, q, qd, tau, t)
        for name, other in (("hybrid", hybrid(t, q, qd)), ("ctc", ctc(t, q, qd))):
            np.testing.assert_allclose(kkt(arm, q, qd, other, t)[0], qdd, atol=1e-8 * np.abs(qdd).max())
            assert np.linalg.norm(tau) <= np.linalg.norm(other)
            margins[name].append(np.linalg.norm(other) - np.linalg.norm(tau))
    assert min(margins["hybrid"]) > 0 and min(margins["ctc"]) > 0


def free_link():
    from cmbs.model.joints import JointModelBuilder

    builder = JointModelBuilder("free-link", gravity=(0.0, 0.0))
    builder.add_link("link", parent=None, coordinate="theta", length=1.0, mass=1.0, com=(0.5, 0.0), inertia=0.1)
    builder.add_actuator("tau", coordinate="theta")
    return builder.build()


def test_bad_settings_are_refused(arm_reference):
    arm, reference = arm_reference
    for kf, ki, period, message in ((1.0, 0.0, 1e-3, "kf must be in"), (-0.1, 0.0, 1e-3, "kf must be in"),
                                    (0.5, 1001.0, 1e-3, "ki must be"), (0.5, -1.0, 1e-3, "ki must be"),
                                    (0.5, 1.0, 0.0, "period must be")):
        with pytest.raises(CmbsError, match=message):
            ConstraintForceControl(arm, 5.0, kf=kf, ki=ki, period=period)
    with pytest.raises(CmbsError, match="force_reference"):
        ConstraintForceControl(arm, [1.0, 2.0], kf=0.5, ki=1.0)
    law = Hybrid(arm, reference, kp=1.0, kd=1.0, force_reference=lambda t: [t, t], kf=0.5, ki=1.0)
    with pytest.raises(CmbsError, match="must return 1 multiplier"):
        law(0.0, arm.q0, np.zeros(3))
    with pytest.raises(CmbsError, match="no constraints"):
        ConstraintForceControl(free_link(), 1.0, kf=0.5, ki=1.0)
    with pytest.raises(CmbsError, match="multipliers must have shape"):
        hybrid_torque(arm, arm.q0, np.zeros(3), np.zeros(3), np.zeros(2))
    with pytest.raises(CmbsError, match="violates the constraints"):
        hybrid_torque(arm, arm.q0, np.zeros(3), np.ones(3), np.zeros(1))
