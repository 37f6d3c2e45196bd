"""Udwadia-Kalaba tracking control (control through constraints, Nicoara 2016 §5): the task
outputs against finite differences, the closed-loop task error against the closed-form solution
of ë + K_d ė + K_p e = 0 under every forward formulation, the control force against Gauss's
principle (a KKT solve and random admissible alternatives), the inputs against the force and the
plant's own dynamics, agreement with computed-torque control, and non-realisable tasks."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

import cmbs
from cmbs.control import ComputedTorque, Reference
from cmbs.control.faults import mass_fault
from cmbs.control.udwadia_kalaba import (CirclePath, CoordinateOutput, FunctionOutput, TrackingTask,
                                         UdwadiaKalabaTracking, point_output)
from cmbs.errors import CmbsError
from helpers import SmoothPath, first_derivative_fd, second_derivative_fd

WRONG = (-math.pi / 4, math.pi / 4)         # start of the arms: tip at (1 + √½, -√½), off the circle
CIRCLE = CirclePath(center=(1.0, -0.6), radius=0.4, period=2.0)  # starts at (1.4, -0.6)


# ------------------------------------------------------------------ the two-link arm, two ways
def natural_arm(theta: tuple[float, float] = WRONG) -> cmbs.Model:
    """The library two-link arm (uniform rods 1 m, 1 kg) in natural coordinates with torques on
    θ1 (absolute) and θ2 (relative): M is singular (massless angle coordinates), four constraints."""
    return cmbs.load("two-link-arm", theta1=theta[0], theta2=theta[1])


def joint_arm(theta: tuple[float, float] = WRONG) -> cmbs.Model:
    """The same arm in joint angles (no constraints), with a tool point on the lower link."""
    return cmbs.load("two-link-arm-joint", theta1=theta[0], theta2=theta[1], tool=(0.8, 0.1))


def natural_state(theta: np.ndarray, rate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(q, q̇) of the natural arm (P1.x, P1.z, P2.x, P2.z, θ1, θ2) from joint angles and rates."""
    a1, a12 = theta[0], theta[0] + theta[1]
    w1, w12 = rate[0], rate[0] + rate[1]
    p1, p2 = np.array([math.cos(a1), math.sin(a1)]), np.array([math.cos(a12), math.sin(a12)])
    v1, v2 = w1 * np.array([-p1[1], p1[0]]), w12 * np.array([-p2[1], p2[0]])
    return np.concatenate([p1, p1 + p2, theta]), np.concatenate([v1, v1 + v2, rate])


def on_circle_state() -> tuple[np.ndarray, np.ndarray]:
    """Joint angles and rates putting the arm's end on the circle's start with its velocity
    (inverse kinematics of the unit two-link arm, elbow branch θ2 > 0)."""
    y, yd, _ = CIRCLE(0.0)
    elbow = math.acos((y @ y - 2.0) / 2.0)
    shoulder = math.atan2(y[1], y[0]) - math.atan2(math.sin(elbow), 1.0 + math.cos(elbow))
    s1, s12, c1, c12 = math.sin(shoulder), math.sin(shoulder + elbow), math.cos(shoulder), math.cos(shoulder + elbow)
    jacobian = np.array([[-s1 - s12, -s12], [c1 + c12, c12]])
    return np.array([shoulder, elbow]), np.linalg.solve(jacobian, yd)


def designed_error(t: np.ndarray, e0: np.ndarray, ed0: np.ndarray, kp: np.ndarray, kd: np.ndarray) -> np.ndarray:
    """e(t) of ë + K_d ė + K_p e = 0 per component, by the matrix exponential of its state matrix."""
    out = np.empty((t.size, e0.size))
    for i in range(e0.size):
        system = np.array([[0.0, 1.0], [-kp[i], -kd[i]]])
        out[:, i] = [(scipy.linalg.expm(system * s) @ [e0[i], ed0[i]])[0] for s in t]
    return out


