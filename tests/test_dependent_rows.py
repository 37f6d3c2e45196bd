"""Redundant constraints without an SVD (cmbs.dynamics.dependent_rows): the pivoted Schur
complement against numpy's SVD and least squares on random systems with dependent rows, its
certificate against the singular values it bounds, and the projection and Udwadia-Kalaba on
Bricard's mechanism against their SVD paths."""

from __future__ import annotations

import numpy as np
import pytest

import cmbs
from cmbs.dynamics.dependent_rows import KEPT_LOW, RANK, RESIDUAL, TRACE, dependent_rows_arrays, solve_dependent_rows
from cmbs.dynamics.drift import _subtract_minimum_norm, _subtract_pseudo_inverse, drift_work
from cmbs.dynamics.projection import STANDARD, Projection, _by_svd
from cmbs.dynamics.udwadia_kalaba import UdwadiaKalaba, udwadia_kalaba_solve


def _solve(M, Q, A, gamma, row_scale):
    m, n = A.shape
    qdd, lam = np.full(n, np.nan), np.full(m, np.nan)
    floats, order, _ = dependent_rows_arrays(m, n)
    certificate = solve_dependent_rows(float(np.linalg.eigvalsh(M)[0]), floats, order, np.linalg.inv(M), Q, A, gamma,
                                       row_scale, np.zeros((m, n)), np.zeros((m, n), dtype=np.int64),
                                       np.zeros(m, dtype=np.int64), qdd, lam)
    return qdd, lam, certificate.copy()


def _system(rng, n: int, independent: int, dependent: int, noise: float = 0.0):
    """A random SPD M, sparse independent rows B (three non-zeros each) and rows C B (+ noise),
    shuffled, with a consistent γ = A v."""
    L = rng.normal(size=(n, n))
    M = L @ L.T + n * np.eye(n)
    B = np.zeros((independent, n))
    for row in B:
        row[rng.choice(n, 3, replace=False)] = rng.normal(size=3)
    dependent_rows = rng.normal(size=(dependent, independent)) @ B + noise * rng.normal(size=(dependent, n))
    A = np.vstack([B, dependent_rows])[rng.permutation(independent + dependent)]
    return M, rng.normal(size=n), A, A @ rng.normal(size=n)


@pytest.mark.parametrize("seed", range(5))
def test_dependent_rows_give_the_least_squares_solution_and_minimum_norm_multipliers(seed):
    rng = np.random.default_rng(seed)
    M, Q, A, gamma = _system(rng, n=12, independent=7, dependent=3)
    row_scale = rng.uniform(0.5, 2.0, size=A.shape[0])
    qdd, lam, certificate = _solve(M, Q, A, gamma, row_scale)
    assert certificate[RANK] == 7
    # independent: the null-space method with an SVD basis.  q̈ = A⁺γ + N z, N spanning null(A),
    # Nᵀ M N z = Nᵀ(Q - M A⁺γ)
    U, sigma, Vt = np.linalg.svd(A)
    N = Vt[7:].T
    particular = np.linalg.lstsq(A, gamma, rcond=None)[0]
    expected = particular + N @ np.linalg.solve(N.T @ M @ N, N.T @ (Q - M @ particular))
    np.testing.assert_allclose(qdd, expected, rtol=0, atol=1e-10 * np.abs(expected).max())
    # λ: the shortest D⁻¹λ with Aᵀλ = Q - M q̈ (the pseudo-inverse of the row-scaled A)
    scaled = A * row_scale[:, None]
    mu = np.linalg.pinv(scaled.T, rcond=1e-10) @ (Q - M @ expected)
    np.testing.assert_allclose(lam, row_scale * mu, rtol=0, atol=1e-9 * np.abs(mu).max())
    # the certificate bounds what it says it bounds
    singular = np.linalg.svd(scaled, compute_uv=False)
    assert certificate[RESIDUAL] < 1e-24
    assert certificate[KEPT_LOW] <= singular[6] ** 2
    assert certificate[TRACE] >= singular[0] ** 2 * (1 - 1e-12)


