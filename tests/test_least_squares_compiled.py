"""Lagrange's and Baumgarte's ``least_squares`` option, one compiled solve: the minimum-norm
least-squares solution of the augmented system [M Aᵀ; A 0][q̈; λ] = [Q; c] against numpy's
``np.linalg.lstsq`` (default cut-off) of the system written here, at a regular configuration
(where it is the regular solution), with a redundant constraint (where q̈ is the mechanism's
without it) and at a singular position; the cut-off itself; and runs with the option, now on the
compiled loop, against other formulations on the same redundant mechanism."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import cmbs
from cmbs.dynamics import Baumgarte, Lagrange
from cmbs.dynamics.field import CompiledDynamics
from cmbs.model.model import Terms
from cmbs.simulate import simulate
from test_dynamics import redundant_four_bar

#: the option on each formulation (Baumgarte away from its defaults, so that ξ and ω both count)
FORMULATIONS = {"lagrange": Lagrange(least_squares=True),
                "baumgarte": Baumgarte(xi=0.7, omega=3.0, least_squares=True)}


def slider_crank_at_90_degrees() -> tuple[cmbs.Model, np.ndarray]:
    """The equal-link slider-crank with the crank at 90° (C over O): A loses rank."""
    model = cmbs.load("slider-crank")
    values = dict(zip(model.coordinate_names, model.q0))
    values.update({"A.x": 0.0, "A.z": 1.0, "C.x": 0.0, "theta1": math.pi / 2, "theta2": -math.pi})
    return model, np.array([values[name] for name in model.coordinate_names])


def configuration(kind: str) -> tuple[cmbs.Model, np.ndarray, np.ndarray]:
    """(model, q, q̇) with q̇ arbitrary (Φ̇ ≠ 0) and, at the regular and redundant
    configurations, q a little off the constraints (Φ ≠ 0), so that every term of Baumgarte's
    right-hand side counts (the singular position is kept exactly: A has rank m - 1 there)."""
    rng = np.random.default_rng(7)
    if kind == "singular":
        model, q = slider_crank_at_90_degrees()
        return model, q, rng.normal(size=model.n)
    model = cmbs.load("four-bar").without_drivers() if kind == "regular" else redundant_four_bar()
    return model, model.q0 + 1e-4 * rng.normal(size=model.n), rng.normal(size=model.n)


def numpy_minimum_norm(formulation, terms: Terms, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(q̈, λ): numpy's minimum-norm least-squares solution of the augmented system, with
    c = γ - 2ξωΦ̇ - ω²Φ, Φ̇ = Aq̇ + Φ_t (ξ = ω = 0 for Lagrange)."""
    n, m = terms.A.shape[1], terms.A.shape[0]
    xi, omega = getattr(formulation, "xi", 0.0), getattr(formulation, "omega", 0.0)
    c = terms.gamma - 2.0 * xi * omega * (terms.A @ qd + terms.phi_t) - omega**2 * terms.phi
    K = np.block([[terms.M, terms.A.T], [terms.A, np.zeros((m, m))]])
    solution = np.linalg.lstsq(K, np.concatenate([terms.Q, c]), rcond=None)[0]
    return solution[:n], solution[n:]


def relative_error(value: np.ndarray, reference: np.ndarray) -> float:
    return float(np.abs(value - reference).max() / np.abs(reference).max())


@pytest.mark.parametrize("kind", ["regular", "redundant", "singular"])
@pytest.mark.parametrize("name", list(FORMULATIONS))
def test_least_squares_solve_is_numpys_minimum_norm_solution(name, kind):
    """The bound solver's accelerations (one call of the compiled solve) and the compiled field
    (what the compiled loops run) give numpy's solution of the system written above."""
    formulation = FORMULATIONS[name]
    model, q, qd = configuration(kind)
    solver = formulation.bind(model)
    assert formulation.compiled(solver, model) is solver.kernel is not None
    terms = model.evaluate(q, qd, 0.0)
    assert np.linalg.matrix_rank(terms.A) == (model.m if kind == "regular" else model.m - 1)
    qdd, lam = numpy_minimum_norm(formulation, terms, qd)
    solution = solver.accelerations(terms, q, qd, 0.0)
    assert relative_error(solution.qdd, qdd) < 1e-12 and relative_error(solution.lam, lam) < 1e-12
    np.testing.assert_allclose(solution.constraint_force, -terms.A.T @ lam, rtol=0,
                               atol=1e-12 * np.abs(terms.A.T @ lam).max())
    field_qdd, field_lam = CompiledDynamics(model, formulation).accelerations(q, qd)
    assert relative_error(field_qdd, qdd) < 1e-12 and relative_error(field_lam, lam) < 1e-12