# ------------------------------------------------------------------ outputs
def test_point_outputs_match_positions_and_finite_differences():
    """Ψ from the model's drawn points (or the segment frame built by hand), Ψ_q against central
    differences, Ψ̇_q q̇ against d²Ψ(q + s q̇)/ds² (five-point, O(h⁴))."""
    rng = np.random.default_rng(11)
    natural, joint = natural_arm(), joint_arm()
    q_nat, _ = natural_state(np.array([0.3, 0.9]), np.zeros(2))

    def on_lower(q: np.ndarray) -> np.ndarray:
        """The point (0.3, -0.2) of the natural arm's lower segment: r_P1 + 0.3 e - 0.2 e⊥, |e| = 1."""
        _, p1, p2 = natural.point_positions(q)
        along = p2 - p1
        return p1 + 0.3 * along - 0.2 * np.array([-along[1], along[0]])

    cases = [
        (natural, point_output(natural, "P2"), lambda q: natural.point_positions(q)[2]),
        (natural, point_output(natural, segment="lower", local=(0.3, -0.2)), on_lower),
        (joint, point_output(joint, "lower.end"), lambda q: joint.point_positions(q)[3]),
        (joint, point_output(joint, "tool"), lambda q: joint.point_positions(q)[4]),
        (joint, point_output(joint, segment="lower", local=(0.8, 0.1)), lambda q: joint.point_positions(q)[4]),
    ]
    for model, output, position in cases:
        for _ in range(3):
            theta, rate = rng.uniform(-2, 2, 2), rng.normal(size=2)
            q, qd = natural_state(theta, rate) if model is natural else (theta, rate)
            np.testing.assert_allclose(output.value(q), position(q), atol=1e-14)
            columns = [(position(q + 1e-6 * e) - position(q - 1e-6 * e)) / 2e-6 for e in np.eye(model.n)]
            np.testing.assert_allclose(output.jacobian(q), np.array(columns).T, atol=1e-9)
            np.testing.assert_allclose(output.bias(q, qd), second_derivative_fd(lambda s: position(q + s * qd), 0.0),
                                       atol=1e-8)
    # wrapped evaluators (driver removal, mass faults) keep the geometry
    faulty = mass_fault(natural, "lower", factor=1.1, t0=0.5).without_drivers()
    np.testing.assert_allclose(point_output(faulty, segment="lower", local=(0.3, -0.2)).value(q_nat), on_lower(q_nat),
                               atol=1e-15)


def test_function_output_derivatives_by_finite_differences():
    """The documented accuracy of the fallback differences, against the exact joint-arm tip."""
    joint = joint_arm()
    exact = point_output(joint, "lower.end")
    differenced = FunctionOutput(exact.value, ("x", "z"))
    half = FunctionOutput(exact.value, ("x", "z"), jacobian=exact.jacobian)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q, qd = rng.uniform(-2, 2, 2), rng.normal(size=2)
        np.testing.assert_allclose(differenced.jacobian(q), exact.jacobian(q), atol=1e-9)
        np.testing.assert_allclose(differenced.bias(q, qd), exact.bias(q, qd), atol=1e-6 * (1 + qd @ qd))
        np.testing.assert_allclose(half.bias(q, qd), exact.bias(q, qd), atol=1e-9 * (1 + qd @ qd))
    assert np.array_equal(differenced.bias(q, np.zeros(2)), np.zeros(2))
    with pytest.raises(CmbsError, match=r"shape \(3,\), expected \(2,\)"):
        FunctionOutput(lambda q: np.zeros(3), ("x", "z")).value(q)


def test_circle_path_derivatives():
    for path in (CIRCLE, CirclePath((0.5, 0.2), 0.3, -1.5, phase=1.0)):
        for t in (0.0, 0.37, 1.9):
            y, yd, ydd = path(t)
            np.testing.assert_allclose(yd, first_derivative_fd(lambda s: path(s)[0], t), atol=1e-9)
            np.testing.assert_allclose(ydd, second_derivative_fd(lambda s: path(s)[0], t), atol=1e-6)
            assert np.linalg.norm(y - path.center) == pytest.approx(path.radius)