@pytest.mark.parametrize("noise", [1e-8, 1e-7])
def test_the_residual_bounds_the_singular_values_left_out(noise):
    """Rows dependent only up to ``noise``: ρ² ≥ σ²_{r+1} + ... + σ²_m (Eckart-Young), so a
    caller comparing ρ with its SVD threshold never drops a row the SVD keeps."""
    rng = np.random.default_rng(11)
    M, Q, A, gamma = _system(rng, n=10, independent=6, dependent=2, noise=noise)
    row_scale = np.ones(A.shape[0])
    _, _, certificate = _solve(M, Q, A, gamma, row_scale)
    rank = int(certificate[RANK])
    singular = np.linalg.svd(A, compute_uv=False)
    assert rank == 6                        # the remainders, about noise², fall below the stop
    assert certificate[RESIDUAL] >= np.sum(singular[rank:] ** 2) * (1 - 1e-9)
    assert certificate[RESIDUAL] > 1e-9 ** 2    # above the SVD threshold: no caller takes this path
    assert certificate[KEPT_LOW] <= singular[rank - 1] ** 2


def test_the_bound_reused_along_a_moving_a_stays_below_the_kept_rows_singular_value():
    """The same work arrays for a sequence of A: 7 sparse rows moved by ε E (ε from 1e-6 to 0.1)
    and 3 rows kept combinations of them: the
    bound on σ_min(A'_I)² stays below the SVD's value at every step, is reused (the same number
    as Weyl's (b₀ - ‖A'_k - A'_0‖_F)² from the first fresh bound b₀²) while the move is at most
    REUSE·b₀, and is fresh again (λ_min(M)/trace(S_II⁻¹), the value a new work array gives) once
    it is more."""
    from cmbs.dynamics.dependent_rows import REUSE

    rng = np.random.default_rng(4)
    M, Q, _, gamma = _system(rng, n=12, independent=7, dependent=3)
    n, m = 12, 10
    B = np.zeros((7, n))
    for row in B:
        row[rng.choice(n, 3, replace=False)] = rng.normal(size=3)
    combination, shuffle = rng.normal(size=(3, 7)), rng.permutation(m)
    E = rng.normal(size=B.shape) * (B != 0)

    def jacobian(epsilon):              # B moved by ε E, the dependent rows kept combinations of it
        moved = B + epsilon * E
        return np.vstack([moved, combination @ moved])[shuffle]

    A = jacobian(0.0)
    row_scale = rng.uniform(0.5, 2.0, size=m)
    floats, order, _ = dependent_rows_arrays(m, n)
    first = None
    reused = fresh = 0
    for epsilon in (0.0, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1):
        moved = jacobian(epsilon)
        qdd, lam = np.zeros(n), np.zeros(m)
        certificate = solve_dependent_rows(float(np.linalg.eigvalsh(M)[0]), floats, order, np.linalg.inv(M), Q, moved,
                                           gamma, row_scale, np.zeros((m, n)), np.zeros((m, n), dtype=np.int64),
                                           np.zeros(m, dtype=np.int64), qdd, lam)
        assert certificate[RANK] == 7
        kept = np.sort(order[:7])
        sigma = np.linalg.svd((moved * row_scale[:, None])[kept], compute_uv=False)[-1]
        assert certificate[KEPT_LOW] <= sigma**2 * (1 + 1e-12)
        _, _, alone = _solve(M, Q, moved, gamma, row_scale)      # fresh work arrays: the fresh bound
        if first is None:
            first = np.sqrt(alone[KEPT_LOW]), A * row_scale[:, None]
            assert certificate[KEPT_LOW] == alone[KEPT_LOW]
            continue
        delta = np.linalg.norm((moved * row_scale[:, None] - first[1])[kept])
        if delta <= REUSE * first[0]:
            assert certificate[KEPT_LOW] == pytest.approx((first[0] - delta) ** 2, rel=1e-12)
            reused += 1
        else:
            assert certificate[KEPT_LOW] == pytest.approx(alone[KEPT_LOW], rel=1e-12)
            first = np.sqrt(alone[KEPT_LOW]), moved * row_scale[:, None]
            fresh += 1
    assert reused >= 2 and fresh >= 1


