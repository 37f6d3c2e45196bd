"""Nonholonomic (velocity-level) constraints B(q, t) q̇ + b(q, t) = 0 (THEORY §1, §3.6).

The Chaplygin sleigh (library model "chaplygin-sleigh") is checked against its own reduced
equations in the body-frame forward speed v and angular velocity ω,

    m v̇ = m a ω²,    (I_G + m a²) ω̇ = -m a v ω,

integrated independently (with the heading and the COM path) by scipy, and against their closed
form: with J = I_G + m a², E = ½ m v² + ½ J ω², V = sqrt(2E/m), k = m a / J,
v(t) = V tanh(k V t + atanh(v0 / V)), ω(t) = sign(ω0) sqrt(m/J) V sech(k V t + atanh(v0 / V)).
"""

import math
import pickle

import numpy as np
import pytest
import sympy
from scipy.integrate import solve_ivp

import cmbs
from cmbs.dynamics import UdwadiaKalaba
from cmbs.errors import ModelError
from cmbs.model.equations import from_callables, from_sympy
from cmbs.simulate import project_state, simulate

from helpers import SmoothPath, first_derivative_fd

MASS, INERTIA, A_DIST = 1.0, 0.1, 0.2  # the library model's chosen values
J = INERTIA + MASS * A_DIST**2
FORMULATIONS = ("udwadia-kalaba", "lagrange", "projection", "matrix-r")


def knife_edge(q, qd, a=A_DIST):
    """ψ(q, q̇): lateral velocity of the contact point P = G - a(cos θ, sin θ), written out."""
    x_d, z_d, th_d = qd
    th = q[2]
    P_d = np.array([x_d + a * math.sin(th) * th_d, z_d - a * math.cos(th) * th_d])
    return float(np.array([-math.sin(th), math.cos(th)]) @ P_d)


def body_velocities(q, qd):
    """Forward speed v of G along the body axis and angular velocity ω."""
    th = q[:, 2]
    return np.cos(th) * qd[:, 0] + np.sin(th) * qd[:, 1], qd[:, 2]


def reference(t_end, times, v0=1.0, w0=1.0, friction=0.0):
    """(x, z, θ, v, ω) from the reduced equations, with a viscous friction -k v along the edge."""
    def rhs(t, y):
        x, z, th, v, w = y
        return [v * math.cos(th) - A_DIST * w * math.sin(th), v * math.sin(th) + A_DIST * w * math.cos(th), w,
                A_DIST * w * w - friction * v / MASS, -MASS * A_DIST * v * w / J]

    solution = solve_ivp(rhs, (0.0, t_end), [0.0, 0.0, 0.0, v0, w0], method="DOP853", rtol=1e-13, atol=1e-14,
                         t_eval=times)
    assert solution.success
    return solution.y


@pytest.fixture(scope="module")
def sleigh():
    return cmbs.load("chaplygin-sleigh")


@pytest.fixture(scope="module")
def runs(sleigh):
    return {name: simulate(sleigh, t_end=10.0, formulation=name, integrator="rk45", rtol=1e-10, atol=1e-12,
                           dt=0.05) for name in FORMULATIONS}


# ---------------------------------------------------------------- model interface
def test_sleigh_model_structure(sleigh):
    assert (sleigh.n, sleigh.m) == (3, 1)
    assert sleigh.nonholonomic.tolist() == [True] and sleigh.drivers.tolist() == [False]
    assert sleigh.constraint_names == ("knife-edge",)
    np.testing.assert_array_equal(sleigh.q0, [0.0, 0.0, 0.0])
    # forward speed 1 m/s, ω = 1 rad/s: G (ahead of the edge) moves sideways at a ω
    np.testing.assert_allclose(sleigh.qd0, [1.0, A_DIST, 1.0], atol=1e-15)
    assert abs(knife_edge(sleigh.q0, sleigh.qd0)) < 1e-15
    points = dict(zip(sleigh.point_names, sleigh.point_positions(np.array([1.0, 2.0, np.pi / 2]))))
    np.testing.assert_allclose(points["G"], [1.0, 2.0], atol=1e-15)
    np.testing.assert_allclose(points["P"], [1.0, 2.0 - A_DIST], atol=1e-15)
    assert points["nose"][1] > 2.0 and len(sleigh.lines) == 2
    np.testing.assert_allclose(sleigh.mass_matrix(sleigh.q0), np.diag([MASS, MASS, INERTIA]))


