"""Matrix R's kernels (cmbs.dynamics.matrix_r_kernels), which MatrixRSolver and the compiled loops
share, against references written here: the recovered state satisfies Φ = 0 and A q̇ + Φ_t = 0
with z and ż held, R spans null(A_r) with the identity on the independent rows, and the
accelerations and multipliers are those of the Lagrange KKT system solved by numpy."""

import math

import numpy as np
import pytest

import cmbs
from cmbs.dynamics.matrix_r_kernels import condition_one, condition_two, factor_dependent
from cmbs.model.equations import from_callables

MODELS = ["slider-crank", "slider-crank-joint", "four-bar-free", "chain-8-closed"]


def _load(name: str) -> cmbs.Model:
    if name == "four-bar-free":
        return cmbs.load("four-bar").without_drivers()
    if name == "chain-8-closed":
        return cmbs.load("chain", links=8, closed=True)
    return cmbs.load(name)


def _consistent_state(model: cmbs.Model) -> tuple[np.ndarray, np.ndarray]:
    """q0 and a random velocity satisfying A q̇ + Φ_t = 0 (by numpy's least squares)."""
    q = np.array(model.q0, dtype=float)
    terms = model.evaluate(q, np.zeros(model.n), 0.0)
    generator = np.random.default_rng(3)
    guess = generator.normal(size=model.n)
    correction = np.linalg.lstsq(terms.A, terms.A @ guess + terms.phi_t, rcond=None)[0]
    return q, guess - correction


def _callable_pendulum() -> cmbs.Model:
    """The 1 m point pendulum in (x, z) from Python functions: only Python evaluates its terms."""
    return from_callables("callable-pendulum", coordinate_names=["x", "z"], mass_matrix=lambda q: np.eye(2),
                          forces=lambda q, qd, t, u: np.array([0.0, -9.81]),
                          constraints=lambda q, t: np.array([q @ q - 1.0]),
                          jacobian=lambda q, t: np.array([2.0 * q]), gamma=lambda q, qd, t: np.array([-2.0 * qd @ qd]),
                          q0=[math.cos(-0.6), math.sin(-0.6)])


@pytest.mark.parametrize("name", MODELS + ["callable", "four-bar"])
def test_recovery_satisfies_the_constraints_and_keeps_z(name):
    """From a state pushed off the constraints by 1e-3, the recovered q has |Φ| < 1e-12 and the
    recovered q̇ has |A q̇ + Φ_t| < 1e-12 (numpy's evaluation of the model), z and ż unchanged
    bit for bit (the Python-callable model runs the same recovery interpreted; the driven
    four-bar, all of whose coordinates are dependent, has Φ_t ≠ 0)."""
    model = _callable_pendulum() if name == "callable" else cmbs.load(name) if name == "four-bar" else _load(name)
    solver = cmbs.formulation("matrix-r").bind(model)
    t = 0.5 if name == "four-bar" else 0.0
    if name == "four-bar":                      # driven: its kinematics at t
        motion = cmbs.kinematic_analysis(model, np.array([t]))
        q, qd = motion.q[0], motion.qd[0]
        assert np.abs(model.evaluate(q, qd, t).phi_t).max() > 0.1
    else:
        q, qd = _consistent_state(model)
    generator = np.random.default_rng(5)
    pushed_q = q + 1e-3 * generator.normal(size=model.n)
    pushed_qd = qd + 1e-3 * generator.normal(size=model.n)
    recovered_q, recovered_qd = solver.recover(pushed_q, pushed_qd, t)
    independent = solver.partition.independent
    np.testing.assert_array_equal(recovered_q[independent], pushed_q[independent])
    np.testing.assert_array_equal(recovered_qd[independent], pushed_qd[independent])
    assert np.abs(recovered_q - pushed_q).max() > 1e-5          # the dependent coordinates moved
    terms = model.evaluate(recovered_q, recovered_qd, t)
    assert np.abs(terms.phi).max() < 1e-12
    assert np.abs(terms.A @ recovered_qd + terms.phi_t).max() < 1e-12


@pytest.mark.parametrize("name", MODELS)
def test_velocity_matrix_spans_the_null_space_with_the_identity_on_z(name):
    """A R = 0 (every row of A at a consistent configuration, not only the partition's) and
    R's independent rows are the identity, so q̇ = R ż is the motion the constraints allow."""
    model = _load(name)
    solver = cmbs.formulation("matrix-r").bind(model)
    q, qd = _consistent_state(model)
    terms = model.evaluate(q, qd, 0.0)
    R = solver.velocity_matrix(terms)
    k = solver.partition.independent.size
    assert R.shape == (model.n, k) and k == model.n - np.linalg.matrix_rank(terms.A)
    np.testing.assert_array_equal(R[solver.partition.independent], np.eye(k))
    assert np.abs(terms.A @ R).max() < 1e-12 * max(1.0, np.abs(terms.A).max() * np.abs(R).max())


