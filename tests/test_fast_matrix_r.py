"""Matrix R in the compiled loops (its stage and after-step hooks in the RK4 loop of
cmbs.integrate.compiled_rk4 and the adaptive loop of cmbs.integrate.compiled_adaptive, the
after-step hook choosing new partitions in place) against the Python loop, another formulation and
conservation."""

import numpy as np
import pytest

import cmbs
from cmbs.dynamics.field import CompiledDynamics
from cmbs.dynamics.matrix_r import ROUNDING_CONDITION, MatrixR
from cmbs.errors import CmbsError
from cmbs.library.mechanisms import slider_crank_branch
from cmbs.simulate import simulate


def _both(model, t_end, dt, formulation="matrix-r"):
    runs = [simulate(model, t_end=t_end, integrator="rk4", dt=dt, formulation=formulation, compiled=flag)
            for flag in (None, False)]
    assert runs[0].info["compiled"] and "compiled" not in runs[1].info
    return runs


def test_compiled_matrix_r_equals_the_python_loop_through_repartitions():
    """The undriven four-bar re-partitions three times in 2 s (condition_growth 1.25): same steps,
    same states."""
    compiled, python = _both(cmbs.load("four-bar").without_drivers(), 2.0, 1e-3)
    assert compiled.info["repartitions"] == 3
    np.testing.assert_allclose(compiled.q, python.q, rtol=0, atol=1e-11)
    np.testing.assert_allclose(compiled.qd, python.qd, rtol=0, atol=1e-10)
    np.testing.assert_allclose(compiled.qdd, python.qdd, rtol=0, atol=1e-8)
    np.testing.assert_allclose(compiled["lam"], python["lam"], rtol=0, atol=1e-8 * np.abs(python["lam"]).max())
    np.testing.assert_allclose(compiled["constraint_force"], python["constraint_force"], rtol=0,
                               atol=1e-8 * np.abs(python["constraint_force"]).max())
    np.testing.assert_allclose(compiled["energy"], python["energy"], rtol=0, atol=1e-9)


def test_compiled_matrix_r_equals_the_python_loop_with_several_independent_coordinates():
    """The 8-link closed chain (six independent coordinates, so Rᵀ M R is 6 × 6 and the sparse M
    multiplies a full R): both loops agree over 0.5 s."""
    compiled, python = _both(cmbs.load("chain", links=8, closed=True), 0.5, 1e-3)
    assert compiled.info["status"] == python.info["status"] == "success"
    np.testing.assert_allclose(compiled.q, python.q, rtol=0, atol=1e-11)
    np.testing.assert_allclose(compiled.qd, python.qd, rtol=0, atol=1e-10)
    np.testing.assert_allclose(compiled.qdd, python.qdd, rtol=0, atol=1e-8)
    np.testing.assert_allclose(compiled["lam"], python["lam"], rtol=0, atol=1e-8 * np.abs(python["lam"]).max())


@pytest.mark.parametrize("name", ["slider-crank", "slider-crank-joint"])
def test_compiled_matrix_r_equals_the_python_loop_before_the_singular_position(name):
    """Up to the first pass of θ1 = 90° (t = 0.46 s) both loops agree to rounding; at the pass
    itself the recovery of the dependent coordinates is ill-conditioned (A_d → 0 for the joint
    model), and rounding differences of 1e-16 are amplified there."""
    compiled, python = _both(cmbs.load(name), 0.44, 1e-3)
    np.testing.assert_allclose(compiled.q, python.q, rtol=0, atol=1e-11)
    np.testing.assert_allclose(compiled.qd, python.qd, rtol=0, atol=1e-10)
    np.testing.assert_allclose(compiled["lam"], python["lam"], rtol=0, atol=1e-8 * np.abs(python["lam"]).max())


def test_compiled_matrix_r_crosses_the_singular_positions_on_the_branch():
    """10 s of the equal-link slider-crank: seven passes of θ1 = ±90°, energy conserved to 1e-7
    relative, the assembly branch θ2 = -2θ1 kept (the other branch has C fixed at the origin)."""
    model = cmbs.load("slider-crank")
    run = simulate(model, t_end=10.0, integrator="rk4", dt=2e-3, formulation="matrix-r")
    assert run.info["status"] == "success" and run.info["compiled"] and run.info["repartitions"] >= 6
    theta1, theta2 = run["theta1"], run["theta2"]
    assert np.count_nonzero(np.diff(np.sign(np.cos(theta1)))) >= 6
    energy = run["energy"]
    assert np.abs(energy - energy[0]).max() / abs(energy[0]) < 1e-7
    branch = np.mod(theta2 + 2.0 * theta1 + np.pi, 2.0 * np.pi) - np.pi
    assert np.abs(branch).max() < 1e-9
    assert run["constraint_error"].max() < 1e-11