# ------------------------------------------------------------------ closed loop
CLOSED_LOOP = {
    "natural-lagrange": ("natural", dict(formulation="lagrange")),
    "natural-baumgarte": ("natural", dict(formulation="baumgarte")),
    "natural-penalty": ("natural", dict(formulation="penalty")),
    "natural-matrix-r": ("natural", dict(formulation="matrix-r")),
    "natural-projection": ("natural", dict(formulation="projection")),
    "natural-udwadia-kalaba": ("natural", dict(formulation="udwadia-kalaba")),
    "natural-trapezoidal": ("natural", dict(integrator="trapezoidal", dt=0.002)),
    "joint-lagrange": ("joint", dict(formulation="lagrange")),
}


@pytest.mark.parametrize("case", sorted(CLOSED_LOOP))
def test_task_error_follows_the_designed_dynamics_from_a_wrong_start(case):
    """Exact model, arm at rest off the circle: the measured tip error (from the model's drawn
    points) equals the closed-form e(t) of ë + K_d ė + K_p e = 0, per-axis gains (critically
    damped in x, underdamped in z), under every forward formulation."""
    kind, options = CLOSED_LOOP[case]
    model = natural_arm() if kind == "natural" else joint_arm()
    point = "P2" if kind == "natural" else "tool"
    kp, kd = np.array([100.0, 64.0]), np.array([20.0, 10.0])
    law = UdwadiaKalabaTracking(model, TrackingTask(point_output(model, point), CIRCLE), kp=kp, kd=kd)
    implicit = "integrator" in options
    t_end = 0.3 if implicit else 1.2
    settings = dict(rtol=1e-10, atol=1e-12, dt=0.01) | options
    q0 = cmbs.assemble(model, model.q0)
    run = cmbs.simulate(model, t_end=t_end, u=law, q0=q0, qd0=np.zeros(model.n), **settings)
    assert run.info["status"] == "success", run.info.get("message")
    column = model.point_names.index(point)
    tip = np.array([model.point_positions(q)[column] for q in run.q])
    desired = np.array([CIRCLE(t)[0] for t in run.t])
    e0 = desired[0] - tip[0]
    expected = designed_error(run.t, e0, CIRCLE(0.0)[1], kp, kd)
    assert np.linalg.norm(e0) > 0.1
    tolerance = 2e-5 if implicit else 2e-8  # trapezoidal: O(h²) with h = 2 ms; explicit: rtol 1e-10
    assert np.abs((desired - tip) - expected).max() < tolerance


@pytest.mark.parametrize("kind", ["natural", "joint"])
def test_a_start_on_the_path_stays_on_it(kind):
    theta, rate = on_circle_state()
    if kind == "natural":
        model, point = natural_arm(tuple(theta)), "P2"
        q0, qd0 = natural_state(theta, rate)
    else:
        model, point = joint_arm(tuple(theta)), "lower.end"
        q0, qd0 = theta, rate
    law = UdwadiaKalabaTracking(model, TrackingTask(point_output(model, point), CIRCLE), kp=100.0, kd=20.0)
    run = cmbs.simulate(model, t_end=2.0, u=law, q0=q0, qd0=qd0, rtol=1e-10, atol=1e-12, dt=0.01)
    column = model.point_names.index(point)
    error = [np.linalg.norm(model.point_positions(q)[column] - CIRCLE(t)[0]) for t, q in zip(run.t, run.q)]
    assert error[0] < 1e-14
    assert max(error) < 1e-8


# ------------------------------------------------------------------ the force
def random_state(model: cmbs.Model, rng: np.random.Generator) -> tuple[float, np.ndarray, np.ndarray]:
    """A random consistent state near the model's start."""
    q = cmbs.assemble(model, model.q0 + 0.1 * rng.normal(size=model.n))
    qd = cmbs.velocities(model, q, qd=rng.normal(size=model.n))
    return float(rng.uniform(0, 2)), q, qd


GAUSS_CASES = {
    "passive-manipulator-joint-tip": lambda: (cmbs.load("passive-manipulator-joint"),
                                              lambda m: point_output(m, "link3.end"), CirclePath((7.0, 3.0), 1.0, 4.0)),
    "arm-on-slider-theta1": lambda: (cmbs.load("arm-on-slider"), lambda m: CoordinateOutput(m, ["theta1"]),
                                     lambda t: (np.array([math.sin(t)]), np.array([math.cos(t)]),
                                                np.array([-math.sin(t)]))),
}


