"""Matrix R's partition chosen in compiled code (cmbs.dynamics.matrix_r_kernels.choose_partition,
update_partition), inside the compiled loops' after-step hook: against scipy's pivoted QR and LU
(the reference written here), through re-partitions with drift projection and in the batched
sweep, and a user's partition that becomes singular during a compiled run."""

import math

import numpy as np
import pytest
import scipy.linalg

import cmbs
from cmbs.dynamics.field import CompiledDynamics
from cmbs.dynamics.matrix_r import MatrixR, choose_partition
from cmbs.dynamics.matrix_r_kernels import SINGULAR_PARTITION, pivot_columns, pivot_rows, row_scaled, update_partition
from cmbs.errors import SingularSystemError
from cmbs.simulate import simulate
from cmbs.sweep import Variant, sweep


#: Relative margin within which two pivot candidates count as tied (equal in exact arithmetic,
#: ordered by rounding): there either choice follows the rule.
TIE = 1e-9


def lapack_pivots(A: np.ndarray, rank_tolerance: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """The pivots, in the order chosen, of the partition by LAPACK: the rank of the row-scaled A
    by its singular values, rows by QR with column pivoting of its transpose (dgeqp3), dependent
    coordinates by LU with partial pivoting of those rows' (sorted) transpose (dgetrf).

    Every column of the row-scaled Aᵀ has norm 1, a tie that rounding breaks at random: the
    first row is made the first pivot (its column doubled, which changes no later step: the
    others' residuals are orthogonal to it)."""
    norms = np.linalg.norm(A, axis=1)
    scaled = A / np.where(norms > 0, norms, 1.0)[:, None]
    sigma = np.linalg.svd(scaled, compute_uv=False)
    rank = int(np.sum(sigma > rank_tolerance * max(sigma[0], 1.0)))
    first_wins = scaled.T.copy()
    first_wins[:, 0] *= 2.0
    _, _, row_pivots = scipy.linalg.qr(first_wins, pivoting=True, mode="economic")
    rows = np.sort(row_pivots[:rank])
    permutation, _, _ = scipy.linalg.lu(A[rows].T)
    return row_pivots[:rank], np.argmax(permutation, axis=0)[:rank]


def compiled_pivots(A: np.ndarray, rank: int) -> tuple[np.ndarray, np.ndarray]:
    """The pivots, in the order chosen, of the compiled choice's two steps."""
    rows, dependent = np.empty(rank, dtype=np.int64), np.empty(rank, dtype=np.int64)
    pivot_columns(row_scaled(A).T.copy(), rank, rows)
    pivot_rows(np.ascontiguousarray(A[np.sort(rows)].T), rank, dependent)
    return rows, dependent


def qr_pivot_ratios(B: np.ndarray, order: np.ndarray) -> list[tuple[float, float]]:
    """QR with column pivoting of B replayed in the pivot ``order`` (numpy's QR of the columns
    chosen before): at each step the pivot's residual norm and the runner-up's, each over the
    largest residual norm among the candidates."""
    ratios = []
    for k, pivot in enumerate(order):
        basis = np.linalg.qr(B[:, order[:k]])[0] if k else np.zeros((B.shape[0], 0))
        residual = np.linalg.norm(B - basis @ (basis.T @ B), axis=0)
        candidates = np.delete(residual, order[:k])
        largest = np.sort(candidates)[::-1]
        ratios.append((residual[pivot] / largest[0], largest[1] / largest[0] if largest.size > 1 else 0.0))
    return ratios


def lu_pivot_ratios(C: np.ndarray, order: np.ndarray) -> list[tuple[float, float]]:
    """Gaussian elimination of C replayed with the pivot rows ``order``: at each step the
    pivot's |value| and the runner-up's, each over the largest |value| among the candidates."""
    C = C.copy()
    remaining = list(range(C.shape[0]))
    ratios = []
    for k, pivot in enumerate(order):
        values = np.abs(C[remaining, k])
        largest = np.sort(values)[::-1]
        ratios.append((abs(C[pivot, k]) / largest[0], largest[1] / largest[0] if largest.size > 1 else 0.0))
        remaining.remove(pivot)
        C[remaining] -= np.outer(C[remaining, k] / C[pivot, k], C[pivot])
    return ratios


def _assert_same_choice(A: np.ndarray) -> None:
    """The compiled choice follows the pivoting rules at every step (its pivot the largest
    candidate, up to a tie) and is LAPACK's up to LAPACK's first tie after the first step; and
    :func:`choose_partition` returns it, sorted, with the other coordinates independent.
    Returns the number of steps compared with LAPACK."""
    lapack_rows, lapack_dependent = lapack_pivots(A)
    rows, dependent = compiled_pivots(A, lapack_rows.size)
    norms = np.linalg.norm(A, axis=1)
    scaled_transpose = (A / np.where(norms > 0, norms, 1.0)[:, None]).T
    rules = ((qr_pivot_ratios, scaled_transpose, rows, lapack_rows),
             (lu_pivot_ratios, A[np.sort(rows)].T, dependent, lapack_dependent))
    compared = 0
    for replay, matrix, compiled, lapack in rules:
        assert all(ratio > 1.0 - TIE for ratio, _ in replay(matrix, compiled))
        if not np.array_equal(np.sort(rows), np.sort(lapack_rows)):
            break                           # after a tie among the rows: other dependent coordinates
        for k, (_, runner_up) in enumerate(replay(matrix, lapack)):
            if runner_up > 1.0 - TIE and not (replay is qr_pivot_ratios and k == 0):
                break                       # a tie: either candidate follows the rule
            assert compiled[k] == lapack[k]
            compared += 1
    chosen = choose_partition(A, 1e-9)
    np.testing.assert_array_equal(chosen.rows, np.sort(rows))
    np.testing.assert_array_equal(chosen.dependent, np.sort(dependent))
    np.testing.assert_array_equal(np.union1d(chosen.dependent, chosen.independent), np.arange(A.shape[1]))
    return compared


@pytest.mark.parametrize("m, n, rank", [(1, 2, 1), (3, 5, 3), (5, 7, 5), (6, 9, 4), (8, 8, 8), (7, 12, 5)])
def test_compiled_choice_is_lapacks_on_random_matrices(m, n, rank):
    """Random A of the given rank (redundant rows as combinations of the others), several draws:
    the same rows and dependent coordinates as scipy's pivoted QR and LU (but at the first
    step, where every row-scaled column ties)."""
    generator = np.random.default_rng(m * 100 + n)
    for _ in range(20):
        A = generator.normal(size=(rank, n))
        if m > rank:
            A = np.vstack([A, generator.normal(size=(m - rank, rank)) @ A])
        A = A[generator.permutation(m)] * generator.uniform(0.1, 10.0, size=(m, 1))
        assert _assert_same_choice(A) == 2 * rank          # no tie: every pivot compared


def _parallelogram(model: cmbs.Model, N: int, theta: float) -> np.ndarray:
    """q of the N-four-bar with every crank at angle θ (B_i = (i + cos θ, sin θ), L = 1 m)."""
    values = {}
    for i in range(N + 1):
        values[f"B{i}.x"], values[f"B{i}.z"] = i + math.cos(theta), math.sin(theta)
    return np.array([values[name] for name in model.coordinate_names])


def _jacobians():
    """(label, A) of library mechanisms at their start and along their motion (the
    N-four-bar with N = 2 approaching its singular passage at θ = 0)."""
    for name in ("four-bar", "slider-crank", "slider-crank-joint", "pendulum", "double-pendulum"):
        model = cmbs.load(name)
        yield name, model.jacobian(model.q0, 0.0)
    free = cmbs.load("four-bar").without_drivers()
    run = simulate(free, t_end=2.0, integrator="rk4", dt=1e-2, formulation="lagrange")
    for k in range(0, run.t.size, 20):
        yield f"free four-bar t={run.t[k]:.1f}", free.jacobian(run.q[k], run.t[k])
    crank = cmbs.load("slider-crank")
    run = simulate(crank, t_end=1.0, integrator="rk4", dt=1e-2, formulation="matrix-r")
    for k in range(0, run.t.size, 10):
        yield f"slider-crank t={run.t[k]:.1f}", crank.jacobian(run.q[k], run.t[k])
    chain = cmbs.load("chain", links=8, closed=True)
    yield "closed chain", chain.jacobian(chain.q0, 0.0)
    n_four_bar = cmbs.load("n-four-bar", N=2)
    for theta in (1.0, 0.1, 1e-3, 1e-6):
        yield f"n-four-bar θ={theta:g}", n_four_bar.jacobian(_parallelogram(n_four_bar, 2, theta), 0.0)


def test_compiled_choice_is_lapacks_on_mechanism_jacobians():
    """Jacobians of library mechanisms (exact ties between equal entries among them): LAPACK's
    rows and dependent coordinates, or at a tie another choice the rules allow."""
    compared = total = 0
    for label, A in _jacobians():
        try:
            compared += _assert_same_choice(np.asarray(A, dtype=float))
        except AssertionError as error:
            raise AssertionError(label) from error
        total += 2 * np.linalg.matrix_rank(A)
    assert compared > total / 2


def test_user_partition_at_a_singular_block_fails_in_the_compiled_update():
    """The pendulum (x, z) with z independent: A_d = [2x] is singular under the pivot; the
    compiled update reports it (κ₂ = L/|x| in the message), and the solver raises with the names."""
    solver = MatrixR(independent=("P.z",)).bind(cmbs.load("pendulum"))
    A = np.array([[2e-14, -2.0]])
    assert update_partition(A, solver.kernel()) == SINGULAR_PARTITION
    assert "1e+14" in solver.loop_failure(SINGULAR_PARTITION, 1.5)
    with pytest.raises(SingularSystemError, match=r"at t=1.5: the dependent block A_d is singular \(condition "
                                                  r"‖A_r‖‖A_d⁻¹‖ 1e\+14\) with independent coordinates P.z"):
        solver.update_partition(A, 1.5)


def _a02_jacobian(model: cmbs.Model, theta: float) -> np.ndarray:
    """A of A02 (N = 2) on its parallelogram branch with every crank at angle θ:
    B_i = (i + cos θ, sin θ), placed by coordinate name."""
    values = {}
    for i in range(3):
        values[f"B{i}.x"], values[f"B{i}.z"] = i + math.cos(theta), math.sin(theta)
    q = np.array([values[name] for name in model.coordinate_names])
    return np.ascontiguousarray(model.jacobian(q, 0.0))


def _kappa_two(A: np.ndarray, rows: np.ndarray, dependent: np.ndarray) -> float:
    """‖A_r‖₂ / σ_min(A_d) by numpy's SVDs."""
    block = A[np.ix_(rows, dependent)]
    return np.linalg.svd(A[rows], compute_uv=False)[0] / np.linalg.svd(block, compute_uv=False)[-1]


def test_a_partition_chosen_at_a_passage_is_chosen_again_when_its_condition_grows_from_its_smallest_value():
    """A02's cranks turning from 1e-3 rad off horizontal (a passage, where every partition's κ₂
    is about 1/δ) to hanging vertical: the partition chosen at the passage is kept while its κ₂
    (numpy's SVDs) falls, and chosen again at the first configuration where κ₂ exceeds
    ``condition_growth`` (1.25) times the smallest value it had since it was chosen; each new one
    likewise.  The update used to compare with κ₂ when the partition was chosen (4.7e3 here) and
    kept the passage's partition to the vertical, where its block A_d turns singular (a crank's z
    independent) and matrix R's recovery stopped converging (RK4 at 1 ms, t = 0.97 s)."""
    model = cmbs.load("n-four-bar", N=2)
    solver = MatrixR().bind(model)
    kernel = solver.kernel()
    solver.repartition(_a02_jacobian(model, -1e-3))
    smallest = _kappa_two(_a02_jacobian(model, -1e-3), kernel.rows, kernel.dependent)
    assert smallest > 1e3
    chosen_again = []
    for theta in np.linspace(-2e-3, -math.pi / 2, 800):
        A = _a02_jacobian(model, theta)
        kappa = _kappa_two(A, kernel.rows, kernel.dependent)
        before = solver.repartitions
        solver.update_partition(A, 0.0)
        if solver.repartitions > before:
            assert kappa > 1.25 * smallest * (1 - TIE), theta
            chosen_again.append(theta)
            smallest = _kappa_two(A, kernel.rows, kernel.dependent)
        else:
            assert kappa <= 1.25 * smallest * (1 + TIE), theta
            smallest = min(smallest, kappa)
    assert chosen_again and chosen_again[0] > -1.4          # well before the vertical
    at_vertical = _a02_jacobian(model, -math.pi / 2)
    assert _kappa_two(at_vertical, kernel.rows, kernel.dependent) < 10


def test_an_automatic_partition_singular_where_it_was_chosen_does_not_suggest_choosing_automatically():
    """At A02's passage exactly (the cranks horizontal, A of rank N + 1 = 3 with 5 rows) the
    automatic partition chosen again is singular too: the message names the position and what
    to try, not the automatic choice it already made."""
    model = cmbs.load("n-four-bar", N=2)
    solver = MatrixR().bind(model)
    assert update_partition(_a02_jacobian(model, 0.0), solver.kernel()) == SINGULAR_PARTITION
    message = solver.loop_failure(SINGULAR_PARTITION, 0.714)
    assert "the dependent block A_d is singular" in message and "chosen automatically" in message
    assert "singular position" in message and "try another dt or rtol" in message
    assert "let matrix-r choose" not in message
    user = MatrixR(independent=("B1.x",)).bind(model)
    assert update_partition(_a02_jacobian(model, 0.0), user.kernel()) == SINGULAR_PARTITION
    assert "let matrix-r choose them automatically" in user.loop_failure(SINGULAR_PARTITION, 0.714)


@pytest.mark.parametrize("integrator, options", [("rk4", dict(dt=1e-3)), ("rk45", dict(dt=0.01))])
def test_user_partition_becoming_singular_stops_the_compiled_run_as_the_python_loop(integrator, options):
    """The pendulum hanging 1e-11 m off the vertical with z independent swings through x = 0,
    where A_d = [2x] is singular (κ₂ = 1/|x| > 1e12): both loops stop at the same time with the
    same message."""
    model = cmbs.load("pendulum")
    q0 = np.array([1e-11, -math.sqrt(1.0 - 1e-22)])
    runs = [simulate(model, t_end=1.0, integrator=integrator, formulation=MatrixR(independent=("P.z",)), q0=q0,
                     qd0=np.zeros(2), compiled=flag, rtol=1e-8, atol=1e-12, **options) for flag in (None, False)]
    compiled, python = runs
    assert compiled.info["compiled"] and "compiled" not in python.info
    assert compiled.info["status"] == python.info["status"] == "failed"
    assert "the dependent block A_d is singular" in compiled.info["message"]
    assert "with independent coordinates P.z" in compiled.info["message"]
    assert compiled.info["message"] == python.info["message"]
    np.testing.assert_array_equal(compiled.t, python.t)


def _projected_both(model, integrator, t_end):
    options = dict(t_end=t_end, integrator=integrator, dt=1e-3 if integrator == "rk4" else 0.01, rtol=1e-8,
                   atol=1e-8, formulation="matrix-r", project=True, projection_tolerance=1e-11)
    return simulate(model, **options), simulate(model, compiled=False, **options)


@pytest.mark.parametrize("integrator", ["rk4", "rk45", "dop853"])
@pytest.mark.parametrize("name, t_end", [("free four-bar", 2.0), ("pendulum", 3.0), ("slider-crank", 0.4)])
def test_compiled_matrix_r_with_drift_projection_takes_the_python_loops_steps(name, t_end, integrator):
    """Matrix R with drift projection after each step (and at each adaptive output) in the
    compiled loops, through re-partitions (the free four-bar: 3 in 2 s, the pendulum passing
    under its pivot), as on the Python loop: the same steps and counters, the same states to
    rounding.  The pendulum's λ is checked against Lagrange's at the same states instead: the
    Python loop evaluates the outputs after the run, with the last partition, ill-conditioned
    at the outputs under the pivot (tests/test_fast_matrix_r.py)."""
    model = cmbs.load("four-bar").without_drivers() if name == "free four-bar" else cmbs.load(name)
    fast, python = _projected_both(model, integrator, t_end)
    assert fast.info["compiled"] and "compiled" not in python.info
    assert fast.info["status"] == python.info["status"] == "success"
    assert fast.info["repartitions"] == python.info["repartitions"]
    if name != "slider-crank":
        assert fast.info["repartitions"] >= 3
    counters = ("steps",) if integrator == "rk4" else ("steps", "rejected", "evaluations")
    for counter in counters:
        assert fast.info[counter] == python.info[counter], counter
    np.testing.assert_allclose(fast.t, python.t, rtol=0, atol=1e-15)
    np.testing.assert_allclose(fast.q, python.q, rtol=0, atol=1e-11)
    np.testing.assert_allclose(fast.qd, python.qd, rtol=0, atol=1e-10)
    if name == "pendulum":      # the Python loop's λ: after the run, with the last partition (as without projection)
        lagrange = CompiledDynamics(model, "lagrange")
        expected = np.array([lagrange.accelerations(q, qd, t)[1] for t, q, qd in zip(fast.t, fast.q, fast.qd)])
        np.testing.assert_allclose(fast["lam"], expected, rtol=0, atol=1e-10 * np.abs(expected).max())
    else:
        np.testing.assert_allclose(fast["lam"], python["lam"], rtol=0, atol=1e-8 * np.abs(python["lam"]).max())
    assert fast["constraint_error"][1:].max() < 1e-11


def test_batched_sweep_runs_matrix_r_through_repartitions_as_single_simulations():
    """The free four-bar released at several crank speeds, 2 s of matrix R (re-partitioning in
    each run) in one compiled batch: each variant's own partition, the numbers of its single
    simulation."""
    model = cmbs.load("four-bar").without_drivers()
    variants = []
    for k, speed in enumerate((-1.5, -0.5, 0.5, 1.5)):
        qd = cmbs.velocities(model, model.q0, qd=np.eye(model.n)[-1] * speed + 1e-3 * k)
        variants.append(Variant(qd0=qd))
    result = sweep(model, variants, t_end=2.0, dt=1e-3, every=10, formulation="matrix-r")
    assert result.info["mode"] == "batched" and set(result.status) == {"success"}
    repartitions = []
    for v, variant in enumerate(variants):
        run = simulate(model, t_end=2.0, dt=1e-3, integrator="rk4", formulation="matrix-r",
                       qd0=np.asarray(variant.qd0))
        repartitions.append(run.info["repartitions"])
        np.testing.assert_allclose(result.q[v], run.q[::10], rtol=0, atol=1e-12)
        np.testing.assert_allclose(result.qd[v], run.qd[::10], rtol=0, atol=1e-11)
    assert min(repartitions) >= 1 and len(set(repartitions)) > 1