def test_compiled_matrix_r_converges_at_fourth_order():
    """Crank angle at t = 1 s (after one singular pass) for h, h/2 against h/8: ratio ≈ 16."""
    model = cmbs.load("slider-crank")
    final = [simulate(model, t_end=1.0, integrator="rk4", dt=dt, formulation="matrix-r")["theta1"][-1]
             for dt in (0.02, 0.01, 0.0025)]
    ratio = abs(final[0] - final[2]) / abs(final[1] - final[2])
    assert 12.0 < ratio < 20.0


def test_compiled_and_python_loops_report_the_same_worst_stage_condition():
    """Both loops keep the largest cond₁(A_d) met at a stage (numpy.linalg.cond(A_d, 1) on the
    Python path, the LU factors in the compiled loop): the slider-crank nears 90° at 0.83 s."""
    model = cmbs.load("slider-crank", gravity=9.81)
    compiled, python = _both(model, 0.9, 1e-3)
    assert compiled.info["max_condition"] == pytest.approx(python.info["max_condition"], rel=1e-6)
    assert compiled.info["max_condition_t"] == python.info["max_condition_t"] == pytest.approx(0.828)
    assert 1e3 < compiled.info["max_condition"] < ROUNDING_CONDITION


@pytest.mark.parametrize("compiled", [None, False])
def test_velocities_kept_near_the_singular_position_keep_the_digits(compiled):
    """At h = 0.5 ms a stage falls 3.6e-6 rad from the crossing (cond₁(A_d) = 1.1e6, reported
    with a warning).  Recovering its velocities from A there amplifies the positions' rounding:
    with the integrated velocities kept only beyond a 1e12-fold growth of cond₁(A_d) (so never),
    the run ends more than 1e-8 rad from the branch ODE (slider_crank_branch; measured 1.9e-6
    compiled, 1.8e-6 Python); keeping them beyond the default 100-fold growth, within 1e-9
    (measured 1.0e-10, 3.3e-11), as RK4 at 1 ms without any kept (5.2e-12)."""
    model = cmbs.load("slider-crank", gravity=9.81)
    reference = slider_crank_branch(np.array([1.0]), gravity=9.81)[0][0]

    def error(dt, formulation):
        run = simulate(model, t_end=1.0, integrator="rk4", dt=dt, formulation=formulation, compiled=compiled)
        return run, abs(run["theta1"][-1] - reference)

    coarse, coarse_error = error(1e-3, "matrix-r")
    kept, kept_error = error(5e-4, "matrix-r")
    recovered, recovered_error = error(5e-4, MatrixR(velocity_recovery_growth=1e12))
    assert coarse.info["max_condition"] < ROUNDING_CONDITION < kept.info["max_condition"] / 10
    assert "‖A_r‖‖A_d⁻¹‖ = 1.1e+06 (t = 0.82775" in kept.info["note"]
    assert coarse_error < 1e-10 and kept_error < 1e-9 and recovered_error > max(1e-8, 10 * kept_error)


def test_compiled_matrix_r_refuses_nonholonomic_models():
    sleigh = cmbs.load("chaplygin-sleigh")
    with pytest.raises(CmbsError, match="compiled loop cannot run"):
        simulate(sleigh, t_end=0.1, integrator="rk4", dt=1e-3, formulation="matrix-r", compiled=True)
    run = simulate(sleigh, t_end=0.1, integrator="rk4", dt=1e-3, formulation="matrix-r")
    assert "compiled" not in run.info and run.info["status"] == "success"