@pytest.mark.parametrize("case", sorted(GAUSS_CASES))
def test_force_obeys_gauss_principle(case):
    """Q_c = M q̈* - Q equals the KKT solution of min ½(q̈ - a)ᵀM(q̈ - a) s.t. [A; Ψ_q] q̈ = [γ; b_task];
    it is an ideal constraint force (in range [A; Ψ_q]ᵀ); every other force achieving the task
    acceleration has a larger Gauss function (M q̈ - Q)ᵀM⁻¹(M q̈ - Q), larger by exactly δᵀMδ."""
    model, make_output, desired = GAUSS_CASES[case]()
    output = make_output(model)
    kp, kd = 49.0, 14.0
    law = UdwadiaKalabaTracking(model, TrackingTask(output, desired), kp=kp, kd=kd, tolerance=None)
    rng = np.random.default_rng(5)
    for _ in range(4):
        t, q, qd = random_state(model, rng)
        step = law.step(t, q, qd)
        terms = model.evaluate(q, qd, t)
        M, Q = terms.M.copy(), terms.Q.copy()
        J = output.jacobian(q)
        y_d, yd_d, ydd_d = desired(t)
        b_task = ydd_d + kd * (yd_d - J @ qd) + kp * (y_d - output.value(q)) - output.bias(q, qd)
        A_s, b_s = np.vstack([terms.A, J]), np.concatenate([terms.gamma, b_task])
        k = A_s.shape[0]
        kkt = np.block([[M, A_s.T], [A_s, np.zeros((k, k))]])
        solution = np.linalg.solve(kkt, np.concatenate([Q, b_s]))
        qdd, multipliers = solution[:model.n], solution[model.n:]
        scale = np.abs(Q).max() + np.abs(M @ qdd).max()
        np.testing.assert_allclose(step.qdd, qdd, atol=1e-9 * np.abs(qdd).max())
        np.testing.assert_allclose(step.constraint_force, -A_s.T @ multipliers, atol=1e-9 * scale)
        gauss = lambda force: force @ np.linalg.solve(M, force)
        best = gauss(step.constraint_force)
        null = scipy.linalg.null_space(A_s)
        assert null.shape[1] >= 1
        for size in (1e-3, 1e-1, 10.0):
            delta = null @ rng.normal(size=null.shape[1]) * size
            alternative = M @ (step.qdd + delta) - Q
            np.testing.assert_allclose(A_s @ (step.qdd + delta), b_s, atol=1e-8 * (1 + np.abs(b_s).max()))
            assert gauss(alternative) > best
            assert gauss(alternative) - best == pytest.approx(delta @ M @ delta, rel=1e-6, abs=1e-12 * scale**2)


def symmetric_root_solution(M: np.ndarray, Q: np.ndarray, A_s: np.ndarray,
                            b_s: np.ndarray) -> np.ndarray:
    """q̈* of Nicoara eq. (11) with the symmetric square root of a definite M and numpy's
    pseudo-inverse, the rows of B = A_s M^{-1/2} scaled to unit norm by D:
    q̈* = a + M^{-1/2} (D B)⁺ D (b_s - A_s a), a = M⁻¹Q."""
    values, vectors = np.linalg.eigh(M)
    inverse_root = (vectors / np.sqrt(values)) @ vectors.T
    a = np.linalg.solve(M, Q)
    B = A_s @ inverse_root
    D = 1.0 / np.linalg.norm(B, axis=1)
    return a + inverse_root @ np.linalg.pinv(D[:, None] * B) @ (D * (b_s - A_s @ a))


def stretched_joint_arm_task():
    """The joint arm at full stretch (θ2 = 0): the tip's Jacobian has rank 1 and the circle's
    demand is inconsistent, so Gauss's solution is the least-squares one of the pseudo-inverse."""
    model = joint_arm((0.3, 0.0))
    return model, TrackingTask(point_output(model, "lower.end"), CIRCLE), np.array([0.3, 0.0]), np.array([0.4, -0.2])