def test_sleigh_terms_against_the_written_constraint_and_finite_differences(sleigh):
    rng = np.random.default_rng(11)
    for _ in range(5):
        path = SmoothPath(rng.uniform(-2.0, 2.0, 3), rng, amplitude=1.0)
        t = float(rng.uniform(0.0, 3.0))
        q, qd, qdd = path.q(t), path.qd(t), path.qdd(t)
        terms = sleigh.evaluate(q, qd, t)
        assert terms.phi[0] == 0.0
        # B = ∂ψ/∂q̇ and b = ψ(q, 0) of the hand-written constraint (ψ is linear in q̇: exact differences)
        B = np.array([knife_edge(q, np.eye(3)[k]) for k in range(3)])
        np.testing.assert_allclose(terms.A[0], B, atol=1e-14)
        assert abs(terms.phi_t[0] - knife_edge(q, np.zeros(3))) < 1e-14
        assert abs(terms.A[0] @ qd + terms.phi_t[0] - knife_edge(q, qd)) < 1e-13
        # γ = B q̈ - d/dt ψ(q(t), q̇(t)) along the path, by the hand-written ψ and by the model's own B, b
        psi_dot = first_derivative_fd(lambda s: knife_edge(path.q(s), path.qd(s)), t)
        own_dot = first_derivative_fd(lambda s: sleigh.jacobian(path.q(s), s)[0] @ path.qd(s)
                                      + sleigh.constraints_t(path.q(s), s)[0], t)
        for derivative in (psi_dot, own_dot):
            assert abs(terms.gamma[0] - (B @ qdd - derivative)) < 1e-9


def _rheonomic_symbols():
    x, y, x_d, y_d, t = sympy.symbols("x y x_d y_d t")
    # B(q, t) q̇ + b(q, t) with B and b depending on q and t
    psi = sympy.cos(y) * x_d + (x + sympy.sin(t)) * y_d + x**2 * sympy.cos(2 * t) + y
    return (x, y, x_d, y_d, t), psi


def _rheonomic_model(**extra):
    (x, y, x_d, y_d, t), psi = _rheonomic_symbols()
    return from_sympy("rheonomic", coordinates=[x, y], velocities=[x_d, y_d], time=t,
                      mass_matrix=sympy.diag(2.0, 1.0 + x**2), forces=[-x, sympy.sin(t) - y_d],
                      constraints=[x**2 + y**2 - 1], velocity_constraints=[psi],
                      velocity_constraint_names=["psi-rheo"], drivers=["psi-rheo"], q0=[0.6, 0.8], **extra)


def test_rheonomic_velocity_constraint_terms_against_finite_differences():
    model = _rheonomic_model()
    assert model.constraint_names == ("phi[0]", "psi-rheo")
    assert model.nonholonomic.tolist() == [False, True]
    assert model.drivers.tolist() == [False, True]  # the row named a driver

    def psi(q, qd, t):
        x, y = q
        return math.cos(y) * qd[0] + (x + math.sin(t)) * qd[1] + x * x * math.cos(2 * t) + y

    rng = np.random.default_rng(5)
    for _ in range(5):
        path = SmoothPath(rng.uniform(-1.0, 1.0, 2), rng, amplitude=0.8)
        t = float(rng.uniform(0.0, 3.0))
        q, qd, qdd = path.q(t), path.qd(t), path.qdd(t)
        terms = model.evaluate(q, qd, t)
        np.testing.assert_allclose(terms.A[1], [math.cos(q[1]), q[0] + math.sin(t)], atol=1e-14)
        assert terms.phi[1] == 0.0
        assert abs(terms.phi_t[1] - psi(q, np.zeros(2), t)) < 1e-14
        psi_dot = first_derivative_fd(lambda s: psi(path.q(s), path.qd(s), s), t)
        assert abs(terms.gamma[1] - (terms.A[1] @ qdd - psi_dot)) < 1e-8
        # the holonomic row is untouched
        assert abs(terms.phi[0] - (q @ q - 1.0)) < 1e-14


