"""Band LU of the KKT matrix, profile Cholesky and the Takahashi trace of G⁻¹ (cmbs.banded),
against numpy, and the large chains they make affordable."""

import numpy as np
import pytest

import cmbs
from cmbs.banded import band_factor, band_plan, band_solve, gram_profile, inverse_trace, jacobian_pattern
from cmbs.dynamics.field import CompiledDynamics
from cmbs.dynamics.kkt import cholesky_in_place, packed_workspace, workspace_views
from cmbs.dynamics.lagrange import BandLagrangeKernel
from cmbs.dynamics.projection import BandProjectionKernel
from cmbs.dynamics.udwadia_kalaba import BandUdwadiaKalabaKernel
from cmbs.integrate.variants import fresh


def _band_storage(K, order, width):
    """K permuted by ``order`` in the storage of band_factor."""
    P = K[np.ix_(order, order)]
    size = K.shape[0]
    AB = np.zeros((size, 3 * width + 1))
    for i in range(size):
        for j in range(max(0, i - width), min(size, i + width + 1)):
            AB[j, 2 * width + i - j] = P[i, j]
    return AB, P


@pytest.mark.parametrize("links", [14, 60])
def test_band_lu_solves_the_kkt_system_of_a_chain(links):
    """The KKT matrix of a pinned chain at a random state, permuted by reverse Cuthill-McKee:
    band LU with partial pivoting gives numpy's dense solution; the half-width does not grow
    with the number of links."""
    model = cmbs.load("chain", links=links, closed=True)
    pattern = jacobian_pattern(model)
    order, width = band_plan(model.mass_matrix(model.q0), pattern)
    assert width <= 8
    rng = np.random.default_rng(links)
    q = model.q0 + 0.01 * rng.normal(size=model.n)
    terms = model.evaluate(q, rng.normal(size=model.n), 0.0)
    n, m = model.n, model.m
    K = np.block([[terms.M, terms.A.T], [terms.A, np.zeros((m, m))]])
    rhs = rng.normal(size=n + m)
    AB, P = _band_storage(K, order, width)
    pivots = np.zeros(n + m, dtype=np.int64)
    assert band_factor(AB, width, pivots)
    b = rhs[order].copy()
    band_solve(AB, width, pivots, b)
    expected = np.linalg.solve(P, rhs[order])
    np.testing.assert_allclose(b, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())


def test_band_lu_reports_a_singular_matrix():
    K = np.diag([1.0, 0.0, 2.0])
    AB, _ = _band_storage(K, np.arange(3), 1)
    assert not band_factor(AB, 1, np.zeros(3, dtype=np.int64))


def test_profile_cholesky_and_takahashi_trace_match_numpy():
    """G = A Aᵀ of a random banded A: the profile from A's pattern, the factor within it, and
    trace(G⁻¹) by the Takahashi recurrence equal numpy's Cholesky and inverse."""
    rng = np.random.default_rng(4)
    m, n = 40, 84
    A = np.zeros((m, n))
    for r in range(m):
        columns = rng.choice(np.arange(max(0, 2 * r - 3), min(n, 2 * r + 4)), size=3, replace=False)
        A[r, columns] = rng.normal(size=3)
    G = A @ A.T + 0.1 * np.eye(m)
    start = gram_profile(A != 0.0)
    assert start.max() > 0 and np.all(start <= np.arange(m))
    for i in range(m):                       # the profile covers G's non-zeros
        assert np.all(G[i, :start[i]] == 0.0)
    factor = np.tril(G).copy()
    assert cholesky_in_place(factor, start)
    np.testing.assert_allclose(np.tril(factor), np.linalg.cholesky(G), rtol=0, atol=1e-12)
    width = int(np.max(np.arange(m) - start))
    Z = np.zeros((m, width + 1))
    assert inverse_trace(factor, start, Z) == pytest.approx(np.trace(np.linalg.inv(G)), rel=1e-11)
    dense = np.tril(G).copy()                # the dense profile gives the same
    assert cholesky_in_place(dense, np.zeros(m, dtype=np.int64))
    assert inverse_trace(dense, np.zeros(m, dtype=np.int64), np.zeros((m, m))) == pytest.approx(
        np.trace(np.linalg.inv(G)), rel=1e-11)


@pytest.mark.parametrize("closed", [False, True])
def test_large_chains_take_the_band_path_with_the_python_solver_results(closed):
    """200 links (n = 400): the compiled evaluation uses the band KKT solve (a kernel of the band
    class, which a copy for a sweep keeps) and gives the solution of [M Aᵀ; A 0][q̈; λ] = [Q; γ] by
    numpy's dense LU to 1e-9; Lagrange, projection and Udwadia-Kalaba alike (at a regular state
    the three coincide)."""
    model = cmbs.load("chain", links=200, closed=closed)
    rng = np.random.default_rng(9)
    q = cmbs.assemble(model, model.q0 + 1e-3 * rng.normal(size=model.n), tolerance=1e-13)
    qd = cmbs.velocities(model, q, qd=rng.normal(size=model.n))
    terms = model.evaluate(q, qd, 0.0)
    n, m = model.n, model.m
    kkt = np.block([[terms.M, terms.A.T], [terms.A, np.zeros((m, m))]])
    solution = np.linalg.solve(kkt, np.concatenate([terms.Q, terms.gamma]))     # numpy's dense LU
    expected_qdd, expected_lam = solution[:n], solution[n:]
    for name, kind in (("lagrange", BandLagrangeKernel), ("projection", BandProjectionKernel),
                       ("udwadia-kalaba", BandUdwadiaKalabaKernel)):
        compiled = CompiledDynamics(model, name)
        assert workspace_views(*packed_workspace(model))[16] == 1      # the band KKT plan is used
        assert type(compiled.solver.kernel) is kind and type(fresh(compiled.solver.kernel)) is kind
        qdd, lam = compiled.accelerations(q, qd)
        np.testing.assert_allclose(qdd, expected_qdd, rtol=0, atol=1e-9 * np.abs(expected_qdd).max())
        np.testing.assert_allclose(lam, expected_lam, rtol=0, atol=1e-9 * np.abs(expected_lam).max())


def test_a_200_link_closed_chain_runs_and_conserves_energy():
    model = cmbs.load("chain", links=200, closed=True)
    run = cmbs.simulate(model, t_end=0.05, integrator="rk4", dt=1e-3, formulation="baumgarte")
    assert run.info["compiled"] and run.info["status"] == "success"
    energy = run["energy"]
    assert np.abs(energy - energy[0]).max() < 1e-6 * max(1.0, np.abs(energy).max())
    assert run["constraint_error"].max() < 1e-9