def redundant_joint_arm_task():
    """The joint arm told to move θ1 and 2θ1 along φ(t) and 2φ(t): two dependent, consistent rows."""
    model = joint_arm()
    twice = FunctionOutput(lambda q: np.array([q[0], 2.0 * q[0]]), ("theta1", "twice theta1"),
                           jacobian=lambda q: np.array([[1.0, 0.0], [2.0, 0.0]]))
    desired = lambda t: (np.array([1.0, 2.0]) * math.sin(t), np.array([1.0, 2.0]) * math.cos(t),
                         -np.array([1.0, 2.0]) * math.sin(t))
    return model, TrackingTask(twice, desired), np.array([0.2, 0.9]), np.array([-0.5, 0.3])


def natural_arm_task():
    """The natural arm (semi-definite M, four plant constraints) drawing the circle."""
    model = natural_arm()
    return (model, TrackingTask(point_output(model, "P2"), CIRCLE)) + natural_state(np.array([0.4, 1.1]),
                                                                                       np.array([0.7, -0.3]))


@pytest.mark.parametrize("make", [natural_arm_task, stretched_joint_arm_task, redundant_joint_arm_task],
                         ids=["natural-arm", "stretched-joint-arm", "redundant-task"])
def test_force_is_the_symmetric_root_formula(make):
    """q̈* and Q_c = M q̈* - Q against Nicoara eq. (11), (19) computed with the symmetric square
    root and numpy's pseudo-inverse, also where [A; Ψ_q] loses rank (the KKT solve of
    test_force_obeys_gauss_principle is singular there).  The natural arm's M is semi-definite:
    the formula takes M + s AᵀA, Q + s Aᵀγ (s = trace M / n), which has the same q̈* on A q̈ = γ."""
    model, task, q, qd = make()
    kp, kd = np.array([100.0, 64.0]), np.array([20.0, 10.0])
    t = 0.7
    step = UdwadiaKalabaTracking(model, task, kp=kp, kd=kd, tolerance=None).step(t, q, qd)
    terms = model.evaluate(q, qd, t)
    J = task.output.jacobian(q)
    y_d, yd_d, ydd_d = task.desired(t)
    b_task = ydd_d + kd * (yd_d - J @ qd) + kp * (y_d - task.output.value(q)) - task.output.bias(q, qd)
    A_s, b_s = np.vstack([terms.A, J]), np.concatenate([terms.gamma, b_task])
    M, Q = terms.M, terms.Q
    if model.m:
        s = np.trace(M) / model.n
        M, Q = M + s * terms.A.T @ terms.A, Q + s * terms.A.T @ terms.gamma
    else:
        assert np.linalg.matrix_rank(A_s) < A_s.shape[0]      # dependent task rows
    qdd = symmetric_root_solution(M, Q, A_s, b_s)
    force = terms.M @ qdd - terms.Q
    np.testing.assert_allclose(step.qdd, qdd, rtol=0, atol=1e-10 * np.abs(qdd).max())
    np.testing.assert_allclose(step.constraint_force, force, rtol=0, atol=1e-10 * np.abs(force).max())


def test_inputs_realise_the_force_without_plant_constraints():
    """Open chain (m = 0): G u = Q_c exactly, where G u is measured as Q(u) - Q(0)."""
    model = joint_arm()
    law = UdwadiaKalabaTracking(model, TrackingTask(point_output(model, "tool"), CIRCLE), kp=100.0, kd=20.0)
    rng = np.random.default_rng(8)
    for _ in range(4):
        t, q, qd = float(rng.uniform(0, 2)), rng.uniform(-2, 2, 2), rng.normal(size=2)
        step = law.step(t, q, qd)
        applied = model.forces(q, qd, t, step.u) - model.forces(q, qd, t)
        np.testing.assert_allclose(applied, step.constraint_force, atol=1e-10 * np.abs(step.constraint_force).max())
        np.testing.assert_allclose(step.actuator_force, applied, atol=1e-12 * np.abs(applied).max())
        assert step.residual < 1e-10 * np.abs(step.constraint_force).max() and step.unrealisable < 1e-12