def test_from_sympy_rejects_nonlinear_and_misplaced_velocity_constraints():
    x, y, x_d, y_d = sympy.symbols("x y x_d y_d")
    u = sympy.Symbol("u")
    base = dict(coordinates=[x, y], velocities=[x_d, y_d], mass_matrix=sympy.eye(2), forces=[0, 0])
    with pytest.raises(ModelError, match=r"velocity_constraints\[1\] \('slip'\) is not linear in the velocities "
                                         r"\(it is nonlinear in x_d\)"):
        from_sympy("bad", velocity_constraints=[x_d - y, x_d**2 + y_d], velocity_constraint_names=["ok", "slip"],
                   **base)
    with pytest.raises(ModelError, match=r"velocity_constraints\[0\].*nonlinear in x_d, y_d"):
        from_sympy("bad", velocity_constraints=[x_d * y_d], **base)
    with pytest.raises(ModelError, match=r"velocity_constraints\[0\] uses input 'u'"):
        from_sympy("bad", inputs=[u], velocity_constraints=[x_d - u], **{**base, "forces": [u, 0]})
    with pytest.raises(ModelError, match="share names"):
        from_sympy("bad", constraints=[x - y], constraint_names=["c"], velocity_constraints=[x_d],
                   velocity_constraint_names=["c"], **base)
    with pytest.raises(ModelError, match=r"drivers row index 2 is out of range \(the model has 2 constraints\)"):
        from_sympy("bad", constraints=[x - y], velocity_constraints=[x_d], drivers=[2], **base)


def test_model_nonholonomic_mask_defaults_and_validation(sleigh):
    pendulum = cmbs.load("pendulum")
    assert pendulum.nonholonomic.shape == (pendulum.m,) and not pendulum.nonholonomic.any()
    assert not pendulum.nonholonomic.flags.writeable
    with pytest.raises(ModelError, match="nonholonomic mask does not match"):
        sleigh.replace(nonholonomic=np.array([True, False]))
    undriven = _rheonomic_model().without_drivers()
    assert undriven.constraint_names == ("phi[0]",) and undriven.nonholonomic.tolist() == [False]
    copy = pickle.loads(pickle.dumps(_rheonomic_model()))
    q, qd = np.array([0.3, -0.4]), np.array([0.7, 0.2])
    np.testing.assert_array_equal(copy.gamma(q, qd, 0.4), _rheonomic_model().gamma(q, qd, 0.4))
    assert copy.nonholonomic.tolist() == [False, True]