@pytest.mark.parametrize("name", list(FORMULATIONS))
def test_least_squares_is_the_regular_solution_where_there_is_one(name):
    """At a regular configuration the system has one solution: the regular solve's.  With a
    coupler given twice, q̈ and the constraint force are those of the four-bar without the
    duplicate (the duplicate's c equals its original's, so the system is consistent)."""
    formulation = FORMULATIONS[name]
    plain_formulation = dataclasses.replace(formulation, least_squares=False)
    model, q, qd = configuration("regular")
    terms = model.evaluate(q, qd, 0.0)
    regular = plain_formulation.bind(model).accelerations(terms, q, qd, 0.0)
    solution = formulation.bind(model).accelerations(terms, q, qd, 0.0)
    assert relative_error(solution.qdd, regular.qdd) < 1e-10 and relative_error(solution.lam, regular.lam) < 1e-10
    redundant = redundant_four_bar()
    duplicated = formulation.bind(redundant).accelerations(redundant.evaluate(q, qd, 0.0), q, qd, 0.0)
    assert relative_error(duplicated.qdd, regular.qdd) < 1e-10
    assert relative_error(duplicated.constraint_force, regular.constraint_force) < 1e-10


def test_least_squares_cut_off_is_numpys_default():
    """Singular values up to ε·(n + m)·σ_max count as zero, as with numpy's ``rcond=None``.

    Terms written by hand on the 14-link closed chain's sizes (n = 26, m = 14): M = I, the
    constraint rows e_1 ... e_13 and δ e_0 with δ² = 3e-15 σ_max.  Then K = [I Aᵀ; A 0] has
    σ_max = (1 + √5)/2 and σ_min ≈ δ², between LAPACK's own cut-off ε σ_max (numba's default
    rcond = -1) and numpy's 40 ε σ_max.  Cut off, the δ pair gives q̈_0 = (Q_0 + δγ_0)/(1 + δ²)
    ≈ Q_0 and λ_0 ≈ δ Q_0; kept, q̈_0 = γ_0/δ ≈ 1e7."""
    model = cmbs.load("chain", links=14, closed=True)
    n, m = model.n, model.m
    sigma_max = (1.0 + math.sqrt(5.0)) / 2.0
    delta = math.sqrt(3e-15 * sigma_max)
    terms = Terms(n, m)
    terms.M[:] = np.eye(n)
    terms.A[0, 0] = delta
    for r in range(1, m):
        terms.A[r, r] = 1.0
    terms.Q[:] = np.linspace(1.0, 2.0, n)
    terms.gamma[:] = np.linspace(-1.0, 1.0, m) + 0.5
    q, qd = model.q0, np.zeros(n)
    solution = Lagrange(least_squares=True).bind(model).accelerations(terms, q, qd, 0.0)
    qdd, lam = numpy_minimum_norm(Lagrange(), terms, qd)
    assert relative_error(solution.qdd, qdd) < 1e-12 and relative_error(solution.lam, lam) < 1e-12
    assert solution.qdd[0] == pytest.approx(terms.Q[0], rel=1e-6)
    assert solution.lam[0] == pytest.approx(delta * terms.Q[0], rel=1e-6)