@pytest.mark.parametrize("case", ["natural-arm", "arm-on-slider"])
def test_inputs_give_the_plant_the_task_acceleration(case):
    """With plant constraints: G u differs from Q_c only by a plant reaction Aᵀμ, so the plant's
    own dynamics [M Aᵀ; A 0][q̈; λ] = [Q + G u; γ] gives q̈*.  Arm on slider (3 motors, 2 DOF):
    u is the minimum-norm one among all inputs that do it (orthogonal to {v : G v ∈ range Aᵀ})."""
    rng = np.random.default_rng(21)
    if case == "natural-arm":
        model = natural_arm()
        output, desired = point_output(model, "P2"), CIRCLE
    else:
        model = cmbs.load("arm-on-slider")
        output, desired = point_output(model, "link2.end"), CirclePath((0.3, 0.6), 0.05, 1.0)
    law = UdwadiaKalabaTracking(model, TrackingTask(output, desired), kp=100.0, kd=20.0)
    for _ in range(4):
        if case == "natural-arm":
            t = float(rng.uniform(0, 2))
            q, qd = natural_state(rng.uniform(-2, 2, 2), rng.normal(size=2))
        else:
            t, q, qd = random_state(model, rng)
        step = law.step(t, q, qd)
        terms = model.evaluate(q, qd, t, step.u)
        m = model.m
        kkt = np.block([[terms.M, terms.A.T], [terms.A, np.zeros((m, m))]])
        qdd = np.linalg.solve(kkt, np.concatenate([terms.Q, terms.gamma]))[:model.n]
        np.testing.assert_allclose(qdd, step.qdd, atol=1e-9 * np.abs(qdd).max())
        assert step.unrealisable < 1e-9
        if case == "arm-on-slider":
            G = np.array([model.forces(q, qd, t, e) - model.forces(q, qd, t) for e in np.eye(model.n_u)]).T
            inputs_only = scipy.linalg.null_space(np.hstack([G, -terms.A.T]))[:model.n_u]
            assert inputs_only.shape[1] == 1  # one redundant motor
            assert abs(inputs_only[:, 0] @ step.u) < 1e-9 * np.linalg.norm(step.u)


# ------------------------------------------------------------------ computed torque
def coordinate_reference(model: cmbs.Model, coordinates: tuple[str, ...], rng) -> Reference:
    """A smooth reference for ``coordinates`` (other columns unused), as a sampled Trajectory."""
    columns = model.coordinate_indices(list(coordinates))
    path = SmoothPath(np.asarray(model.q0, float)[columns], rng)
    t = np.linspace(0.0, 3.0, 601)
    q = np.zeros((t.size, model.n))
    q[:, columns] = [path.q(s) for s in t]
    return Reference(cmbs.Trajectory(t, q, np.zeros_like(q), np.zeros_like(q), model.coordinate_names), coordinates)


@pytest.mark.parametrize("case", ["natural-arm", "joint-arm", "arm-on-slider"])
def test_agrees_with_computed_torque_on_independent_coordinates(case):
    """Task = the independent coordinates of a fully actuated system: the stacked constraints fix
    q̈ = R z̈_c + S and the force Rᵀ(M q̈ - Q) is unique, so both laws give the same inputs.
    Natural arm: massless angle coordinates; arm on slider: dependent θ1, motors τ2, τ3 only."""
    rng = np.random.default_rng(13)
    model = {"natural-arm": natural_arm, "joint-arm": joint_arm, "arm-on-slider": lambda: cmbs.load("arm-on-slider")}[
        case]()
    coordinates, actuators = (("theta2", "theta3"), ("tau2", "tau3")) if case == "arm-on-slider" else \
        (("theta1", "theta2"), None)
    reference = coordinate_reference(model, coordinates, rng)
    gains = dict(kp=[100.0, 60.0], kd=[20.0, 9.0])
    ctc = ComputedTorque(model, reference, **gains)
    law = UdwadiaKalabaTracking(model, TrackingTask(CoordinateOutput(model, coordinates), reference),
                                actuators=actuators, **gains)
    for _ in range(5):
        if case == "natural-arm":
            t = float(rng.uniform(0, 3))
            q, qd = natural_state(rng.uniform(-2, 2, 2), rng.normal(size=2))
        elif case == "joint-arm":
            t, q, qd = float(rng.uniform(0, 3)), rng.uniform(-2, 2, 2), rng.normal(size=2)
        else:
            t, q, qd = random_state(model, rng)
        expected = ctc(t, q, qd)
        np.testing.assert_allclose(law(t, q, qd), expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())