def test_from_callables_velocity_constraints_match_from_sympy():
    sympy_model = _rheonomic_model()

    def B_b(q, t):
        return np.array([[math.cos(q[1]), q[0] + math.sin(t)]]), np.array([q[0] ** 2 * math.cos(2 * t) + q[1]])

    def gamma_psi(q, qd, t):  # -(d/dt B) q̇ - ḃ, by hand
        x, y = q
        B_dot = np.array([-math.sin(y) * qd[1], qd[0] + math.cos(t)])
        b_dot = 2 * x * qd[0] * math.cos(2 * t) - 2 * x * x * math.sin(2 * t) + qd[1]
        return np.array([-(B_dot @ qd) - b_dot])

    common = dict(coordinate_names=["x", "y"], mass_matrix=lambda q: np.diag([2.0, 1.0 + q[0] ** 2]),
                  forces=lambda q, qd, t, u: np.array([-q[0], math.sin(t) - qd[1]]),
                  constraints=lambda q, t: np.array([q @ q - 1.0]), jacobian=lambda q, t: 2.0 * q[None, :],
                  gamma=lambda q, qd, t: np.array([-2.0 * qd @ qd]), q0=[0.6, 0.8], velocity_constraints=B_b,
                  velocity_constraint_names=["psi-rheo"])
    exact = from_callables("callable", velocity_gamma=gamma_psi, **common)
    differenced = from_callables("callable-fd", finite_differences=True, **common)
    assert exact.nonholonomic.tolist() == [False, True] and exact.constraint_names == ("phi[0]", "psi-rheo")
    rng = np.random.default_rng(2)
    for _ in range(4):
        q, qd, t = rng.uniform(-1, 1, 2), rng.uniform(-1, 1, 2), float(rng.uniform(0, 3))
        expected = sympy_model.evaluate(q, qd, t)
        for model, tolerance in ((exact, 1e-13), (differenced, 1e-8)):
            terms = model.evaluate(q, qd, t)
            for label in ("phi", "A", "phi_t", "gamma", "M", "Q"):
                np.testing.assert_allclose(getattr(terms, label), getattr(expected, label), atol=tolerance,
                                           err_msg=label)
    with pytest.raises(ModelError, match="velocity_gamma disagrees with finite differences"):
        from_callables("wrong", velocity_gamma=lambda q, qd, t: -gamma_psi(q, qd, t) + 0.1, **common)
    with pytest.raises(ModelError, match="without velocity_gamma"):
        from_callables("missing", **common)


# ---------------------------------------------------------------- position level skips the rows
def _sleigh_on_a_circle():
    """The sleigh with its COM also held on the unit circle x² + z² = 1 (holonomic): 2 DOF,
    1 velocity DOF."""
    x, z, th, x_d, z_d, th_d = sympy.symbols("x z theta x_d z_d theta_d")
    edge = (-sympy.sin(th) * (x_d + A_DIST * sympy.sin(th) * th_d)
            + sympy.cos(th) * (z_d - A_DIST * sympy.cos(th) * th_d))
    return from_sympy("sleigh-on-circle", coordinates=[x, z, th], velocities=[x_d, z_d, th_d],
                      mass_matrix=sympy.diag(MASS, MASS, INERTIA), forces=[0, 0, 0],
                      constraints=[x**2 + z**2 - 1], velocity_constraints=[edge], q0=[0.6, 0.7, 0.2])


def test_constraint_report_counts_configuration_and_velocity_dof(sleigh):
    report = cmbs.constraint_report(sleigh, sleigh.q0)
    assert (report.n, report.m, report.rank, report.dof, report.velocity_dof) == (3, 1, 1, 3, 2)
    mixed = cmbs.constraint_report(_sleigh_on_a_circle(), np.array([0.6, 0.8, 0.2]))
    assert (mixed.rank, mixed.dof, mixed.velocity_dof) == (2, 2, 1)
    holonomic = cmbs.constraint_report(cmbs.load("double-pendulum"), cmbs.load("double-pendulum").q0)
    assert holonomic.velocity_dof == holonomic.dof == 2


def test_assembly_and_projection_use_holonomic_rows_for_positions():
    model = _sleigh_on_a_circle()
    # Newton steps along the circle's gradient (2x, 2z, 0) land on the radial projection with θ
    # untouched (steps also held to the knife-edge row, B Δq = 0, would turn θ)
    radial = np.array([0.6, 0.7]) / math.hypot(0.6, 0.7)
    np.testing.assert_allclose(cmbs.assemble(model, np.array([0.6, 0.7, 0.2])), [*radial, 0.2], atol=1e-12)
    np.testing.assert_allclose(cmbs.assemble(cmbs.load("chaplygin-sleigh"), np.array([0.4, -0.3, 2.0])),
                               [0.4, -0.3, 2.0], atol=0)
    qd = np.array([0.3, -0.7, 1.1])
    q, qd_projected = project_state(model, np.array([0.6, 0.7, 0.2]), qd, 0.0, tolerance=1e-14)
    np.testing.assert_allclose(q, [*radial, 0.2], atol=1e-12)
    # velocities: the orthogonal projection onto {x ẋ + z ż = 0, ψ = 0}, from the hand-written rows
    rows = np.array([[q[0], q[1], 0.0], [knife_edge(q, e) for e in np.eye(3)]])
    expected = qd - rows.T @ np.linalg.solve(rows @ rows.T, rows @ qd)
    np.testing.assert_allclose(qd_projected, expected, atol=1e-12)
    assert abs(knife_edge(q, qd_projected)) < 1e-14