def test_condition_bound_brackets_the_two_norm_partition_condition():
    """The step-end test's filter: κ₂ ≤ sqrt(κ₁ κ_∞) ≤ (r n)^¼ √r κ₂ (κ_p = ‖A_r‖_p ‖A_d⁻¹‖_p;
    ‖B‖₁ ≤ √rows ‖B‖₂ and ‖B‖∞ ≤ √columns ‖B‖₂), on random and nearly singular partitions (the
    bound comes from the LU factors of A_d, the reference from numpy's norms and inverse)."""
    from cmbs.dynamics.matrix_r_kernels import condition_two_bound, factor_dependent

    generator = np.random.default_rng(7)
    n, m = 7, 5
    for scale in (1.0, 1e-4, 1e-9):
        A = generator.normal(size=(m, n))
        A[3] = A[1] + scale * generator.normal(size=n)         # rows 1 and 3 nearly dependent
        rows, dependent = np.array([0, 1, 3, 4]), np.array([0, 2, 5, 6])
        r = rows.size
        Ad, pivots, side = np.empty((r, r)), np.empty(r, dtype=np.int64), np.empty(r)
        assert factor_dependent(A, rows, dependent, Ad, pivots)
        bound = condition_two_bound(A, rows, Ad, pivots, side)
        A_r, inverse = A[rows], np.linalg.inv(A[np.ix_(rows, dependent)])
        exact = np.linalg.svd(A_r, compute_uv=False)[0] / np.linalg.svd(A[np.ix_(rows, dependent)],
                                                                         compute_uv=False)[-1]
        assert exact * (1 - 1e-9) <= bound <= (r * n) ** 0.25 * np.sqrt(r) * exact * (1 + 1e-9)
        expected = np.sqrt(np.linalg.norm(A_r, 1) * np.linalg.norm(inverse, 1) * np.linalg.norm(A_r, np.inf)
                           * np.linalg.norm(inverse, np.inf))
        assert bound == pytest.approx(expected, rel=1e-6)


def _adaptive_both(model, integrator, t_end, formulation="matrix-r"):
    options = dict(t_end=t_end, integrator=integrator, rtol=1e-8, atol=1e-8, dt=0.01, formulation=formulation)
    runs = [simulate(model, compiled=flag, **options) for flag in (None, False)]
    assert runs[0].info["compiled"] and "compiled" not in runs[1].info
    return runs


def _assert_same_adaptive_run(compiled, python, same_lam=True):
    """Same accepted and rejected steps and evaluations, same outputs to rounding (λ unless not
    ``same_lam``), same worst stage condition."""
    assert compiled.info["status"] == python.info["status"] == "success"
    for counter in ("steps", "rejected", "evaluations"):
        assert compiled.info[counter] == python.info[counter], counter
    np.testing.assert_allclose(compiled.t, python.t, rtol=0, atol=1e-15)
    np.testing.assert_allclose(compiled.q, python.q, rtol=0, atol=1e-11)
    np.testing.assert_allclose(compiled.qd, python.qd, rtol=0, atol=1e-10)
    np.testing.assert_allclose(compiled.qdd, python.qdd, rtol=0, atol=1e-8 * max(1.0, np.abs(python.qdd).max()))
    if same_lam:
        np.testing.assert_allclose(compiled["lam"], python["lam"], rtol=0, atol=1e-8 * np.abs(python["lam"]).max())
    np.testing.assert_allclose(compiled["energy"], python["energy"], rtol=0, atol=1e-9)
    assert compiled.info["max_condition"] == pytest.approx(python.info["max_condition"], rel=1e-6)


@pytest.mark.parametrize("integrator", ["rk45", "rk23", "dop853"])
def test_compiled_adaptive_matrix_r_takes_the_python_loops_steps_through_repartitions(integrator):
    """The undriven four-bar re-partitions three times in 2 s: each time the compiled loop's
    after-step hook chooses the partition at the recovered state and recovers it again, as the
    Python loop's after_step does: the same steps, rejections and evaluations."""
    compiled, python = _adaptive_both(cmbs.load("four-bar").without_drivers(), integrator, 2.0)
    assert compiled.info["repartitions"] == 3
    _assert_same_adaptive_run(compiled, python)


@pytest.mark.parametrize("name, t_end", [("pendulum", 5.0), ("slider-crank", 0.4), ("slider-crank-joint", 0.4),
                                         ("chain", 0.5)])
def test_compiled_adaptive_matrix_r_equals_the_python_loop(name, t_end):
    """The pendulum swinging under its pivot (a new partition at each pass), the slider-crank in
    natural and joint coordinates up to its singular position, the closed 8-link chain (six
    independent coordinates).

    The pendulum's λ at the outputs is checked against Lagrange's at the same states instead:
    the Python loop evaluates every output after the run, with the last partition, which at the
    outputs under the pivot (x ≈ 0) is the one with x dependent (measured 1.1e-6 off there,
    the compiled loop's 5e-15)."""
    model = cmbs.load(name, links=8, closed=True) if name == "chain" else cmbs.load(name)
    compiled, python = _adaptive_both(model, "rk45", t_end)
    _assert_same_adaptive_run(compiled, python, same_lam=name != "pendulum")
    if name == "pendulum":
        assert compiled.info["repartitions"] >= 5 and np.count_nonzero(np.diff(np.sign(compiled["P.x"]))) >= 5
        lagrange = CompiledDynamics(model, "lagrange")
        expected = np.array([lagrange.accelerations(q, qd, t)[1] for t, q, qd in zip(compiled.t, compiled.q,
                                                                                     compiled.qd)])
        np.testing.assert_allclose(compiled["lam"], expected, rtol=0, atol=1e-10 * np.abs(expected).max())