@pytest.mark.parametrize("name", MODELS + ["callable"])
def test_accelerations_are_the_lagrange_kkt_solution(name):
    """At a regular configuration with a random consistent velocity, q̈ and λ of matrix R are the
    solution of [M Aᵀ; A 0][q̈; λ] = [Q; γ] by numpy (rows of A not in the partition, redundant
    there, carry λ = 0, and the KKT system is solved on the partition's rows)."""
    model = _callable_pendulum() if name == "callable" else _load(name)
    solver = cmbs.formulation("matrix-r").bind(model)
    q, qd = _consistent_state(model)
    terms = model.evaluate(q, qd, 0.0)
    result = solver.accelerations(terms, q, qd, 0.0)
    rows = solver.partition.rows
    A, n, r = terms.A[rows], model.n, rows.size
    kkt = np.block([[terms.M, A.T], [A, np.zeros((r, r))]])
    solution = np.linalg.solve(kkt, np.concatenate([terms.Q, terms.gamma[rows]]))
    scale = max(1.0, np.abs(solution).max())
    np.testing.assert_allclose(result.qdd, solution[:n], rtol=0, atol=1e-10 * scale)
    expected_lam = np.zeros(model.m)
    expected_lam[rows] = solution[n:]
    np.testing.assert_allclose(result.lam, expected_lam, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(result.constraint_force, -terms.A.T @ expected_lam, rtol=0, atol=1e-9 * scale)


def test_condition_kernels_against_numpy_norms():
    """κ₁ from the LU factors is ‖A_r‖₁ ‖A_d⁻¹‖₁ by numpy; κ₂ of the re-partition test is
    ‖A_r‖₂ / σ_min(A_d) by numpy's SVDs."""
    generator = np.random.default_rng(13)
    n, m = 7, 5
    rows, dependent = np.array([0, 2, 3, 4]), np.array([1, 3, 5, 6])
    for scale in (1.0, 1e-3, 1e-8):
        A = generator.normal(size=(m, n))
        A[4, dependent] = A[0, dependent] + scale * generator.normal(size=4)   # A_d nearly singular
        r = rows.size
        Ad, pivots, side = np.empty((r, r)), np.empty(r, dtype=np.int64), np.empty(r)
        assert factor_dependent(A, rows, dependent, Ad, pivots)
        block = A[np.ix_(rows, dependent)]
        expected_one = np.linalg.norm(A[rows], 1) * np.linalg.norm(np.linalg.inv(block), 1)
        assert condition_one(A, rows, Ad, pivots, side) == pytest.approx(expected_one, rel=1e-6)
        kappa = np.linalg.svd(A[rows], compute_uv=False)[0] / np.linalg.svd(block, compute_uv=False)[-1]
        assert condition_two(A, rows, dependent) == pytest.approx(kappa, rel=1e-9)


@pytest.mark.parametrize("name", MODELS)
def test_dependent_accelerations_satisfy_the_acceleration_constraints(name):
    """The trapezoidal rule's expansion of z̈: with random independent accelerations held (bit for
    bit), the dependent ones make A q̈ = γ on every row (numpy's evaluation), and they are those
    of R z̈ + S (the velocity matrix and the KKT solution's S = q̈ - R z̈ at z̈ = 0)."""
    model = _load(name)
    solver = cmbs.formulation("matrix-r").bind(model)
    q, qd = _consistent_state(model)
    terms = model.evaluate(q, qd, 0.0)
    generator = np.random.default_rng(17)
    guess = generator.normal(size=model.n)
    qdd = solver.dependent_accelerations(terms, guess)
    independent = solver.partition.independent
    np.testing.assert_array_equal(qdd[independent], guess[independent])
    scale = max(1.0, np.abs(qdd).max(), np.abs(terms.gamma).max())
    assert np.abs(terms.A @ qdd - terms.gamma).max() < 1e-11 * scale
    at_rest = solver.dependent_accelerations(terms, np.zeros(model.n))
    R = solver.velocity_matrix(terms)
    np.testing.assert_allclose(qdd, R @ guess[independent] + at_rest, rtol=0, atol=1e-11 * scale)
