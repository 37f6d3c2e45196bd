"""Andrews' squeezing mechanism (Hairer & Wanner's seven-body benchmark) against the Test Set for
IVP Solvers' reference solution, and the penalty formulation on it: grams of mass, a stiff
spring and a crank reaching 1100 rad/s in 0.03 s."""

import numpy as np
import pytest

import cmbs
from cmbs.dynamics import formulation
from cmbs.library.andrews import REFERENCE_AT_0_03
from cmbs.simulate import simulate


@pytest.fixture(scope="module")
def andrews():
    return cmbs.load("andrews")


def exact_accelerations(model, q, qd):
    """q̈ of the index-1 system [M Aᵀ; A 0] [q̈; λ] = [Q; γ], solved directly."""
    terms = model.evaluate(q, qd, 0.0)
    n, m = model.n, model.m
    matrix = np.block([[terms.M, terms.A.T], [terms.A, np.zeros((m, m))]])
    return np.linalg.solve(matrix, np.concatenate([terms.Q, terms.gamma]))[:n]


@pytest.fixture(scope="module")
def lagrange_run(andrews):
    return simulate(andrews, t_end=0.03, dt=0.001, formulation="lagrange", rtol=1e-9, atol=1e-12)


def test_lagrange_matches_the_test_set_reference(andrews):
    """Angles and angular velocities at t = 0.03 s (PSIDE at 1e-14) to 1e-8 rad and 1e-7 of the
    crank's 1140 rad/s."""
    run = simulate(andrews, t_end=0.03, dt=0.03, formulation="lagrange", integrator="dop853", rtol=1e-12, atol=1e-14)
    assert run.info["status"] == "success"
    np.testing.assert_allclose(run.q[-1], REFERENCE_AT_0_03[:7], atol=1e-8)
    np.testing.assert_allclose(run.qd[-1], REFERENCE_AT_0_03[7:], atol=1e-7 * 1140)
    assert run.info["energy_drift"] < 1e-8          # T + V with V = ½c0(l - l0)² - mom·β


def test_penalty_defaults_match_lagrange_on_a_fast_stiff_mechanism(andrews, lagrange_run):
    """The default penalty (scaled α, augmented Lagrangian) within 1e-6 rad of Lagrange at the
    same tolerance; α = 1e7 used to cost cond(M + αAᵀA) ≈ 4e10 and six digits of q̈."""
    run = simulate(andrews, t_end=0.03, dt=0.001, formulation="penalty", rtol=1e-9, atol=1e-12)
    assert run.info["status"] == "success"          # and nothing noted but the loop it took
    assert run.info["note"] == "Python loop: model 'andrews' has Python-callable terms or time functions"
    assert np.abs(run.q - lagrange_run.q).max() < 1e-6
    assert np.abs(run.q[-1] - REFERENCE_AT_0_03[:7]).max() < 1e-6


def test_augmented_lagrangian_stops_at_an_attainable_residual(andrews):
    """At the reference state (crank at 1140 rad/s) with α = 1e7, the iteration used to stall at a
    relative change of q̈ of cond · ε and report non-convergence; its residual test converges,
    and q̈ equals the index-1 solution to what that conditioning leaves (1e-5)."""
    q, qd = REFERENCE_AT_0_03[:7], REFERENCE_AT_0_03[7:]
    exact = exact_accelerations(andrews, q, qd)
    terms = andrews.evaluate(q, qd, 0.0)
    for options, tolerance in (({"alpha": 1e7, "iterations": 10}, 1e-5), ({}, 1e-8)):
        solver = formulation("penalty", Omega=0.0, **options).bind(andrews)
        qdd = solver.accelerations(terms, q, qd, 0.0).qdd
        assert np.abs(qdd - exact).max() <= tolerance * np.abs(exact).max(), options


def test_a_soft_penalty_run_says_so(andrews, lagrange_run):
    """The plain penalty with the scaled α misses the constraint accelerations by 5e-4 (relative)
    and the motion by 1e-2 rad: the run's note says so."""
    run = simulate(andrews, t_end=0.03, dt=0.001, formulation="penalty", formulation_options={"iterations": 0},
                   rtol=1e-9, atol=1e-12)
    assert np.abs(run.q - lagrange_run.q).max() > 1e-3
    assert "penalty: the constraint accelerations missed the exact ones by up to" in run.info["note"]


def test_a_diverged_run_says_so(andrews):
    """RK4 at the default 10 ms step explodes on this mechanism (angles of 1e53 rad at 0.03 s): the
    run is failed, saying the motion diverged (the branch watch sees |q̇| grow 1e9 times in the
    step after 0.01 s and keeps the outputs before it)."""
    run = simulate(andrews, t_end=0.03, integrator="rk4")
    assert run.info["status"] == "failed" and "the motion diverged" in run.info["message"]
    assert np.all(np.isfinite(run.q)) and run.t[-1] < 0.03


def test_its_coordinates_are_angles(andrews):
    """from_sympy's coordinate_kinds: the angles read in rad and their forces in N m; a kind it
    does not know, or a count that does not match, is refused."""
    import sympy

    from cmbs.errors import ModelError
    from cmbs.model.equations import from_sympy
    from cmbs.units import coordinate_unit, force_unit

    assert andrews.coordinate_kinds == ("angle",) * 7
    assert coordinate_unit(andrews, "beta") == "rad" and force_unit(andrews, "beta") == "N m"
    x = sympy.Symbol("x")
    for kinds in (["meters"], ["x", "z"]):
        with pytest.raises(ModelError, match="coordinate_kinds must give one of"):
            from_sympy("bad", coordinates=[x], mass_matrix=sympy.Matrix([[1]]), forces=[0], coordinate_kinds=kinds)
