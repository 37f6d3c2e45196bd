"""The compiled RK4 loop gives the Python loop's results (same formulation, same steps)."""

import numpy as np
import pytest

import cmbs
from cmbs.errors import CmbsError
from cmbs.simulate import simulate


@pytest.mark.parametrize("name", ["four-bar", "slider-crank-joint"])
@pytest.mark.parametrize("formulation", ["lagrange", "baumgarte", "projection"])
def test_compiled_loop_equals_python_loop(name, formulation):
    model = cmbs.load(name, gravity=9.81) if name == "slider-crank-joint" else cmbs.load(name).without_drivers()
    runs = [simulate(model, t_end=0.3, integrator="rk4", dt=1e-3, formulation=formulation, compiled=flag)
            for flag in (True, False)]
    fast, python = runs
    assert fast.info["compiled"] and "compiled" not in python.info
    np.testing.assert_allclose(fast.q, python.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.qd, python.qd, rtol=0, atol=1e-11)
    np.testing.assert_allclose(fast.qdd, python.qdd, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(fast["lam"], python["lam"], rtol=1e-9, atol=1e-8)
    np.testing.assert_allclose(fast["energy"], python["energy"], rtol=0, atol=1e-10)
    # Φ itself is rounding noise here (|Φ| ~ 1e-12 for lengths of 10 m): agree to that level
    np.testing.assert_allclose(fast["constraint_error"], python["constraint_error"], rtol=1e-6, atol=1e-12)


def test_compiled_loop_stops_at_a_singular_position_with_the_python_message():
    model = cmbs.load("slider-crank")
    run = simulate(model, t_end=2.0, integrator="rk4", dt=1e-3, formulation="lagrange", compiled=True)
    assert run.info["status"] == "failed" and run.t[-1] < 2.0
    assert "singular configuration" in run.info["message"] and "dependent:" in run.info["message"]


def test_compiled_loop_refuses_what_it_cannot_run():
    model = cmbs.load("pendulum")
    with pytest.raises(CmbsError, match="compiled loop cannot run"):
        simulate(model, t_end=0.1, integrator="rk45", compiled=True)
    with pytest.raises(CmbsError, match="compiled loop cannot run"):
        simulate(model, t_end=0.1, integrator="rk4", formulation="penalty", compiled=True)


def test_jacobi_extreme_eigenvalues_match_lapack():
    """The rank check's small symmetric eigenvalue routine against numpy (LAPACK), including
    nearly rank-deficient Gram matrices."""
    from cmbs.fast import _gram_extremes

    rng = np.random.default_rng(0)
    for m in range(1, 13):
        for _ in range(20):
            A = rng.normal(size=(m, m + 2)) * rng.uniform(0.01, 10.0, size=(m, 1))
            if m > 1 and rng.random() < 0.5:
                A[-1] = 2.0 * A[0] + 1e-9 * rng.normal(size=m + 2)
            G = A @ A.T
            expected = np.linalg.eigvalsh(G)
            low, high = _gram_extremes(G.copy())
            assert abs(low - expected[0]) <= 1e-13 * expected[-1]
            assert abs(high - expected[-1]) <= 1e-13 * expected[-1]