def _bricard_states():
    model = cmbs.load("bricard")
    run = cmbs.simulate(model, t_end=2.0, formulation="projection", integrator="dop853", rtol=1e-10, atol=1e-12,
                        dt=0.5)
    return model, [(run.q[k], run.qd[k], run.t[k]) for k in range(run.t.size)]


def test_bricard_projection_takes_the_dependent_rows_and_matches_the_svd():
    model, states = _bricard_states()
    solver = Projection().bind(model)
    for q, qd, t in states:
        terms = model.evaluate(q, qd, t)
        M, A = model.mass_matrix(q), model.jacobian(q, t)
        Q, gamma = model.forces(q, qd, t), model.gamma(q, qd, t)
        fast = solver.accelerations(terms, q, qd, t)
        assert solver.kernel.last_path[0] == 1            # the path of dependent rows, not the SVD
        qdd, lam = np.empty(model.n), np.empty(model.m)
        assert _by_svd(M, Q, A, gamma, solver.row_scale, 1e-9, STANDARD, 1.0, solver.scale, False, qdd, lam)
        np.testing.assert_allclose(fast.qdd, qdd, rtol=0, atol=1e-9 * np.abs(qdd).max())
        np.testing.assert_allclose(fast.lam, lam, rtol=0, atol=1e-9 * np.abs(lam).max())


def test_bricard_udwadia_kalaba_takes_the_dependent_rows_and_matches_the_svds():
    model, states = _bricard_states()
    solver = UdwadiaKalaba().bind(model)
    for q, qd, t in states:
        terms = model.evaluate(q, qd, t)
        fast = solver.accelerations(terms, q, qd, t)
        assert solver.kernel.last_path[0] == 1
        M, A = model.mass_matrix(q), model.jacobian(q, t)
        Q, gamma = model.forces(q, qd, t), model.gamma(q, qd, t)
        n, m = model.n, model.m
        factor = np.linalg.cholesky(M)
        qdd, lam, force = np.empty(n), np.empty(m), np.empty(n)
        status = udwadia_kalaba_solve(M, Q, A, gamma, np.zeros(0), 0.0, True, 1e-9, solver.row_scale,
                                      float(solver.mass_scale), factor.copy(), np.zeros((m, n)), np.zeros((3, n)),
                                      np.zeros((2, m)), qdd, lam, force)
        assert status == 0
        np.testing.assert_allclose(fast.qdd, qdd, rtol=0, atol=1e-9 * np.abs(qdd).max())
        np.testing.assert_allclose(fast.lam, lam, rtol=0, atol=1e-9 * np.abs(lam).max())


@pytest.mark.parametrize("name", ["bricard", "four-bar-3d", "four-bar"])
def test_drift_projection_steps_match_the_svd(name):
    """The drift projection's minimum-norm steps (x - A⁺b, and x - A⁺b - A⁺A x for velocities)
    equal the SVD's, near the constraint manifold of a redundant and two regular mechanisms."""
    model = cmbs.load(name)
    rng = np.random.default_rng(3)
    work = drift_work(model)
    q = model.q0 + 1e-6 * rng.normal(size=model.n)
    A, phi = model.jacobian(q, 0.0), model.constraints(q, 0.0)
    x = rng.normal(size=model.n)
    for b, row_space in ((phi, 0.0), (rng.normal(size=model.m), 1.0)):
        fast, svd = x.copy(), x.copy()
        _subtract_minimum_norm(work, A, b, 1e-9, fast, row_space)
        _subtract_pseudo_inverse(A, b, 1e-9, svd, row_space)
        np.testing.assert_allclose(fast, svd, rtol=0, atol=1e-9 * max(np.abs(svd).max(), np.abs(x).max()))


def test_zero_rows_certify_nothing_and_the_svd_decides():
    """A Jacobian without a non-zero row has no row to keep: no certificate (the callers then
    take their SVD path, which keeps nothing either)."""
    M, Q = np.diag([2.0, 3.0, 4.0]), np.array([1.0, -1.0, 0.5])
    _, _, certificate = _solve(M, Q, np.zeros((2, 3)), np.zeros(2), np.ones(2))
    assert certificate.size == 0