def test_least_squares_with_non_finite_terms_gives_nan_not_an_exception():
    """An overflowed velocity in Baumgarte's right-hand side (terms finite) gives NaN
    accelerations, the state the integrators report as diverged, not LAPACK's refusal."""
    model = cmbs.load("four-bar").without_drivers()
    q = model.q0
    qd = np.full(model.n, np.inf)
    terms = model.evaluate(q, np.zeros(model.n), 0.0)
    solution = FORMULATIONS["baumgarte"].bind(model).accelerations(terms, q, qd, 0.0)
    assert np.isnan(solution.qdd).all() and np.isnan(solution.lam).all()


@pytest.mark.parametrize("reference", ["projection", "udwadia-kalaba"])
def test_least_squares_run_is_compiled_and_moves_as_the_other_formulations(reference):
    """Lagrange with least squares on the four-bar with its coupler given twice runs on the
    compiled loop and moves as the projection and Udwadia-Kalaba, which handle the redundant row
    on their own (1 s of RK4 at 1 ms, every run compiled)."""
    model = redundant_four_bar()
    qd0 = cmbs.velocities(model, model.q0, qd=np.eye(model.n)[-1] * 2.0)
    options = dict(t_end=1.0, integrator="rk4", dt=1e-3, qd0=qd0)
    run = simulate(model, formulation="lagrange", formulation_options={"least_squares": True}, **options)
    other = simulate(model, formulation=reference, **options)
    for trajectory in (run, other):
        assert trajectory.info["compiled"] and trajectory.info["status"] == "success"
        assert "Python loop" not in trajectory.info.get("note", "")
    assert np.abs(run.q - other.q).max() < 1e-8
    assert np.abs(run.qd - other.qd).max() < 1e-8


def test_baumgarte_least_squares_run_moves_as_baumgarte_without_the_duplicate():
    """Baumgarte with least squares on the redundant four-bar moves as plain Baumgarte on the
    four-bar without the duplicate (both compiled; the regular run by the Schur complement).
    RK4 at 10 ms for 5 s drifts off the constraints, so that the stabilisation acts."""
    redundant, plain = redundant_four_bar(), cmbs.load("four-bar").without_drivers()
    qd0 = cmbs.velocities(plain, plain.q0, qd=np.eye(plain.n)[-1] * 3.0)
    options = dict(t_end=5.0, integrator="rk4", dt=1e-2, qd0=qd0, formulation="baumgarte")
    run = simulate(redundant, formulation_options={"least_squares": True, "xi": 0.7, "omega": 3.0}, **options)
    regular = simulate(plain, formulation_options={"xi": 0.7, "omega": 3.0}, **options)
    assert run.info["compiled"] and regular.info["compiled"] and run.info["status"] == "success"
    assert run["constraint_error"].max() > 1e-9
    assert np.abs(run.q - regular.q).max() < 1e-8 and np.abs(run.qd - regular.qd).max() < 1e-8


def test_batched_sweep_runs_least_squares_one_variant_at_a_time():
    """The sweep's lanes solve the regular system: a least-squares kernel is refused there and the
    batched sweep runs each variant in the one-variant loop, bit for bit the single runs."""
    from cmbs.integrate.compiled_lanes import lane_setup
    from cmbs.model.compiled import model_kernel
    from cmbs.sweep import Variant, sweep

    model = cmbs.load("four-bar").without_drivers()
    kernels = {flag: Lagrange(least_squares=flag).compiled(Lagrange(least_squares=flag).bind(model), model)
               for flag in (False, True)}
    assert lane_setup(model_kernel(model), kernels[False], model.m, model.n) is not None
    assert lane_setup(model_kernel(model), kernels[True], model.m, model.n) is None
    variants = [Variant(qd0=cmbs.velocities(model, model.q0, qd=np.eye(model.n)[-1] * speed))
                for speed in (-1.0, 0.5, 2.0)]
    options = dict(t_end=0.5, dt=1e-3, integrator="rk4", formulation="lagrange",
                   formulation_options={"least_squares": True})
    result = sweep(model, variants, batched=True, **options)
    assert result.info["mode"] == "batched"
    for v, variant in enumerate(variants):
        np.testing.assert_array_equal(result.q[v], simulate(model, qd0=variant.qd0, **options).q)