# ---------------------------------------------------------------- dynamics of the sleigh
def test_sleigh_conserves_energy_and_its_constraint(runs, sleigh):
    E0 = 0.5 * MASS * 1.0**2 + 0.5 * J * 1.0**2
    assert sleigh.energy(sleigh.q0, sleigh.qd0) == pytest.approx(E0, rel=1e-14)
    for name, run in runs.items():
        assert run.info["status"] == "success", name
        assert np.abs(run.extras["energy"] / E0 - 1.0).max() < 1e-8, name
        residual = [knife_edge(q, qd) for q, qd in zip(run.q, run.qd)]
        assert np.abs(residual).max() < 1e-8, name
        assert run.extras["velocity_constraint_error"].max() < 1e-8, name
        assert run.extras["constraint_error"].max() == 0.0, name


def test_sleigh_formulations_agree(runs):
    reference_run = runs["udwadia-kalaba"]
    for name, run in runs.items():
        np.testing.assert_allclose(run.q, reference_run.q, atol=1e-7, err_msg=name)
        np.testing.assert_allclose(run.qd, reference_run.qd, atol=1e-7, err_msg=name)
        np.testing.assert_allclose(run.qdd, reference_run.qdd, atol=1e-6, err_msg=name)


def test_sleigh_matches_reduced_equations_and_closed_form(runs):
    run = runs["lagrange"]
    x, z, th, v_ref, w_ref = reference(10.0, run.t)
    E = 0.5 * MASS + 0.5 * J
    V, k = math.sqrt(2 * E / MASS), MASS * A_DIST / J
    phase = k * V * run.t + math.atanh(1.0 / V)
    v_closed, w_closed = V * np.tanh(phase), math.sqrt(MASS / J) * V / np.cosh(phase)
    np.testing.assert_allclose(v_ref, v_closed, atol=1e-11)
    np.testing.assert_allclose(w_ref, w_closed, atol=1e-11)
    for name, run in runs.items():
        v, w = body_velocities(run.q, run.qd)
        assert np.abs(v - v_ref).max() < 1e-7, name
        assert np.abs(w - w_ref).max() < 1e-7, name
        np.testing.assert_allclose(run.q, np.column_stack([x, z, th]), atol=1e-7, err_msg=name)
    # ω has died out and v reached sqrt(2E/m): the sleigh ends up sliding straight
    v, w = body_velocities(run.q, run.qd)
    assert abs(w[-1]) < 1e-5 and abs(v[-1] - V) < 1e-8
    assert np.all(np.diff(v) > 0)  # v̇ = a ω² > 0


def test_sleigh_with_projection_after_every_step(sleigh, runs):
    run = simulate(sleigh, t_end=10.0, formulation="lagrange", rtol=1e-10, atol=1e-12, dt=0.05, project=True)
    assert run.extras["velocity_constraint_error"].max() < 1e-8  # outputs are interpolated between steps
    np.testing.assert_allclose(run.q, runs["lagrange"].q, atol=1e-7)