# ------------------------------------------------------------------ not realisable, user mistakes
def test_a_task_the_actuators_cannot_produce_raises():
    """3-link arm with a passive third joint: the least-constraint force for its tip needs a
    torque at joint 3 (ρ ≈ 0.3); θ1 alone is realisable; three outputs for two motors fail at once."""
    model = cmbs.load("passive-manipulator")
    t, q, qd = 0.0, cmbs.assemble(model, model.q0), np.zeros(model.n)
    tip = TrackingTask(point_output(model, "P3"), CirclePath((7.0, 3.0), 1.0, 4.0))
    with pytest.raises(CmbsError, match=r"P3.x, P3.z needs generalized forces .* \(tau1, tau2\).* not realisable"):
        UdwadiaKalabaTracking(model, tip, kp=100.0, kd=20.0)(t, q, qd)
    least_squares = UdwadiaKalabaTracking(model, tip, kp=100.0, kd=20.0, tolerance=None).step(t, q, qd)
    assert 0.1 < least_squares.unrealisable <= 1.0 and least_squares.residual > 1.0
    held = lambda t: (np.array([1.0]), np.zeros(1), np.zeros(1))
    assert UdwadiaKalabaTracking(model, TrackingTask(CoordinateOutput(model, ["theta1"]), held), kp=1.0,
                                 kd=1.0).step(t, q, qd).unrealisable < 1e-12
    every_angle = TrackingTask(CoordinateOutput(model, ["theta1", "theta2", "theta3"]),
                               lambda t: (np.zeros(3), np.zeros(3), np.zeros(3)))
    with pytest.raises(CmbsError, match="3 outputs but only 2 actuator"):
        UdwadiaKalabaTracking(model, every_angle, kp=1.0, kd=1.0)
    # in closed loop the run stops with the message instead of a traceback
    run = cmbs.simulate(model, t_end=0.1, u=UdwadiaKalabaTracking(model, tip, kp=100.0, kd=20.0), dt=0.01)
    assert run.info["status"] == "failed" and "not realisable" in run.info["message"]


def test_user_mistakes_name_the_culprit():
    natural, joint = natural_arm(), joint_arm()
    task = TrackingTask(point_output(natural, "P2"), CIRCLE)
    cases = [
        (lambda: point_output(natural, "Q"), "no point 'Q'"),
        (lambda: point_output(natural, "O"), "'O' .* fixed to the ground"),
        (lambda: point_output(natural, segment="middle", local=(0.1, 0.0)), "no segment 'middle'"),
        (lambda: point_output(joint, segment="middle", local=(0.1, 0.0)), "no link 'middle'"),
        (lambda: point_output(joint, segment="lower"), "needs local"),
        (lambda: point_output(joint, "tool", segment="lower", local=(0, 0)), "either a point name or"),
        (lambda: CoordinateOutput(natural, ["theta9"]), "no coordinate 'theta9'"),
        (lambda: UdwadiaKalabaTracking(natural, task, kp=1.0, kd=1.0, actuators=["tau3"]), "no actuator.* tau3"),
        (lambda: UdwadiaKalabaTracking(natural, task, kp=[1.0, 2.0, 3.0], kd=1.0), "gain kp"),
        (lambda: UdwadiaKalabaTracking(natural, task, kp=1.0, kd=1.0, tolerance=-1.0), "tolerance"),
        (lambda: UdwadiaKalabaTracking(natural, TrackingTask(task.output, lambda t: (np.zeros(3),) * 3), kp=1.0,
                                       kd=1.0), r"three \(2,\) arrays"),
        (lambda: UdwadiaKalabaTracking(cmbs.load("double-pendulum"), TrackingTask(
            point_output(cmbs.load("double-pendulum"), "P2"), CIRCLE), kp=1.0, kd=1.0), "no actuators"),
        (lambda: CirclePath((0, 0), -1.0, 1.0), "radius"),
        (lambda: CirclePath((0, 0), 1.0, 0.0), "period"),
    ]
    for make, message in cases:
        with pytest.raises(CmbsError, match=message):
            make()
