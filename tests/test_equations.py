"""Models from user-given equations (cmbs.model.equations): SymPy and callables.

Every expected value is a closed form or a finite-difference estimate computed here, never a
number recorded from the code under test.
"""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp

from cmbs.errors import ModelError
from cmbs.model.equations import from_callables, from_sympy

x, z, t = sp.symbols("x z t")
x_d, z_d = sp.symbols("x_d z_d")
u0, u1 = sp.symbols("u0 u1")
MASS, G, L = 1.3, 9.81, 0.7
RNG_SEED = 12345


# ---------------------------------------------------------------- models
def pendulum_kwargs(**changes):
    """Planar pendulum in Cartesian coordinates, Φ = x² + z² - L², gravity along -z."""
    theta0 = 0.3
    kwargs = dict(coordinates=[x, z], mass_matrix=sp.diag(MASS, MASS), forces=[0, -MASS * G],
                  constraints=[x**2 + z**2 - L**2], potential=MASS * G * z,
                  points={"O": (0, 0), "P": (x, z)}, lines=[("O", "P")],
                  q0=[L * math.sin(theta0), -L * math.cos(theta0)],
                  source="closed-form test model")
    kwargs.update(changes)
    return kwargs


@pytest.fixture(scope="module")
def pendulum():
    return from_sympy("pendulum", **pendulum_kwargs())


def pendulum_callables(**changes):
    kwargs = dict(coordinate_names=["x", "z"],
                  mass_matrix=lambda q: MASS * np.eye(2),
                  forces=lambda q, qd, t, u: np.array([0.0, -MASS * G]),
                  constraints=lambda q, t: np.array([q[0]**2 + q[1]**2 - L**2]),
                  jacobian=lambda q, t: np.array([[2 * q[0], 2 * q[1]]]),
                  gamma=lambda q, qd, t: np.array([-2 * (qd[0]**2 + qd[1]**2)]),
                  potential=lambda q: MASS * G * q[1],
                  points=lambda q: np.array([[0.0, 0.0], [q[0], q[1]]]), point_names=["O", "P"],
                  lines=[(0, 1)], q0=[L * math.sin(0.3), -L * math.cos(0.3)])
    kwargs.update(changes)
    return from_callables("pendulum-callables", **kwargs)


# Rheonomic constraints mixing q and t: Φ_t, Φ_qt and Φ_tt all non-zero.
RHEONOMIC_PHI = [x - sp.sin(t), x * z * sp.cos(2 * t) + z**2 * t**2 - 1]


def rheonomic_phi(q, s):
    return np.array([q[0] - math.sin(s), q[0] * q[1] * math.cos(2 * s) + q[1]**2 * s**2 - 1])


@pytest.fixture(scope="module")
def rheonomic():
    return from_sympy("rheonomic", coordinates=[x, z], mass_matrix=sp.eye(2), forces=[0, 0],
                      constraints=RHEONOMIC_PHI, drivers=["phi[0]", "phi[1]"], q0=[0.0, 1.0])


def random_states(count, n=2, seed=RNG_SEED):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        yield rng.uniform(-1, 1, n), rng.uniform(-2, 2, n), float(rng.uniform(-3, 3))


def fd_jacobian(phi, q, s, h=1e-6):
    columns = []
    for i in range(q.size):
        step = np.zeros_like(q)
        step[i] = h
        columns.append((phi(q + step, s) - phi(q - step, s)) / (2 * h))
    return np.stack(columns, axis=1)


def pendulum_phi(q, s):
    return np.array([q[0]**2 + q[1]**2 - L**2])


