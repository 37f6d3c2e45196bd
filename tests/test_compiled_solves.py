"""The compiled solves of the penalty and Udwadia-Kalaba formulations against independent values:
Baumgarte's and Lagrange's KKT solutions, the penalty's linear system and Udwadia-Kalaba's
symmetric-square-root formula written here with numpy, the minimum-norm multipliers of
redundant constraints; and what they do with a matrix that is not positive definite or a
non-finite term; and that the penalty's allocates nothing per call."""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import cmbs
from cmbs import jit
from cmbs.dynamics import Baumgarte, Lagrange, Penalty, UdwadiaKalaba
from cmbs.errors import CmbsError, SingularSystemError
from cmbs.model.equations import from_callables
from cmbs.model.model import Terms
from test_dynamics import redundant_four_bar

REGULAR_MODELS = [("four-bar", {}), ("chain", {"links": 14, "closed": True}), ("human", {}),
                  ("slider-crank-joint", {"gravity": 9.81}), ("double-pendulum", {})]


def state_off_the_constraints(model: cmbs.Model, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """q0 moved off the constraints (Φ ≠ 0) and random velocities (Φ̇ ≠ 0), so that every term of
    the penalty's and Baumgarte's right-hand sides counts."""
    rng = np.random.default_rng(seed)
    return model.q0 + 1e-3 * rng.normal(size=model.n), rng.normal(size=model.n)


def terms_copy(model: cmbs.Model, q: np.ndarray, qd: np.ndarray, t: float = 0.0) -> Terms:
    """The terms at (q, q̇, t) in a workspace whose M can be changed."""
    source = model.evaluate(q, qd, t)
    terms = Terms(model.n, model.m)
    for name in ("M", "Q", "phi", "A", "gamma", "phi_t"):
        getattr(terms, name)[...] = getattr(source, name)
    return terms


def relative_error(value: np.ndarray, reference: np.ndarray) -> float:
    return float(np.abs(value - reference).max() / np.abs(reference).max())


# ------------------------------------------------------------------ penalty
@pytest.mark.parametrize("name, parameters", REGULAR_MODELS)
def test_converged_penalty_is_baumgarte(name, parameters):
    """The augmented Lagrangian's fixed point is Baumgarte's KKT solution with ξω = μΩ and
    ω² = Ω² (here μ = ξ = 0.7, Ω = ω = 3), off the constraints so that Φ and Φ̇ count."""
    model = cmbs.load(name, **parameters)
    q, qd = state_off_the_constraints(model, 3)
    terms = model.evaluate(q, qd, 0.2)
    exact = Baumgarte(xi=0.7, omega=3.0).bind(model).accelerations(terms, q, qd, 0.2)
    solver = Penalty(mu=0.7, Omega=3.0, iterations=50).bind(model)
    penalty = solver.accelerations(terms, q, qd, 0.2)
    assert relative_error(penalty.qdd, exact.qdd) < 1e-9
    # λ = λ* + α r carries α times the residual left by rounding in q̈
    assert relative_error(penalty.lam, exact.lam) < 1e-6
    np.testing.assert_allclose(penalty.constraint_force, -terms.A.T @ penalty.lam, rtol=0,
                               atol=1e-12 * np.abs(terms.A.T @ penalty.lam).max())
    assert solver.worst_residual < 1e-12


@pytest.mark.parametrize("name, parameters", REGULAR_MODELS)
@pytest.mark.parametrize("alpha", [None, 1e5])
def test_plain_penalty_solves_its_linear_system(name, parameters, alpha):
    """iterations=0: (M + αAᵀA) q̈ = Q + αAᵀ(γ - 2μΩΦ̇ - Ω²Φ), λ = α(Aq̈ - γ + 2μΩΦ̇ + Ω²Φ)."""
    model = cmbs.load(name, **parameters)
    q, qd = state_off_the_constraints(model, 4)
    terms = model.evaluate(q, qd, 0.1)
    mu, Omega = 0.8, 6.0
    solver = Penalty(alpha=alpha, mu=mu, Omega=Omega, iterations=0).bind(model)
    solution = solver.accelerations(terms, q, qd, 0.1)
    M, Q, A = terms.M, terms.Q, terms.A
    target = terms.gamma - 2 * mu * Omega * (A @ qd + terms.phi_t) - Omega**2 * terms.phi
    qdd = np.linalg.solve(M + solver.alpha * A.T @ A, Q + solver.alpha * A.T @ target)
    lam = solver.alpha * (A @ qdd - target)
    assert relative_error(solution.qdd, qdd) < 1e-9
    assert relative_error(solution.lam, lam) < 1e-6
    np.testing.assert_array_equal(solver.lam_star, 0.0)
    residual = np.abs(A @ qdd - target).max() / (np.abs(A).max() * np.abs(qdd).max() + np.abs(target).max())
    assert solver.worst_residual == pytest.approx(residual, rel=1e-3)


def test_penalty_keeps_lambda_star_between_evaluations():
    """The second evaluation at the same state starts from the first one's λ*, which is already
    the converged one: its plain solve is then exact, no iteration needed."""
    model = cmbs.load("four-bar")
    q, qd = state_off_the_constraints(model, 5)
    terms = model.evaluate(q, qd, 0.0)
    solver = Penalty(iterations=50).bind(model)
    first = solver.accelerations(terms, q, qd, 0.0)
    converged = solver.lam_star.copy()
    assert np.abs(converged).max() > 0
    one_step = Penalty(iterations=1).bind(model)
    one_step.lam_star[:] = converged
    second = one_step.accelerations(terms, q, qd, 0.0)
    np.testing.assert_allclose(second.qdd, first.qdd, rtol=0, atol=1e-10 * np.abs(first.qdd).max())


def test_penalty_matrix_not_positive_definite_is_a_singular_system():
    """A coordinate without mass that no constraint touches (particle on the circle at (1, 0)
    with M = diag(1, 0): A = (2, 0)) leaves M + αAᵀA singular: a one-line SingularSystemError,
    not scipy's LinAlgError."""
    model = cmbs.load("particle-circle")
    q = np.array([1.0, 0.0])
    terms = terms_copy(model, q, np.zeros(2))
    terms.M[...] = np.diag([1.0, 0.0])
    with pytest.raises(SingularSystemError, match=r"particle-circle.* at t=0\.5: the penalty matrix M \+ alpha AᵀA "
                                                  r"\(alpha = .*\) is not positive definite"):
        Penalty().bind(model).accelerations(terms, q, np.zeros(2), 0.5)


@pytest.mark.parametrize("formulation", [Penalty(), UdwadiaKalaba()], ids=["penalty", "udwadia-kalaba"])
@pytest.mark.parametrize("term", ["M", "Q", "gamma"])
def test_a_non_finite_term_gives_nan_accelerations(formulation, term):
    """A NaN in the terms (a diverging motion) gives NaN accelerations, which the integrators
    report as a non-finite state (an adaptive one first retries a smaller step), not an error
    about a singular matrix."""
    model = cmbs.load("slider-crank-joint", gravity=9.81)        # M(q): factored at each evaluation
    q, qd = model.q0, model.qd0
    terms = terms_copy(model, q, qd)
    getattr(terms, term).flat[0] = np.nan
    solution = formulation.bind(model).accelerations(terms, q, qd, 0.0)
    assert np.all(np.isnan(solution.qdd)) and np.all(np.isnan(solution.lam))
    assert np.all(np.isnan(solution.constraint_force))


# ------------------------------------------------------------------ Udwadia-Kalaba
@pytest.mark.parametrize("name, parameters", REGULAR_MODELS + [("andrews", {})])
def test_udwadia_kalaba_is_lagrange_at_a_regular_state(name, parameters):
    """With A of full row rank UK's q̈ and λ are the KKT solution's; the natural models (four-bar,
    human, double pendulum) have a semi-definite M (massless angle coordinates) and take
    M̂ = M + sAᵀA, the closed chain a constant definite M factored once, the joint slider-crank
    and Andrews' squeezer an M(q) factored at each evaluation."""
    model = cmbs.load(name, **parameters)
    q, qd = state_off_the_constraints(model, 6)
    terms = model.evaluate(q, qd, 0.4)
    exact = Lagrange().bind(model).accelerations(terms, q, qd, 0.4)
    solution = UdwadiaKalaba().bind(model).accelerations(terms, q, qd, 0.4)
    assert relative_error(solution.qdd, exact.qdd) < 1e-10
    assert relative_error(solution.lam, exact.lam) < 1e-10
    assert relative_error(solution.constraint_force, exact.constraint_force) < 1e-10


def redundant_pendulum() -> cmbs.Model:
    """Two particles in Cartesian coordinates (x1, z1, x2, z2) with a constant, non-diagonal,
    positive definite M: particle 1 on a circle of radius 1 about the origin, particle 2 at
    0.8 from particle 1, and that distance constraint given a second time, doubled."""
    mass = np.array([[2.0, 0.3, 0.0, 0.1], [0.3, 1.5, 0.2, 0.0], [0.0, 0.2, 1.0, 0.1], [0.1, 0.0, 0.1, 0.8]])

    def constraints(q, t):
        link = (q[2] - q[0])**2 + (q[3] - q[1])**2 - 0.64
        return np.array([q[0]**2 + q[1]**2 - 1.0, link, 2.0 * link])

    def jacobian(q, t):
        dx, dz = q[2] - q[0], q[3] - q[1]
        link = np.array([-2 * dx, -2 * dz, 2 * dx, 2 * dz])
        return np.array([[2 * q[0], 2 * q[1], 0.0, 0.0], link, 2.0 * link])

    def gamma(q, qd, t):
        link = -2.0 * ((qd[2] - qd[0])**2 + (qd[3] - qd[1])**2)
        return np.array([-2.0 * (qd[0]**2 + qd[1]**2), link, 2.0 * link])

    x1, z1 = math.sin(0.3), -math.cos(0.3)
    return from_callables("redundant-pendulum", coordinate_names=["x1", "z1", "x2", "z2"],
                          mass_matrix=lambda q: mass,
                          forces=lambda q, qd, t, u: np.array([0.5 * qd[1], -19.62, 0.0, -9.81 - 0.2 * qd[2]]),
                          constraints=constraints, jacobian=jacobian, gamma=gamma,
                          q0=[x1, z1, x1 + 0.8 * math.sin(0.9), z1 - 0.8 * math.cos(0.9)])


def udwadia_kalaba_reference(M: np.ndarray, Q: np.ndarray, A: np.ndarray, gamma: np.ndarray,
                             c: np.ndarray) -> np.ndarray:
    """Nicoara eq. (7)-(12) with the symmetric square root of M and numpy's pseudo-inverse:
    q̈ = a + M^{-1/2} B⁺ (γ - A a) + M^{-1/2} (I - B⁺B) M^{-1/2} c, a = M⁻¹Q, B = A M^{-1/2}."""
    values, vectors = np.linalg.eigh(M)
    inverse_root = (vectors / np.sqrt(values)) @ vectors.T
    a = np.linalg.solve(M, Q)
    B = A @ inverse_root
    B_pinv = np.linalg.pinv(B)
    return a + inverse_root @ B_pinv @ (gamma - A @ a) + inverse_root @ (np.eye(M.shape[0]) - B_pinv @ B) \
        @ inverse_root @ c


def minimum_norm_multipliers(model: cmbs.Model, A: np.ndarray, force: np.ndarray) -> np.ndarray:
    """λ with -Aᵀλ = force of least ‖D⁻¹λ‖, D = 1 / (row norms of A at q0): the multipliers of
    redundant rows shared in proportion to their scale (numpy's least squares in μ = D⁻¹λ)."""
    D = 1.0 / np.linalg.norm(model.jacobian(model.q0, 0.0), axis=1)
    mu = np.linalg.lstsq((D[:, None] * A).T, -force, rcond=None)[0]
    return D * mu


@pytest.mark.parametrize("nonideal", [False, True], ids=["ideal", "non-ideal"])
def test_udwadia_kalaba_with_redundant_constraints_is_the_symmetric_root_formula(nonideal):
    """A definite M (factored at each evaluation: a callable mass matrix) and a duplicated
    constraint row: q̈ by the formula above, λ the minimum-norm multipliers of the force."""
    model = redundant_pendulum()
    assert cmbs.constraint_report(model, model.q0).redundant
    q = model.q0
    qd = cmbs.velocities(model, q, qd=np.array([0.4, -0.2, 1.1, 0.3]))
    terms = model.evaluate(q, qd, 0.0)
    c = np.array([0.7, -1.3, 0.2, 2.1]) if nonideal else np.zeros(model.n)
    solution = UdwadiaKalaba(nonideal=(lambda t, q, qd: c) if nonideal else None).bind(model).accelerations(
        terms, q, qd, 0.0)
    expected = udwadia_kalaba_reference(terms.M, terms.Q, terms.A, terms.gamma, c)
    assert relative_error(solution.qdd, expected) < 1e-12
    force = terms.M @ expected - terms.Q
    np.testing.assert_allclose(solution.constraint_force, force, rtol=0, atol=1e-12 * np.abs(force).max())
    lam = minimum_norm_multipliers(model, terms.A, force)
    assert relative_error(solution.lam, lam) < 1e-10
    if not nonideal:            # the ideal force is in range(Aᵀ): -Aᵀλ gives it back
        np.testing.assert_allclose(-terms.A.T @ solution.lam, force, rtol=0, atol=1e-10 * np.abs(force).max())


def test_udwadia_kalaba_semi_definite_redundant_four_bar():
    """Natural coordinates (massless angle coordinate) with the coupler given twice: the formula
    with M̂ = M + sAᵀA, Q̂ = Q + sAᵀγ, s = trace M / n, and the non-ideal term."""
    model = redundant_four_bar()
    q = model.q0
    qd = cmbs.velocities(model, q, qd=np.eye(model.n)[-1] * 1.5, fixed=["alpha"])
    terms = model.evaluate(q, qd, 0.0)
    assert np.linalg.eigvalsh(terms.M)[0] < 1e-12        # semi-definite
    c = np.random.default_rng(8).normal(size=model.n)
    solution = UdwadiaKalaba(nonideal=lambda t, q, qd: c).bind(model).accelerations(terms, q, qd, 0.0)
    s = np.trace(terms.M) / model.n
    M_hat = terms.M + s * terms.A.T @ terms.A
    Q_hat = terms.Q + s * terms.A.T @ terms.gamma
    expected = udwadia_kalaba_reference(M_hat, Q_hat, terms.A, terms.gamma, c)
    assert relative_error(solution.qdd, expected) < 1e-10
    force = terms.M @ expected - terms.Q
    assert relative_error(solution.lam, minimum_norm_multipliers(model, terms.A, force)) < 1e-8


def test_udwadia_kalaba_mass_matrix_not_positive_definite_is_a_singular_system():
    model = cmbs.load("slider-crank-joint", gravity=9.81)
    terms = terms_copy(model, model.q0, model.qd0)
    terms.M[...] = np.diag([1.0, -1.0])
    with pytest.raises(SingularSystemError, match=r"slider-crank-joint.* at t=1\.5: the mass matrix M is not "
                                                  "positive definite"):
        UdwadiaKalaba().bind(model).accelerations(terms, model.q0, model.qd0, 1.5)


@pytest.mark.parametrize("value", [np.zeros(3), np.zeros((2, 2)), 1.0])
def test_udwadia_kalaba_nonideal_of_the_wrong_size_is_named(value):
    model = cmbs.load("slider-crank-joint")
    terms = model.evaluate(model.q0, model.qd0, 0.0)
    solver = UdwadiaKalaba(nonideal=lambda t, q, qd: value).bind(model)
    with pytest.raises(CmbsError, match=r"nonideal\(t, q, qd\) must return 2 values .*, got shape"):
        solver.accelerations(terms, model.q0, model.qd0, 0.0)


ALLOCATIONS = textwrap.dedent("""
    import gc
    import json

    import numpy as np
    from numba import njit
    from numba.core.runtime import rtsys

    import cmbs
    from cmbs.dynamics.penalty import penalty_solve
    from cmbs.dynamics.udwadia_kalaba import udwadia_kalaba_solve

    @njit
    def repeat_penalty(count, arguments):
        for _ in range(count):
            penalty_solve(*arguments)

    @njit
    def repeat_udwadia_kalaba(count, arguments):
        for _ in range(count):
            udwadia_kalaba_solve(*arguments)

    def allocations(repeat, count, arguments):
        gc.collect()
        before = rtsys.get_allocation_stats()
        repeat(count, arguments)
        gc.collect()
        after = rtsys.get_allocation_stats()
        return [after.alloc - before.alloc, after.free - before.free]

    model = cmbs.load("human")
    q, qd = model.q0, model.qd0 + 0.1
    terms = model.evaluate(q, qd, 0.0)
    outputs = (np.empty(model.n), np.empty(model.m), np.empty(model.n))
    penalty = cmbs.Penalty().bind(model)
    uk = cmbs.UdwadiaKalaba().bind(model)
    calls = {
        "penalty": (repeat_penalty, (terms.M, terms.Q, terms.A, terms.gamma, terms.phi, terms.phi_t, qd, penalty.alpha,
                                     1.0, 10.0, 20, 1e-12, penalty.lam_star, penalty.factor, penalty.vectors_n,
                                     penalty.vectors_m) + outputs),
        "udwadia-kalaba": (repeat_udwadia_kalaba, (terms.M, terms.Q, terms.A, terms.gamma, np.ones(model.n),
                                                   uk.augmentation, uk.factored, 1e-9, uk.row_scale, uk.mass_scale,
                                                   uk.factor, uk.work_matrix, uk.vectors_n, uk.vectors_m) + outputs),
    }
    result = {}
    for name, (repeat, arguments) in calls.items():
        repeat(1, arguments)
        result[name] = [allocations(repeat, 10, arguments), allocations(repeat, 20, arguments)]
    print(json.dumps(result))
""")


@pytest.mark.skipif(not jit.COMPILED, reason="numba's statistics: numba is not installed")
def test_penalty_solve_allocates_nothing_per_call_and_udwadia_kalaba_frees_its_svds():
    """Called 10 and 20 times from compiled code (numba's allocation statistics, switched on at
    interpreter start, hence the subprocess), the penalty's solve allocates the same: only the
    adaptation of its array arguments, once; Udwadia-Kalaba's SVDs allocate per call and free
    all of it."""
    environment = {**os.environ, "NUMBA_NRT_STATS": "1", "OPENBLAS_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-c", ALLOCATIONS], capture_output=True, text=True, env=environment,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    (ten, ten_freed), (twenty, twenty_freed) = result["penalty"]
    assert ten == twenty and ten == ten_freed and twenty == twenty_freed, result
    (ten, ten_freed), (twenty, twenty_freed) = result["udwadia-kalaba"]
    assert twenty > ten and ten == ten_freed and twenty == twenty_freed, result


def particle_losing_its_mass() -> cmbs.Model:
    """A particle on the line z = 0 pushed along x by a unit force, whose x-mass 1 - x vanishes at
    x = 1: a mass matrix that stops being positive definite in a run.  From ẍ = 1 / (1 - x),
    ẋ²/2 = -ln(1 - x), so x = 1 at t = ∫₀^∞ e^{-u} (2u)^{-1/2} du = √(π/2) = 1.2533 s."""
    return from_callables("particle-losing-its-mass", coordinate_names=["x", "z"],
                          mass_matrix=lambda q: np.diag([1.0 - q[0], 1.0]),
                          forces=lambda q, qd, t, u: np.array([1.0, -9.81]),
                          constraints=lambda q, t: np.array([q[1]]), jacobian=lambda q, t: np.array([[0.0, 1.0]]),
                          gamma=lambda q, qd, t: np.zeros(1), q0=[0.0, 0.0])


@pytest.mark.parametrize("name, problem", [
    ("penalty", r"the penalty matrix M \+ alpha AᵀA \(alpha = .*\) is not positive definite"),
    ("udwadia-kalaba", r"the mass matrix M is not positive definite \(Udwadia-Kalaba needs"),
])
def test_a_run_whose_matrix_stops_being_positive_definite_fails_with_the_message(name, problem):
    run = cmbs.simulate(particle_losing_its_mass(), t_end=2.0, integrator="rk4", dt=1e-2, formulation=name)
    assert run.info["status"] == "failed"
    assert re.search(r"model 'particle-losing-its-mass' at t=1\.25\d*: " + problem, run.info["message"]), \
        run.info["message"]


@pytest.mark.parametrize("name, parameters", REGULAR_MODELS)
def test_udwadia_kalaba_regular_path_gives_the_svd_formulas_solution(name, parameters):
    """Where A is certified regular, Udwadia-Kalaba's solve takes the augmented system
    (``_regular``): q̈, λ and the constraint force are those of its SVD formulas
    (``udwadia_kalaba_solve``, called directly) to rounding."""
    from cmbs.dynamics.udwadia_kalaba import _regular, _solve_with, udwadia_kalaba_solve

    model = cmbs.load(name, **parameters)
    solver = UdwadiaKalaba().bind(model)
    kernel = solver.kernel
    for seed in (1, 2):
        q, qd = state_off_the_constraints(model, seed)
        terms = terms_copy(model, q, qd, 0.3)
        qdd, lam = np.empty(model.n), np.empty(model.m)
        assert _regular(kernel, terms.M, terms.A, kernel.no_nonideal)[0]          # proven: _solve_with takes it
        assert _solve_with(kernel, terms.M, terms.Q, terms.A, terms.gamma, kernel.no_nonideal, qdd, lam) == 0
        force = kernel.force.copy()
        expected = np.empty(model.n), np.empty(model.m), np.empty(model.n)
        work = (np.array(kernel.factor), np.zeros((model.m, model.n)), np.zeros((3, model.n)), np.zeros((2, model.m)))
        status = udwadia_kalaba_solve(terms.M, terms.Q, terms.A, terms.gamma, np.zeros(0), kernel.augmentation,
                                      kernel.factored, kernel.threshold, kernel.row_scale, kernel.mass_scale, *work,
                                      *expected)
        assert status == 0
        for got, reference in zip((qdd, lam, force), expected):
            assert relative_error(got, reference) < 1e-9


def test_udwadia_kalaba_regular_path_declines_redundant_constraints():
    """A doubled constraint makes A rank deficient: the certificate cannot hold, the SVD formulas
    decide (and give the minimum-norm multipliers, test above)."""
    from cmbs.dynamics.udwadia_kalaba import _regular

    model = redundant_four_bar()
    kernel = UdwadiaKalaba().bind(model).kernel
    terms = terms_copy(model, model.q0, np.zeros(model.n))
    assert not _regular(kernel, terms.M, terms.A, kernel.no_nonideal)[0]
