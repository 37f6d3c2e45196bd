"""Tests of the planar joint-coordinate builder (cmbs.model.joints).

Reference values never come from the code under test: kinematics is recomputed by an
independent forward-kinematics function written here (complex-step derivatives make its
Jacobians exact to rounding), the constraint derivatives are checked by finite differences, the
velocity terms by Lagrange's equations of an independently computed kinetic energy, and the
double pendulum by the textbook closed form.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from cmbs.errors import ModelError
from cmbs.model.drivers import PythonFunction, Table
from cmbs.model.joints import JointModelBuilder

G = 9.81
CS = 1e-30  # complex step: derivative = Im f(x + i h) / h, exact to rounding (no subtraction)


# ---------------------------------------------------------------- independent kinematics
def forward(spec: list[dict], q: np.ndarray) -> dict[str, tuple]:
    """Per link: (θ, O, G, end) from the definition (revolute/prismatic), complex-safe."""
    out: dict[str, tuple] = {}
    pending = list(range(len(spec)))
    while pending:
        for k in list(pending):
            link = spec[k]
            parent = link.get("parent")
            if parent is not None and parent not in out:
                continue
            thp, Op = (0.0, np.zeros(2)) if parent is None else out[parent][:2]
            rot_p = np.array([[np.cos(thp), -np.sin(thp)], [np.sin(thp), np.cos(thp)]])
            origin = rot_p @ np.asarray(link.get("origin", (0.0, 0.0)), float)
            if link.get("joint", "revolute") == "revolute":
                th = thp + link.get("angle", 0.0) + q[k]
                O = Op + origin
            else:
                th = thp + link.get("angle", 0.0) + 0.0 * q[k]
                O = Op + origin + q[k] * np.array([np.cos(th), np.sin(th)])
            rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
            out[link["name"]] = (th, O, O + rot @ np.asarray(link["com"], float),
                                 O + rot @ np.array([link["length"], 0.0]))
            pending.remove(k)
    return out


def velocities(spec, q, qd):
    """COM velocities and angular velocities by a complex-step directional derivative."""
    moved = forward(spec, q + 1j * CS * qd)
    return {name: (np.imag(value[2]) / CS, np.imag(value[0]) / CS) for name, value in moved.items()}


def kinetic_energy(spec, q, qd) -> float:
    v = velocities(spec, q, qd)
    return sum(0.5 * link["mass"] * v[link["name"]][0] @ v[link["name"]][0]
               + 0.5 * link["inertia"] * v[link["name"]][1] ** 2 for link in spec)


def build(spec, *, closures=(), drivers=(), actuators=(), points=(), gravity=(0.0, -G)):
    builder = JointModelBuilder("test", gravity=gravity)
    for link in spec:
        builder.add_link(**link)
    for point in points:
        builder.add_point(**point)
    for closure in closures:
        builder.add_closure(**closure)
    for coordinate, function in drivers:
        builder.add_driver(coordinate, function)
    for actuator in actuators:
        builder.add_actuator(**actuator)
    return builder.build()


def link(name, parent, coordinate, **options):
    options.setdefault("length", 1.0)
    options.setdefault("mass", 1.0)
    options.setdefault("com", (options["length"] / 2, 0.0))
    options.setdefault("inertia", options["mass"] * options["length"] ** 2 / 12)
    return dict(name=name, parent=parent, coordinate=coordinate, **options)


# A tree: two branches from a root, a prismatic joint on a rotating link, offsets and off-axis COMs.
TREE = [
    link("base", None, "q1", origin=(0.1, -0.2), angle=0.3, length=0.8, mass=2.0, com=(0.3, 0.05), inertia=0.11),
    link("slider", "base", "s", joint="prismatic", origin=(0.2, 0.1), angle=-0.4, length=0.3, mass=0.7,
         com=(0.1, -0.03), inertia=0.02),
    link("arm", "slider", "q3", origin=(0.3, 0.0), angle=0.2, length=0.6, mass=1.1, com=(0.35, 0.08), inertia=0.05),
    link("branch", "base", "q4", origin=(0.8, 0.0), length=0.5, mass=0.9, com=(0.2, -0.1), inertia=0.03),
]
FOURBAR = [
    link("crank", None, "a", length=0.4, mass=1.0),
    link("coupler", "crank", "b", origin=(0.4, 0.0), length=1.2, mass=2.0, com=(0.5, 0.1), inertia=0.3),
    link("rocker", None, "c", origin=(1.0, 0.0), length=0.9, mass=1.5),
]


@pytest.fixture(scope="module")
def tree_model():
    return build(TREE, actuators=[dict(name="u1", coordinate="q1", gain=2.0), dict(name="u2", coordinate="s")])


# ---------------------------------------------------------------- (1) kinematics and mass matrix
def test_point_positions_match_independent_kinematics(tree_model):
    rng = np.random.default_rng(1)
    for _ in range(5):
        q = rng.uniform(-2, 2, 4)
        reference = forward(TREE, q)
        positions = tree_model.point_positions(q)
        for name, (th, O, _, end) in reference.items():
            np.testing.assert_allclose(positions[tree_model.point_names.index(f"{name}.origin")], O, atol=1e-14)
            np.testing.assert_allclose(positions[tree_model.point_names.index(f"{name}.end")], end, atol=1e-14)
    assert tree_model.lines == ((0, 1), (2, 3), (4, 5), (6, 7))
    assert tree_model.coordinate_names == ("q1", "s", "q3", "q4")
    assert tree_model.coordinate_kinds == ("joint",) * 4
    assert tree_model.segment_masses == (("base", 2.0), ("slider", 0.7), ("arm", 1.1), ("branch", 0.9))


def test_mass_matrix_from_independent_jacobians(tree_model):
    # M = Σ m J_GᵀJ_G + I ωᵀω with J from complex-step derivatives of the test's own kinematics:
    # exact to rounding, so the tolerance is a few ulps of |M| (1e-12 relative).
    rng = np.random.default_rng(2)
    for _ in range(5):
        q = rng.uniform(-2, 2, 4)
        reference = np.zeros((4, 4))
        for lk in TREE:
            J = np.zeros((2, 4))
            w = np.zeros(4)
            for i in range(4):
                v, omega = velocities(TREE, q, np.eye(4)[i])[lk["name"]]
                J[:, i], w[i] = v, omega
            reference += lk["mass"] * J.T @ J + lk["inertia"] * np.outer(w, w)
        M = tree_model.mass_matrix(q)
        np.testing.assert_allclose(M, reference, rtol=1e-12, atol=1e-12 * np.abs(reference).max())
        qd = rng.normal(size=4)
        assert tree_model.kinetic_energy(q, qd) == pytest.approx(kinetic_energy(TREE, q, qd), rel=1e-12)


def test_potential_energy_and_gravity_force(tree_model):
    # V = -Σ m g·r_G from the independent kinematics; the gravity part of Q (q̇ = 0, u = 0) is -∂V/∂q,
    # checked by a central difference (h = 1e-6: truncation ~1e-12, rounding ~1e-10 relative).
    rng = np.random.default_rng(3)
    g = np.array([0.0, -G])

    def V(q):
        return -sum(lk["mass"] * g @ forward(TREE, q)[lk["name"]][2] for lk in TREE)

    q = rng.uniform(-2, 2, 4)
    assert tree_model.potential_energy(q) == pytest.approx(V(q), rel=1e-13, abs=1e-13)
    h = 1e-6
    dV = np.array([(V(q + h * e) - V(q - h * e)) / (2 * h) for e in np.eye(4)])
    np.testing.assert_allclose(tree_model.forces(q, np.zeros(4)), -dV, atol=1e-7)


def test_actuators_enter_q_with_their_gain(tree_model):
    q, qd = np.array([0.1, 0.2, 0.3, 0.4]), np.array([0.5, -0.2, 0.1, 0.3])
    difference = tree_model.forces(q, qd, u=np.array([1.5, -3.0])) - tree_model.forces(q, qd)
    np.testing.assert_allclose(difference, [2.0 * 1.5, -3.0, 0.0, 0.0], atol=1e-12)
    assert tree_model.actuator_names == ("u1", "u2")


# ---------------------------------------------------------------- (3) velocity terms by Lagrange
def test_velocity_terms_satisfy_lagranges_equations(tree_model):
    # c(q, q̇) = (∂²T/∂q̇∂q) q̇ - ∂T/∂q with T from the test's kinematics (complex step, exact).
    # ∂T/∂q̇ is a central difference of a quadratic in q̇ (exact up to rounding); the outer
    # differences (h = 1e-5) carry O(h²) ≈ 1e-10 truncation and ~1e-10 rounding: tolerance 1e-7.
    rng = np.random.default_rng(4)
    n, h = 4, 1e-5
    eye = np.eye(n)

    def p(q, qd):
        return np.array([(kinetic_energy(TREE, q, qd + e) - kinetic_energy(TREE, q, qd - e)) / 2 for e in eye])

    for _ in range(3):
        q, qd = rng.uniform(-2, 2, n), rng.normal(size=n)
        dp_dq_qd = (p(q + h * qd, qd) - p(q - h * qd, qd)) / (2 * h)
        dT_dq = np.array([(kinetic_energy(TREE, q + h * e, qd) - kinetic_energy(TREE, q - h * e, qd)) / (2 * h)
                          for e in eye])
        coriolis = dp_dq_qd - dT_dq
        velocity_part = tree_model.forces(q, qd) - tree_model.forces(q, np.zeros(n))
        np.testing.assert_allclose(velocity_part, -coriolis, atol=1e-7 * max(1.0, np.abs(coriolis).max()))


# ---------------------------------------------------------------- (2) constraint derivatives
def closed_models():
    fourbar = build(FOURBAR, closures=[dict(name="pin", point="coupler.end", to="rocker.end")],
                    drivers=[("a", "0.3*sin(2*t) + 0.1*t^2")])
    tree = build(TREE, points=[dict(name="tip", link="arm", local=(0.5, 0.1)),
                               dict(name="knob", link="branch", local=(0.4, 0.2))],
                 closures=[dict(name="wall", point="tip", to=(1.0, 0.5), directions="x"),
                           dict(name="tilt", point="knob", to="tip", directions=(0.6, -0.8)),
                           dict(name="floor", point="slider.end", to=(0.0, -1.0), directions="z")],
                 drivers=[("s", "0.2*cos(3*t)")])
    return [fourbar, tree]


@pytest.mark.parametrize("model", closed_models(), ids=["fourbar", "tree"])
def test_jacobian_phi_t_and_gamma_by_finite_differences(model):
    rng = np.random.default_rng(5)
    n = model.n
    # A by central differences (h = 1e-6; truncation ~1e-12, rounding ~1e-10): tolerance 1e-8.
    q, t = rng.uniform(-1.5, 1.5, n), 0.37
    h = 1e-6
    A_fd = np.column_stack([(model.constraints(q + h * e, t) - model.constraints(q - h * e, t)) / (2 * h)
                            for e in np.eye(n)])
    np.testing.assert_allclose(model.jacobian(q, t), A_fd, atol=1e-8)
    phi_t_fd = (model.constraints(q, t + h) - model.constraints(q, t - h)) / (2 * h)
    np.testing.assert_allclose(model.constraints_t(q, t), phi_t_fd, atol=1e-8)
    # γ = A q̈ - Φ̈ along a smooth path q(s) = a + b s + c sin(ω s); Φ̈ by the five-point stencil
    # (h = 1e-3: truncation O(h⁴) ~ 1e-11, rounding ~ 1e-16/h² ~ 1e-10): tolerance 1e-7.
    a, b, c, omega = rng.uniform(-1, 1, n), rng.normal(size=n), rng.normal(size=n), 1.7

    def path(s):
        return a + b * s + c * np.sin(omega * s)

    def phi(s):
        return model.constraints(path(s), s)

    for s in (0.2, 1.1):
        h = 1e-3
        phi_dd = (-phi(s + 2 * h) + 16 * phi(s + h) - 30 * phi(s) + 16 * phi(s - h) - phi(s - 2 * h)) / (12 * h * h)
        qd = b + c * omega * np.cos(omega * s)
        qdd = -c * omega ** 2 * np.sin(omega * s)
        A = model.jacobian(path(s), s)
        np.testing.assert_allclose(model.gamma(path(s), qd, s), A @ qdd - phi_dd, atol=1e-7)


def test_closure_and_driver_values():
    # Φ from the independent kinematics; driver rows from the closed form of the expression.
    model = closed_models()[0]
    q, t = np.array([0.4, -0.9, 1.3]), 0.8
    ref = forward(FOURBAR, q)
    assert model.constraint_names == ("pin.x", "pin.z", "a-driver")
    assert list(model.drivers) == [False, False, True]
    expected = list(ref["coupler"][3] - ref["rocker"][3]) + [0.4 - (0.3 * math.sin(1.6) + 0.1 * t * t)]
    np.testing.assert_allclose(model.constraints(q, t), expected, atol=1e-14)
    np.testing.assert_allclose(model.constraints_t(q, t)[2], -(0.6 * math.cos(1.6) + 0.2 * t), atol=1e-14)
    np.testing.assert_allclose(model.gamma(q, np.zeros(3), t)[2], -1.2 * math.sin(1.6) + 0.2, atol=1e-14)
    np.testing.assert_allclose(model.jacobian(q, t)[2], [1.0, 0.0, 0.0])


def test_python_and_table_drivers_match_the_function():
    # A Python callable (derivatives given) and a spline table of a cubic (reproduced exactly by a
    # not-a-knot spline) must give Φ = q - f, Φ_t = -f', γ = f''.
    times = np.linspace(0.0, 2.0, 9)
    functions = {
        "python": (PythonFunction(math.sin, math.cos, lambda t: -math.sin(t)),
                   (math.sin(0.7), math.cos(0.7), -math.sin(0.7))),
        "table": (Table(times, times ** 3 - times, "spline"), (0.7 ** 3 - 0.7, 3 * 0.49 - 1, 6 * 0.7)),
    }
    for kind, (function, (f, f1, f2)) in functions.items():
        model = build(FOURBAR[:1], drivers=[("a", function)])
        terms = model.evaluate(np.array([0.25]), np.zeros(1), 0.7)
        np.testing.assert_allclose([terms.phi[0], terms.phi_t[0], terms.gamma[0]], [0.25 - f, -f1, f2],
                                   atol=1e-12, err_msg=kind)


# ---------------------------------------------------------------- (6) double pendulum closed form
def test_double_pendulum_closed_form():
    # Spong, Hutchinson & Vidyasagar, Robot Modeling and Control, §7.4.1 (relative angles from
    # the horizontal x axis, gravity -z): M, Coriolis and gravity terms; exact to rounding.
    m1, m2, l1, lc1, lc2, I1, I2 = 1.3, 0.8, 0.9, 0.4, 0.35, 0.07, 0.05
    model = build([link("l1", None, "q1", length=l1, mass=m1, com=(lc1, 0.0), inertia=I1),
                   link("l2", "l1", "q2", origin=(l1, 0.0), length=0.7, mass=m2, com=(lc2, 0.0), inertia=I2)])
    rng = np.random.default_rng(6)
    for _ in range(5):
        (q1, q2), qd = rng.uniform(-3, 3, 2), rng.normal(size=2)
        c2 = math.cos(q2)
        M = np.array([[m1 * lc1 ** 2 + m2 * (l1 ** 2 + lc2 ** 2 + 2 * l1 * lc2 * c2) + I1 + I2,
                       m2 * (lc2 ** 2 + l1 * lc2 * c2) + I2],
                      [m2 * (lc2 ** 2 + l1 * lc2 * c2) + I2, m2 * lc2 ** 2 + I2]])
        hh = -m2 * l1 * lc2 * math.sin(q2)
        coriolis = np.array([hh * (2 * qd[0] * qd[1] + qd[1] ** 2), -hh * qd[0] ** 2])
        gravity = np.array([(m1 * lc1 + m2 * l1) * G * math.cos(q1) + m2 * lc2 * G * math.cos(q1 + q2),
                            m2 * lc2 * G * math.cos(q1 + q2)])
        q = np.array([q1, q2])
        np.testing.assert_allclose(model.mass_matrix(q), M, rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(model.forces(q, qd), -coriolis - gravity, rtol=1e-12, atol=1e-12)


# ---------------------------------------------------------------- (4) energy conservation, open chains
def _ode(model):
    terms = model.new_terms()
    n = model.n

    def rhs(t, y):
        model.evaluate(y[:n], y[n:], t, None, terms)
        return np.concatenate([y[n:], np.linalg.solve(terms.M, terms.Q)])

    return rhs


@pytest.mark.parametrize("spec", [
    [link("l1", None, "q1", q0=0.3), link("l2", "l1", "q2", origin=(1.0, 0.0), length=0.8, mass=0.7, q0=1.2),
     link("l3", "l2", "q3", origin=(0.8, 0.0), length=0.6, mass=0.5, com=(0.3, 0.05), q0=-0.5, qd0=2.0)],
    [link("l1", None, "q1", q0=0.2, qd0=1.0),
     link("sl", "l1", "s", joint="prismatic", origin=(0.2, 0.0), length=0.2, mass=0.6, com=(0.1, 0.02),
          q0=0.3, qd0=-0.4),
     link("l3", "sl", "q3", origin=(0.2, 0.0), angle=0.5, length=0.5, mass=0.4, q0=0.7)],
], ids=["3-link pendulum", "with prismatic"])
def test_energy_conserved_in_open_chains(spec):
    # DOP853 at rtol 1e-10 over 2 s: the energy error is of the order of the integration error,
    # ~1e-10 of the energy scale Σ m g L (13-18 J here); 1e-7 leaves margin yet catches any wrong
    # Coriolis term (an error of a few percent of it changes E by O(1) J).
    model = build(spec)
    y0 = np.concatenate([model.q0, model.qd0])
    solution = solve_ivp(_ode(model), (0.0, 2.0), y0, method="DOP853", rtol=1e-10, atol=1e-10)
    assert solution.success
    n = model.n
    energy = [model.energy(y[:n], y[n:]) for y in solution.y.T]
    scale = sum(lk["mass"] * G * lk["length"] for lk in spec)
    assert np.ptp(energy) < 1e-7 * scale
    assert np.ptp(solution.y[n:], axis=1).max() > 0.5  # it really moved


# ---------------------------------------------------------------- (5) closed loop: slider-crank
def test_slider_crank_index1_lagrange_conserves_energy():
    # Crank r = 0.5, rod l = 1.2 (no singular position since l > r), rod end on the line z = 0
    # (Aghili's constraint r sinθ1 + l sin(θ1+θ2) = 0).  [M Aᵀ; A 0][q̈; λ] = [Q; γ] over 1 s,
    # rtol 1e-10: energy and constraint drift stay ~1e-10 (measured); tolerance 1e-8 of the energy
    # scale (≈ 27 J) and 1e-8 m; a 1 % error in the closure γ gives 5e-2 J and 2e-2 m.
    r, l = 0.5, 1.2
    th1 = 0.4
    th2 = -th1 - math.asin(r * math.sin(th1) / l)
    spec = [link("crank", None, "theta1", length=r, mass=1.0, q0=th1),
            link("rod", "crank", "theta2", origin=(r, 0.0), length=l, mass=0.6, com=(0.5, 0.0), inertia=0.08,
                 q0=th2)]
    model = build(spec, closures=[dict(name="slider", point="rod.end", to=(0.0, 0.0), directions="z")])
    assert abs(model.constraints(model.q0)[0]) < 1e-14
    A = model.jacobian(model.q0)
    qd0 = np.array([3.0, -3.0 * A[0, 0] / A[0, 1]])  # A q̇ = 0
    terms = model.new_terms()

    def rhs(t, y):
        model.evaluate(y[:2], y[2:], t, None, terms)
        K = np.block([[terms.M, terms.A.T], [terms.A, np.zeros((1, 1))]])
        return np.concatenate([y[2:], np.linalg.solve(K, np.concatenate([terms.Q, terms.gamma]))[:2]])

    solution = solve_ivp(rhs, (0.0, 1.0), np.concatenate([model.q0, qd0]), method="DOP853", rtol=1e-10,
                         atol=1e-10)
    assert solution.success
    energy = [model.energy(y[:2], y[2:]) for y in solution.y.T]
    scale = model.kinetic_energy(model.q0, qd0) + G * 1.6 * (r + l)
    assert np.ptp(energy) < 1e-8 * scale
    assert max(abs(model.constraints(y[:2])[0]) for y in solution.y.T) < 1e-8
    assert np.ptp(solution.y[0]) > 1.0


# ---------------------------------------------------------------- (7) bad input
def _builder():
    builder = JointModelBuilder("bad")
    builder.add_link("a", parent=None, coordinate="qa", length=1.0, mass=1.0, com=(0.5, 0.0), inertia=0.1)
    builder.add_point("p", link="a", local=(0.3, 0.0))
    return builder


def _link(builder, name="b", **changes):
    options = dict(parent="a", coordinate="qb", length=1.0, mass=1.0, com=(0.5, 0.0), inertia=0.1)
    options.update(changes)
    builder.add_link(name, **options)
    return builder


@pytest.mark.parametrize("make, words", [
    (lambda b: _link(b, parent="nope").build(), ["link 'b'", "unknown parent", "'nope'"]),
    (lambda b: _link(b, "a"), ["link 'a'", "duplicate"]),
    (lambda b: _link(b, coordinate="qa"), ["link 'b'", "duplicate coordinate", "'qa'"]),
    (lambda b: _link(b, mass=0.0), ["link 'b'", "mass must be > 0"]),
    (lambda b: _link(b, mass=-1.0), ["link 'b'", "mass"]),
    (lambda b: _link(b, inertia=-0.1), ["link 'b'", "inertia must be >= 0"]),
    (lambda b: _link(b, length=0.0), ["link 'b'", "length must be > 0"]),
    (lambda b: _link(b, joint="spherical"), ["link 'b'", "joint", "'spherical'"]),
    (lambda b: _link(b, com=(1.0,)), ["link 'b'", "com"]),
    (lambda b: _link(b, mass=float("nan")), ["link 'b'", "mass", "finite"]),
    (lambda b: b.add_point("p", link="a", local=(0, 0)), ["point 'p'", "duplicate"]),
    (lambda b: b.add_point("a.end", link="a", local=(0, 0)).build(), ["point 'a.end'", "duplicate"]),
    (lambda b: b.add_point("q", link="zz", local=(0, 0)).build(), ["point 'q'", "unknown link", "'zz'"]),
    (lambda b: b.add_closure("c", point="zz", to=(0, 0)).build(), ["closure 'c'", "unknown point", "'zz'"]),
    (lambda b: b.add_closure("c", point="p", to="zz").build(), ["closure 'c'", "unknown point", "'zz'"]),
    (lambda b: b.add_closure("c", point="p", to=(0, 0), directions="y"), ["closure 'c'", "directions", "'y'"]),
    (lambda b: b.add_closure("c", point="p", to=(0, 0), directions=(0, 0)), ["closure 'c'", "nonzero"]),
    (lambda b: b.add_closure("c", point="p", to=(0, 0), directions=(1, 2, 3)), ["closure 'c'", "directions"]),
    (lambda b: b.add_closure("c", point="p", to="p"), ["closure 'c'", "itself"]),
    (lambda b: b.add_closure("c", point="p", to=(0, 0)).add_closure("c", point="p", to=(1, 0)),
     ["closure 'c'", "duplicate"]),
    (lambda b: b.add_closure("c", point="p", to=(0, 0), directions="x").add_driver("qa", 0.0, name="c").build(),
     ["duplicate constraint name", "'c'"]),
    (lambda b: b.add_driver("zz", "t").build(), ["driver 'zz-driver'", "unknown coordinate", "'zz'"]),
    (lambda b: b.add_driver("qa", "t +* 2"), ["driver 'qa-driver'", "expression"]),
    (lambda b: b.add_driver("qa", "t").add_driver("qa", "2*t", name="other"), ["driver 'other'", "already driven"]),
    (lambda b: b.add_actuator("u", coordinate="zz").build(), ["actuator 'u'", "unknown coordinate", "'zz'"]),
    (lambda b: b.add_actuator("u", coordinate="qa").add_actuator("u", coordinate="qa"), ["actuator 'u'", "duplicate"]),
    (lambda b: _link(_link(b, "b", parent="c"), "c", parent="b", coordinate="qc").build(),
     ["closes on itself"]),
    (lambda b: JointModelBuilder("empty").build(), ["no links"]),
])
def test_bad_input_raises_model_error_naming_the_entry(make, words):
    with pytest.raises(ModelError) as raised:
        make(_builder())
    for word in words:
        assert word in str(raised.value)


def test_links_may_be_added_before_their_parent():
    # Order of definition does not matter: the tree below is the reversed TREE.
    model = build(list(reversed(TREE)))
    q = np.array([0.3, 0.4, -0.2, 0.9])  # coordinates in definition order: q4, q3, s, q1
    reference = forward(TREE, q[::-1])
    positions = model.point_positions(q)
    for name, (_, O, _, end) in reference.items():
        np.testing.assert_allclose(positions[model.point_names.index(f"{name}.end")], end, atol=1e-14)


def test_wrong_workspace_or_sizes_are_refused():
    # The kernel does not bounds-check, so sizes are checked before anything is written.
    small = build(FOURBAR[:1])
    big = build(FOURBAR)
    with pytest.raises(ValueError, match="workspace"):
        small.evaluate(np.zeros(1), np.zeros(1), 0.0, None, big.new_terms())
    with pytest.raises(ValueError, match="wrong size"):
        small.evaluate(np.zeros(2), np.zeros(1), 0.0)