@pytest.mark.parametrize("name", FORMULATIONS)
def test_mixed_holonomic_and_nonholonomic_rows_simulate(name):
    """The sleigh with its COM on the unit circle: energy is conserved, both rows hold; with
    projection after every step a fixed-step run stays on the circle."""
    model = _sleigh_on_a_circle()
    q0 = cmbs.assemble(model, model.q0, tolerance=1e-14)
    qd0 = cmbs.velocities(model, q0, qd=np.array([-1.0, 1.0, 0.5]))
    assert abs(q0 @ q0 - q0[2] ** 2 - 1.0) < 1e-14 and abs(q0[:2] @ qd0[:2]) < 1e-14
    assert abs(knife_edge(q0, qd0)) < 1e-14
    run = simulate(model, t_end=5.0, formulation=name, rtol=1e-11, atol=1e-13, dt=0.05, q0=q0, qd0=qd0)
    assert run.info["status"] == "success"
    E = run.extras["energy"]
    assert np.abs(E / E[0] - 1.0).max() < 1e-8
    assert run.extras["constraint_error"].max() < 1e-8
    assert np.abs([knife_edge(q, qd) for q, qd in zip(run.q, run.qd)]).max() < 1e-8
    # rk4 outputs are the steps themselves (no interpolation): the projected states are recorded
    projected = simulate(model, t_end=5.0, formulation=name, integrator="rk4", dt=0.05, q0=q0, qd0=qd0,
                         project=True, projection_tolerance=1e-12)
    assert projected.extras["constraint_error"].max() < 1e-11
    assert projected.extras["velocity_constraint_error"].max() < 1e-13
    np.testing.assert_allclose(projected.q, run.q, atol=1e-7)


@pytest.mark.parametrize("name", ["baumgarte", "penalty"])
def test_sleigh_stabilised_formulations_agree(sleigh, runs, name):
    run = simulate(sleigh, t_end=10.0, formulation=name, integrator="rk45", rtol=1e-10, atol=1e-12, dt=0.05)
    np.testing.assert_allclose(run.q, runs["udwadia-kalaba"].q, atol=1e-6)
    assert run.extras["velocity_constraint_error"].max() < 1e-7


def test_udwadia_kalaba_nonideal_friction_along_the_edge(sleigh):
    """Viscous friction -k v at the contact point along the blade: generalized c = J_Pᵀ(-k v e₁) =
    -k v (cos θ, sin θ, 0); its power on the motion is -k v², so dE/dt = -k v² and the reduced
    equations gain m v̇ = m a ω² - k v."""
    friction = 0.5

    def c(t, q, qd):
        th = q[2]
        v = math.cos(th) * qd[0] + math.sin(th) * qd[1]
        return -friction * v * np.array([math.cos(th), math.sin(th), 0.0])

    run = simulate(sleigh, t_end=10.0, formulation=UdwadiaKalaba(nonideal=c), rtol=1e-10, atol=1e-12, dt=0.05)
    assert run.info["status"] == "success"
    x, z, th, v_ref, w_ref = reference(10.0, run.t, friction=friction)
    v, w = body_velocities(run.q, run.qd)
    assert np.abs(v - v_ref).max() < 1e-7 and np.abs(w - w_ref).max() < 1e-7
    np.testing.assert_allclose(run.q, np.column_stack([x, z, th]), atol=1e-7)
    # energy balance E(t) = E0 - ∫ k v² dt, the integral from the reference solution
    fine = np.linspace(0.0, 10.0, 20001)
    v_fine = reference(10.0, fine, friction=friction)[3]
    dissipated = np.concatenate([[0.0], np.cumsum(0.5 * (v_fine[1:] ** 2 + v_fine[:-1] ** 2) * np.diff(fine))])
    expected = 0.5 * MASS + 0.5 * J - friction * np.interp(run.t, fine, dissipated)
    np.testing.assert_allclose(run.extras["energy"], expected, atol=1e-6)
    assert run.extras["energy"][-1] < 0.5 * (0.5 * MASS + 0.5 * J)
    assert np.abs([knife_edge(q, qd) for q, qd in zip(run.q, run.qd)]).max() < 1e-8


def test_position_level_integrators_refuse_nonholonomic_models():
    from cmbs.errors import CmbsError
    from cmbs.simulate import simulate

    model = cmbs.load("chaplygin-sleigh")
    for integrator in ("trapezoidal", "backward-euler", "generalized-alpha"):
        with pytest.raises(CmbsError, match="cannot impose the nonholonomic constraints"):
            simulate(model, t_end=1.0, integrator=integrator)