# ---------------------------------------------------------------- closed forms
def test_pendulum_terms_match_closed_form(pendulum):
    terms = pendulum.new_terms()
    for q, qd, s in random_states(5):
        pendulum.evaluate(q, qd, s, None, terms)
        np.testing.assert_array_equal(terms.M, MASS * np.eye(2))
        np.testing.assert_allclose(terms.Q, [0.0, -MASS * G], rtol=1e-15)
        np.testing.assert_allclose(terms.phi, [q @ q - L**2], rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(terms.A, [2 * q], rtol=1e-15)
        np.testing.assert_allclose(terms.gamma, [-2 * (qd @ qd)], rtol=1e-14)
        np.testing.assert_array_equal(terms.phi_t, [0.0])
        assert pendulum.kinetic_energy(q, qd) == pytest.approx(0.5 * MASS * (qd @ qd), rel=1e-14)
        assert pendulum.potential_energy(q) == pytest.approx(MASS * G * q[1], rel=1e-14)
        np.testing.assert_allclose(pendulum.point_positions(q), [[0.0, 0.0], q], rtol=1e-15)


def test_derived_expressions_in_user_symbols(pendulum):
    equations = pendulum.equations
    assert sp.expand(equations.A - sp.Matrix([[2 * x, 2 * z]])) == sp.zeros(1, 2)
    assert sp.expand(equations.gamma[0] + 2 * x_d**2 + 2 * z_d**2) == 0
    assert equations.phi_t[0] == 0


def test_nonsmooth_constraint_differentiated_almost_everywhere():
    """|x| with sympy's default (complex) symbols: A = [sign x, 2z], γ = -2 ż² off x = 0."""
    model = from_sympy("abs", coordinates=[x, z], mass_matrix=sp.eye(2), forces=[0, 0],
                       constraints=[sp.Abs(x) + z**2 - 1], q0=[0.5, 0.5])
    for q, qd, _ in random_states(4, seed=5):
        np.testing.assert_allclose(model.jacobian(q), [[np.sign(q[0]), 2 * q[1]]], rtol=1e-15)
        np.testing.assert_allclose(model.gamma(q, qd), [-2 * qd[1]**2], rtol=1e-14)


def test_pendulum_model_metadata(pendulum):
    assert pendulum.coordinate_names == ("x", "z")
    assert pendulum.coordinate_kinds == ("generic", "generic")
    assert pendulum.constraint_names == ("phi[0]",)
    assert pendulum.drivers.tolist() == [False]
    assert pendulum.point_names == ("O", "P")
    assert pendulum.lines == ((0, 1),)
    assert pendulum.n_u == 0 and pendulum.m == 1
    assert pendulum.constant_mass  # M free of q: shared read-only matrix
    assert not pendulum.new_terms().M.flags.writeable


def test_jacobian_matches_finite_differences(pendulum, rheonomic):
    for model, phi in ((pendulum, pendulum_phi), (rheonomic, rheonomic_phi)):
        for q, _, s in random_states(5):
            np.testing.assert_allclose(model.jacobian(q, s), fd_jacobian(phi, q, s), rtol=1e-8, atol=1e-9)
            np.testing.assert_allclose(model.constraints(q, s), phi(q, s), rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("which", ["pendulum", "rheonomic"])
def test_gamma_matches_second_derivative_along_smooth_motion(which, pendulum, rheonomic):
    """Φ̈ = A q̈ - γ along q(s) = a + b sin(ω s + c), Φ̈ by central differences of Φ(q(s), s)."""
    model, phi = (pendulum, pendulum_phi) if which == "pendulum" else (rheonomic, rheonomic_phi)
    rng = np.random.default_rng(7)
    a, b, c = rng.uniform(-1, 1, 2), rng.uniform(-1, 1, 2), rng.uniform(0, 6, 2)
    omega = np.array([1.3, 2.1])

    def motion(s):
        return (a + b * np.sin(omega * s + c), b * omega * np.cos(omega * s + c),
                -b * omega**2 * np.sin(omega * s + c))

    h = 1e-4
    for s in np.linspace(-1.0, 2.0, 7):
        q, qd, qdd = motion(s)
        phi_dd = (phi(motion(s + h)[0], s + h) - 2 * phi(q, s) + phi(motion(s - h)[0], s - h)) / h**2
        terms = model.evaluate(q, qd, s)
        np.testing.assert_allclose(terms.A @ qdd - terms.gamma, phi_dd, rtol=1e-5, atol=1e-6)
        # velocity level: Φ̇ = A q̇ + Φ_t
        phi_d = (phi(motion(s + h)[0], s + h) - phi(motion(s - h)[0], s - h)) / (2 * h)
        np.testing.assert_allclose(terms.A @ qd + terms.phi_t, phi_d, rtol=1e-7, atol=1e-8)


def test_rheonomic_phi_t_and_time_terms_of_gamma(rheonomic):
    for q, qd, s in random_states(6, seed=3):
        h = 1e-4
        # Φ_t against a central difference in t
        phi_t_fd = (rheonomic_phi(q, s + h) - rheonomic_phi(q, s - h)) / (2 * h)
        np.testing.assert_allclose(rheonomic.constraints_t(q, s), phi_t_fd, rtol=1e-7, atol=1e-8)
        # q̇ = 0: γ = -Φ_tt
        phi_tt = (rheonomic_phi(q, s + h) - 2 * rheonomic_phi(q, s) + rheonomic_phi(q, s - h)) / h**2
        np.testing.assert_allclose(rheonomic.gamma(q, np.zeros(2), s), -phi_tt, rtol=1e-5, atol=1e-6)
        # the velocity terms: γ(q̇) - γ(0) = -(∂(A q̇)/∂q) q̇ - 2 Φ_qt q̇, with Φ_qt = ∂A/∂t
        A_t = (rheonomic.jacobian(q, s + h) - rheonomic.jacobian(q, s - h)) / (2 * h)
        A_dot_qd = (rheonomic.jacobian(q + h * qd, s) - rheonomic.jacobian(q - h * qd, s)) / (2 * h) @ qd
        np.testing.assert_allclose(rheonomic.gamma(q, qd, s) - rheonomic.gamma(q, np.zeros(2), s),
                                   -A_dot_qd - 2 * A_t @ qd, rtol=1e-6, atol=1e-6)
        # closed form of the pure driver row x - sin t: Φ_t = -cos t, γ = -Φ_tt = -sin t
        assert rheonomic.constraints_t(q, s)[0] == pytest.approx(-math.cos(s), rel=1e-14, abs=1e-15)
        assert rheonomic.gamma(q, qd, s)[0] == pytest.approx(-math.sin(s), rel=1e-14, abs=1e-15)
    # the driver rows are the ones named (or indexed)
    assert rheonomic.drivers.tolist() == [True, True]
    explicit = from_sympy("r", coordinates=[x, z], mass_matrix=sp.eye(2), forces=[0, 0],
                          constraints=RHEONOMIC_PHI, drivers=[0], q0=[0.0, 1.0])
    assert explicit.drivers.tolist() == [True, False]
    assert explicit.driver_names == ("phi[0]",)


# ---------------------------------------------------------------- dynamics
def lagrange_rhs(model):
    """Index-1 Lagrange system [M Aᵀ; A 0][q̈; λ] = [Q; γ] (THEORY §3.1)."""
    n, m = model.n, model.m
    terms = model.new_terms()
    matrix = np.zeros((n + m, n + m))
    right = np.zeros(n + m)

    def rhs(s, y):
        q, qd = y[:n], y[n:]
        model.evaluate(q, qd, s, None, terms)
        matrix[:n, :n] = terms.M
        matrix[:n, n:] = terms.A.T
        matrix[n:, :n] = terms.A
        right[:n] = terms.Q
        right[n:] = terms.gamma
        return np.concatenate([qd, np.linalg.solve(matrix, right)[:n]])

    return rhs


def start_state(theta0):
    """At rest at angle θ0 from the downward vertical."""
    return np.array([L * math.sin(theta0), -L * math.cos(theta0), 0.0, 0.0])


@pytest.mark.parametrize("build", ["sympy", "callables"])
def test_pendulum_period_matches_closed_form(build, pendulum):
    model = pendulum if build == "sympy" else pendulum_callables()
    theta0 = 0.05
    period = 2 * math.pi * math.sqrt(L / G) * (1 + theta0**2 / 16)  # next term 11θ⁴/3072 ≈ 2e-8

    def crossing(s, y):
        return y[0]

    crossing.direction = 1.0
    solution = solve_ivp(lagrange_rhs(model), (0.0, 3.2 * period), start_state(theta0), method="DOP853",
                         rtol=1e-11, atol=1e-12, events=crossing)
    times = solution.t_events[0]
    assert len(times) == 3
    assert np.diff(times) == pytest.approx([period, period], rel=2e-6)


def test_pendulum_conserves_energy_at_large_amplitude(pendulum):
    y0 = start_state(1.2)
    energy0 = pendulum.energy(y0[:2], y0[2:])
    assert energy0 == pytest.approx(-MASS * G * L * math.cos(1.2), rel=1e-14)
    solution = solve_ivp(lagrange_rhs(pendulum), (0.0, 5.0), y0, method="DOP853", rtol=1e-11, atol=1e-12,
                         t_eval=np.linspace(0.0, 5.0, 101))
    energies = np.array([pendulum.energy(y[:2], y[2:]) for y in solution.y.T])
    assert np.max(np.abs(energies - energy0)) < 1e-6 * MASS * G * L
    drift = np.array([pendulum.constraints(y[:2])[0] for y in solution.y.T])
    assert np.max(np.abs(drift)) < 1e-6 * L**2
    assert np.ptp(solution.y[0]) > L  # it really swung


# ---------------------------------------------------------------- callables
def test_callables_give_identical_terms(pendulum):
    other = pendulum_callables()
    assert other.coordinate_names == pendulum.coordinate_names
    assert other.point_names == pendulum.point_names and other.lines == pendulum.lines
    a, b = pendulum.new_terms(), other.new_terms()
    for q, qd, s in random_states(5):
        pendulum.evaluate(q, qd, s, None, a)
        other.evaluate(q, qd, s, None, b)
        for name in ("M", "Q", "phi", "A", "gamma", "phi_t"):
            np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=1e-15, atol=1e-15, err_msg=name)
        assert other.energy(q, qd) == pytest.approx(pendulum.energy(q, qd), rel=1e-15)
        np.testing.assert_array_equal(other.point_positions(q), pendulum.point_positions(q))


def test_callables_rheonomic_and_finite_difference_defaults(rheonomic):
    kwargs = dict(coordinate_names=["x", "z"], mass_matrix=lambda q: np.eye(2),
                  forces=lambda q, qd, t, u: np.zeros(2), constraints=rheonomic_phi, q0=[0.0, 1.0])
    exact = from_callables(
        "rheonomic-callables", **kwargs,
        jacobian=lambda q, s: np.array([[1.0, 0.0], [q[1] * math.cos(2 * s), q[0] * math.cos(2 * s) + 2 * q[1] * s**2]]),
        constraints_t=lambda q, s: np.array([-math.cos(s), -2 * q[0] * q[1] * math.sin(2 * s) + 2 * q[1]**2 * s]),
        gamma=lambda q, qd, s: np.array([
            -math.sin(s),
            -(2 * qd[0] * qd[1] * math.cos(2 * s) + 2 * qd[1]**2 * s**2
              + 2 * (-2 * math.sin(2 * s) * (qd[0] * q[1] + q[0] * qd[1]) + 4 * q[1] * qd[1] * s)
              + (-4 * q[0] * q[1] * math.cos(2 * s) + 2 * q[1]**2))]))
    approximate = from_callables("rheonomic-fd", **kwargs, finite_differences=True)
    for q, qd, s in random_states(5):
        reference = rheonomic.evaluate(q, qd, s)
        for model, tolerance in ((exact, 1e-13), (approximate, 1e-5)):
            terms = model.evaluate(q, qd, s)
            for name in ("phi", "A", "gamma", "phi_t"):
                np.testing.assert_allclose(getattr(terms, name), getattr(reference, name),
                                           rtol=tolerance, atol=tolerance, err_msg=name)


# ---------------------------------------------------------------- inputs, mass, energy
def test_forces_with_inputs():
    damping = 0.4
    model = from_sympy("driven", coordinates=[x, z], mass_matrix=sp.diag(MASS, MASS),
                       forces=sp.Matrix([u0 - damping * x_d, u1 * sp.cos(t) - MASS * G]), inputs=[u0, u1],
                       q0=[0.1, 0.2])
    assert model.actuator_names == ("u0", "u1") and model.m == 0
    q, qd, s, u = np.array([0.3, -0.2]), np.array([1.5, -0.5]), 0.8, np.array([2.0, -3.0])
    np.testing.assert_allclose(model.forces(q, qd, s, u),
                               [2.0 - damping * 1.5, -3.0 * math.cos(0.8) - MASS * G], rtol=1e-14)
    np.testing.assert_allclose(model.forces(q, qd, s), [-damping * 1.5, -MASS * G], rtol=1e-14)
    terms = model.evaluate(q, qd, s, u)
    assert terms.phi.shape == (0,) and terms.A.shape == (0, 2) and terms.gamma.shape == (0,)
    assert model.point_positions(q).shape == (0, 2)
    assert model.potential_energy(q) == 0.0  # no potential given
    # numeric constants keep all 17 digits (sympy prints 15 by default)
    exact = from_sympy("constant", coordinates=[x], mass_matrix=sp.eye(1), forces=[0.1 + 0.2])
    assert exact.forces(np.zeros(1), np.zeros(1))[0] == 0.1 + 0.2

    def forces(q, qd, s, u):
        return np.array([u[0] - damping * qd[0], u[1] * math.cos(s) - MASS * G])

    other = from_callables("driven", coordinate_names=["x", "z"], mass_matrix=lambda q: MASS * np.eye(2),
                           forces=forces, n_inputs=2, input_names=["u0", "u1"])
    np.testing.assert_allclose(other.forces(q, qd, s, u), model.forces(q, qd, s, u), rtol=1e-15)
    assert other.point_positions(q).shape == (0, 2) and other.potential_energy(q) == 0.0


def test_configuration_dependent_mass_and_pickle():
    """Particle in polar coordinates: M = diag(m, m r²), T = ½ m (ṙ² + r² θ̇²)."""
    r, th = sp.symbols("r theta", positive=True)
    r_d, th_d = sp.symbols("r_d theta_d")  # other assumptions than r, theta: found by name
    attraction = 2.5  # central force -k/r²
    model = from_sympy("polar", coordinates=[r, th],
                       mass_matrix=sp.diag(MASS, MASS * r**2),
                       forces=[MASS * r * th_d**2 - attraction / r**2, -2 * MASS * r * r_d * th_d],
                       points={"P": (r * sp.cos(th), r * sp.sin(th))}, q0=[1.0, 0.0])
    assert not model.constant_mass and model.new_terms().M.flags.writeable
    q, qd = np.array([1.7, 0.4]), np.array([0.3, -1.1])
    np.testing.assert_allclose(model.mass_matrix(q), np.diag([MASS, MASS * 1.7**2]), rtol=1e-15)
    assert model.kinetic_energy(q, qd) == pytest.approx(0.5 * MASS * (0.3**2 + 1.7**2 * 1.1**2), rel=1e-14)
    np.testing.assert_allclose(model.point_positions(q), [[1.7 * math.cos(0.4), 1.7 * math.sin(0.4)]], rtol=1e-15)
    copy = pickle.loads(pickle.dumps(model))
    np.testing.assert_allclose(copy.forces(q, qd), [MASS * 1.7 * 1.1**2 - attraction / 1.7**2,
                                                    -2 * MASS * 1.7 * 0.3 * -1.1], rtol=1e-14)
    np.testing.assert_array_equal(copy.mass_matrix(q), model.mass_matrix(q))


def test_compiled_expressions_match_sympy_evaluation():
    """The generated code evaluates assorted expression shapes as sympy itself does."""
    expressions = [x**(z**2), 3 / (x * z**2), z**-2, (x**2)**sp.Rational(3, 2), sp.sqrt(x**2 + z**2),
                   sp.atan2(z, x), sp.Abs(x - z) * sp.sign(x - z), sp.exp(-x) * sp.cos(z) / 7,
                   sp.Piecewise((x**3, x > z), (z**4, True)), sp.Min(x, z) + sp.Max(x, z),
                   sp.pi * sp.tanh(x) + sp.E + sp.Rational(1, 3), sp.Heaviside(x - 1.0) * z]
    n = len(expressions)
    q = sp.symbols(f"q0:{n - 2}")
    model = from_sympy("shapes", coordinates=[x, z, *q], mass_matrix=sp.eye(n),
                       forces=expressions, q0=[0.5, 1.5] + [0.0] * (n - 2))
    for values in ([0.7, 1.9], [2.3, 0.4], [1.1, 1.1]):
        state = np.array(values + [0.0] * (n - 2))
        reference = [float(e.subs({x: values[0], z: values[1]}).evalf(30)) for e in expressions]
        np.testing.assert_allclose(model.forces(state, np.zeros(n)), reference, rtol=1e-14, atol=1e-15)


def test_numba_backend_agrees_with_python_backend(rheonomic, tmp_path, monkeypatch):
    monkeypatch.setenv("CMBS_CACHE_DIR", str(tmp_path))
    compiled = from_sympy("rheonomic", coordinates=[x, z], mass_matrix=sp.eye(2), forces=[0, 0],
                          constraints=RHEONOMIC_PHI, drivers=["phi[0]", "phi[1]"], q0=[0.0, 1.0],
                          backend="numba")
    for q, qd, s in random_states(3):
        a, b = rheonomic.evaluate(q, qd, s), compiled.evaluate(q, qd, s)
        np.testing.assert_allclose(b.buffer, a.buffer, rtol=1e-14, atol=1e-14)
    assert list(tmp_path.glob("cmbs_equations_*.py"))


def test_unusable_cache_directory_falls_back_to_a_temporary_folder(rheonomic, tmp_path, monkeypatch):
    """The generated module is imported from a file, never exec-ed: with the cache directory
    unusable (a file in its place) it goes to a temporary folder and gives the same numbers."""
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("")
    monkeypatch.setenv("CMBS_CACHE_DIR", str(blocker / "sub"))
    fallback = from_sympy("rheonomic", coordinates=[x, z], mass_matrix=sp.eye(2), forces=[0, 0],
                          constraints=RHEONOMIC_PHI, drivers=["phi[0]", "phi[1]"], q0=[0.0, 1.0],
                          backend="numba")
    for q, qd, s in random_states(3):
        np.testing.assert_allclose(fallback.evaluate(q, qd, s).buffer, rheonomic.evaluate(q, qd, s).buffer,
                                   rtol=1e-14, atol=1e-14)


# ---------------------------------------------------------------- errors
def sympy_error_cases():
    k = sp.Symbol("k")
    f = sp.Function("f")
    xr = sp.Symbol("x", real=True)
    return [
        (dict(forces=[0, -MASS * G + k * z]), "forces[1] uses unknown symbol 'k'"),
        (dict(mass_matrix=sp.diag(sp.Symbol("m"), MASS)), "mass_matrix[0, 0] uses unknown symbol 'm'"),
        (dict(constraints=[x**2 + z**2 - L**2 + x_d]), "constraints[0] uses velocity 'x_d'"),
        (dict(mass_matrix=sp.diag(MASS, MASS + t)), "mass_matrix[1, 1] uses time 't'"),
        (dict(forces=[xr, 0]), "forces[0] uses unknown symbol 'x' (a declared symbol of that name"),
        (dict(forces=[f(t), 0]), "forces[0] uses undefined function 'f'"),
        (dict(forces=[sp.Derivative(x**3, x), 0]), "forces[0] contains an unevaluated Derivative"),
        (dict(forces=[sp.I * x, 0]), "forces[0] is complex or infinite"),
        (dict(mass_matrix=sp.Matrix([[MASS, 0.1 * x], [0.2 * x, MASS]])), "mass_matrix is not symmetric"),
        (dict(mass_matrix=sp.Matrix([[MASS, 0, 0], [0, MASS, 0]])), "mass_matrix has shape (2, 3), expected (2, 2)"),
        (dict(mass_matrix=sp.diag(MASS, -MASS)), "mass_matrix is not positive definite at q0"),
        (dict(mass_matrix=sp.diag(MASS, x**2), q0=[0.0, -L]), "not positive definite at q0 = [0.0, -0.7]"),
        (dict(forces=[0, 0, 0]), "forces has 3 entries, expected 2"),
        (dict(forces=sp.Matrix([[0, -MASS * G]])), "forces must be a column vector"),
        (dict(constraints=sp.Matrix([[x, z]])), "constraints must be a column vector (k, 1), got a sympy Matrix of shape (1, 2)"),
        (dict(constraints=x**2 + z**2 - L**2), "constraints must be a column vector or a sequence"),
        (dict(potential=MASS * G * z + z_d), "potential uses velocity 'z_d'"),
        (dict(points={"P": (x, k)}), "points['P'].z uses unknown symbol 'k'"),
        (dict(points={"P": (x, z, 0)}), "points['P'] must be a pair"),
        (dict(lines=[("O", "Q")]), "lines[0] names unknown point 'Q'"),
        (dict(lines=[(0, 2)]), "lines[0] has point 2"),
        (dict(drivers=["phi[1]"]), "drivers names unknown constraint 'phi[1]' (did you mean 'phi[0]'?)"),
        (dict(drivers=[True]), "drivers must list constraint names or row indices, got True"),
        (dict(drivers=[0, "phi[0]"]), "drivers names constraint 'phi[0]' twice"),
        (dict(constraint_names=["a", "b"]), "constraint_names has 2 names, expected 1"),
        (dict(q0=[1.0]), "q0 has shape (1,), expected (2,)"),
        (dict(coordinates=[x, x]), "symbol 'x' is declared twice"),
        (dict(coordinates=[sp.Function("x")(t), z]), "coordinates[0] must be a sympy Symbol"),
        (dict(velocities=[x_d]), "velocities has 1 symbols, expected 2"),
        (dict(forces=[x_d, sp.Symbol("x_d", real=True)]), "several different symbols named 'x_d'"),
        (dict(inputs=[x]), "symbol 'x' is declared twice"),
        (dict(forces=[1 / x, 0], q0=[0.0, -L]), "evaluating the equations at q0 = [0.0, -0.7]"),
        (dict(backend="fortran"), "backend must be one of"),
    ]


@pytest.mark.parametrize("changes, message", sympy_error_cases())
def test_from_sympy_errors(changes, message):
    with pytest.raises(ModelError) as caught:
        from_sympy("bad", **pendulum_kwargs(**changes))
    assert message in str(caught.value)
    assert "model 'bad'" in str(caught.value)


def callable_error_cases():
    return [
        (dict(jacobian=None), "constraints is given without jacobian; pass them"),
        (dict(jacobian=None, gamma=None), "without jacobian and gamma"),
        (dict(mass_matrix=lambda q: np.eye(3)), "mass_matrix returned shape (3, 3), expected (2, 2)"),
        (dict(mass_matrix=lambda q: np.array([[1.0, 0.1], [0.0, 1.0]])), "mass_matrix is not symmetric at q0"),
        (dict(mass_matrix=lambda q: np.diag([1.0, 0.0])), "mass_matrix is not positive definite"),
        (dict(forces=lambda q, qd, t, u: np.zeros(3)), "forces returned shape (3,), expected (2,)"),
        (dict(forces=lambda q, qd, t, u: 1 / 0), "forces failed at q0"),
        (dict(forces=lambda q, qd, t, u: np.array([np.nan, 0.0])), "forces is not finite at q0"),
        (dict(n_constraints=2), "constraints returned 1 values but n_constraints = 2"),
        (dict(jacobian=lambda q, t: np.array([2 * q[0], 2 * q[1]])), "jacobian returned shape (2,), expected (1, 2)"),
        (dict(jacobian=lambda q, t: np.array([[2 * q[0], q[1]]])), "jacobian disagrees with finite differences"),
        (dict(gamma=lambda q, qd, t: np.array([-(qd[0]**2 + qd[1]**2)])), "gamma disagrees with finite differences"),
        (dict(constraints=lambda q, t: np.array([q[0]**2 + q[1]**2 - L**2 - 0.01 * t])),
         "constraints depend on time"),
        (dict(constraints=None), "jacobian is given but constraints is None"),
        (dict(points=lambda q: np.zeros(4)), "points returned shape (4,), expected (k, 2)"),
        (dict(point_names=["O"]), "point_names has 1 names, expected 2"),
        (dict(potential=lambda q: np.zeros(2)), "potential returned shape (2,), expected a scalar"),
        (dict(mass_matrix="M"), "mass_matrix must be callable"),
        (dict(coordinate_names=[]), "coordinate_names is empty"),
        (dict(drivers=[1.0]), "drivers must list constraint names or row indices, got 1.0"),
        (dict(drivers=[1]), "drivers row index 1 is out of range (the model has 1 constraints)"),
    ]


@pytest.mark.parametrize("changes, message", callable_error_cases())
def test_from_callables_errors(changes, message):
    with pytest.raises(ModelError) as caught:
        pendulum_callables(**changes)
    assert message in str(caught.value)
    assert "model 'pendulum-callables'" in str(caught.value)


def test_a_rheonomic_constraint_that_is_not_a_driver_survives_without_drivers():
    """A moving guide x = 0.2 sin t (a rheonomic constraint of the mechanism) stays when the
    driver row, named explicitly, is removed; without ``drivers`` a row that depends on t is an
    error naming it, not a guess."""
    guide, drive = x - sp.Rational(1, 5) * sp.sin(t), z - sp.cos(t)
    common = dict(coordinates=[x, z], mass_matrix=sp.eye(2), forces=[0, 0], constraints=[guide, drive],
                  constraint_names=["guide", "drive"], q0=[0.0, 1.0])
    model = from_sympy("moving-guide", drivers=["drive"], **common)
    free = model.without_drivers()
    assert free.constraint_names == ("guide",)
    terms = free.evaluate(np.array([0.1, 0.3]), np.zeros(2), 0.7)
    assert terms.phi[0] == pytest.approx(0.1 - 0.2 * math.sin(0.7), abs=1e-15)
    assert terms.phi_t[0] == pytest.approx(-0.2 * math.cos(0.7), abs=1e-15)
    with pytest.raises(ModelError, match=r"constraints 'guide', 'drive' depend on time; say which rows are drivers"):
        from_sympy("moving-guide", **common)
    assert from_sympy("moving-guide", drivers=[], **common).without_drivers().m == 2