@pytest.mark.parametrize("name, t_end", [("four-bar", 2.0), ("free four-bar", 2.0), ("slider-crank", 0.4),
                                         ("slider-crank-joint", 0.4)])
def test_compiled_adaptive_matrix_r_agrees_with_lagrange(name, t_end):
    """rk45 at rtol 1e-10: matrix R (re-partitioning on the free four-bar and the slider-crank)
    and Lagrange, both compiled, describe the same motion (measured: q within 2.2e-8, λ within
    3.3e-8 of its largest)."""
    model = cmbs.load("four-bar").without_drivers() if name == "free four-bar" else cmbs.load(name)
    runs = [simulate(model, t_end=t_end, formulation=formulation, rtol=1e-10, atol=1e-12)
            for formulation in ("matrix-r", "lagrange")]
    velocity, lagrange = runs
    assert velocity.info["compiled"] and lagrange.info["compiled"]
    assert velocity.info["status"] == lagrange.info["status"] == "success"
    np.testing.assert_allclose(velocity.t, lagrange.t, rtol=0, atol=1e-15)
    np.testing.assert_allclose(velocity.q, lagrange.q, rtol=0, atol=1e-7)
    np.testing.assert_allclose(velocity.qd, lagrange.qd, rtol=0, atol=1e-6)
    np.testing.assert_allclose(velocity["lam"], lagrange["lam"], rtol=0, atol=1e-6 * np.abs(lagrange["lam"]).max())


def test_compiled_adaptive_matrix_r_crosses_the_singular_positions_on_the_branch():
    """rk45 over 10 s of the equal-link slider-crank: seven passes of θ1 = ±90°, each with new
    partitions (measured: 12), energy conserved to 1e-6 relative (measured 5.4e-8), the
    assembly branch θ2 = -2θ1 kept (measured 3.8e-13)."""
    run = simulate(cmbs.load("slider-crank"), t_end=10.0, formulation="matrix-r", rtol=1e-10, atol=1e-12)
    assert run.info["status"] == "success" and run.info["compiled"] and run.info["repartitions"] >= 6
    assert np.count_nonzero(np.diff(np.sign(np.cos(run["theta1"])))) >= 6
    energy = run["energy"]
    assert np.abs(energy - energy[0]).max() / abs(energy[0]) < 1e-6
    branch = np.mod(run["theta2"] + 2.0 * run["theta1"] + np.pi, 2.0 * np.pi) - np.pi
    assert np.abs(branch).max() < 1e-9


@pytest.mark.parametrize("integrator, options", [("rk4", dict(dt=1e-3)), ("rk45", dict(dt=0.01))])
def test_compiled_matrix_r_stops_where_the_python_loop_stops_when_a_recovery_fails(integrator, options):
    """One Newton iteration cannot recover the first stage off the constraints: both loops stop
    there, at the same time and with the same message (Python's adds the residual)."""
    model = cmbs.load("four-bar").without_drivers()
    runs = [simulate(model, t_end=0.5, integrator=integrator, formulation=MatrixR(max_iterations=1),
                     compiled=flag, **options) for flag in (None, False)]
    compiled, python = runs
    assert compiled.info["compiled"] and "compiled" not in python.info
    assert compiled.info["status"] == python.info["status"] == "failed"
    assert "matrix-r position recovery did not converge in 1 iterations" in compiled.info["message"]
    assert python.info["message"].startswith(compiled.info["message"])
    np.testing.assert_array_equal(compiled.t, python.t)


def test_compiled_dynamics_takes_matrix_r_as_its_python_solver_does():
    """One compiled evaluation of matrix R at a state (no recovery), as
    MatrixRSolver.accelerations: the free four-bar at a state off its start, on the constraints."""
    model = cmbs.load("four-bar").without_drivers()
    q = cmbs.assemble(model, model.q0 + 0.05 * np.arange(model.n), fixed=["alpha"])
    start = np.zeros(model.n)
    start[model.coordinate_index("alpha")] = 1.5
    qd = cmbs.velocities(model, q, qd=start, fixed=["alpha"])
    compiled = CompiledDynamics(model, "matrix-r")
    qdd, lam = compiled.accelerations(q, qd, 0.3)
    expected = MatrixR().bind(model).accelerations(model.evaluate(q, qd, 0.3), q, qd, 0.3)
    np.testing.assert_allclose(qdd, expected.qdd, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(lam, expected.lam, rtol=1e-12, atol=1e-12)
