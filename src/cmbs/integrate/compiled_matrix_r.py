"""Compiled fixed-step RK4 of the matrix-R formulation (velocity transformation, THEORY §3.4).

The loop is that of :func:`cmbs.simulate` with ``integrator="rk4"``, ``formulation="matrix-r"``
on the Python path (:class:`cmbs.dynamics.matrix_r.MatrixRSolver`), step for step: every stage
evaluates the accelerations at the recovered state (dependent coordinates by Newton on Φ_r = 0
with z held, started from the integrated values; dependent velocities from
A_d ḋ = -A_z ż - Φ_t), with the independent accelerations of Rᵀ M R z̈ = Rᵀ(Q - M S)::

    R = [-A_d⁻¹ A_z ; I],   S = [A_d⁻¹ γ_r ; 0]   (rows in the partition's order),
    q̈ = R z̈ + S,           λ_r = -A_d⁻ᵀ (M q̈ - Q)_d,   λ = 0 on the rows not in the partition.

A state whose κ₁ = ‖A_r‖₁ ‖A_d⁻¹‖₁ (the partition's condition,
:func:`cmbs.dynamics.matrix_r.partition_condition`) exceeds :attr:`MatrixRSolver.recovery_limit`
(near a singular position) keeps its integrated velocities (positions recovered), as on the
Python path. Every stage also
keeps the largest κ₁ it met and its time (``worst``), for the warning of
:func:`cmbs.dynamics.matrix_r.rounding_note`. After every step the state is recovered and
κ₂ checked (by SVDs only where the bound sqrt(κ₁ κ_∞), from the LU factors the
recovery left, does not already rule a re-partition out). Choosing a new partition is Python's
(:meth:`MatrixRSolver.update_partition`: pivoted QR and LU, rare): when κ₂ has grown by
``condition_growth`` (automatic partition) or passed 1e12 (any partition), the loop returns
REPARTITION with the step reached, Python chooses again (or raises for a user partition) and the
loop resumes from there. Holonomic models with constant inputs only (a nonholonomic row makes some
positions non-recoverable; see :meth:`MatrixRSolver.stage_state`).
"""

from __future__ import annotations

from cmbs.jit import njit
import numpy as np

from cmbs.dynamics.matrix_r import MatrixR, MatrixRSolver
from cmbs.errors import CmbsError
from cmbs.dynamics.base import NON_FINITE, OK, SINGULAR
from cmbs.dynamics.kkt import lu_in_place, lu_solve, lu_solve_transposed, solve_in_place
from cmbs.integrate.compiled_rk4 import record_constraints
from cmbs.model.compiled import evaluate, model_kernel, terms_views
from cmbs.model.model import Model

#: status codes besides OK, SINGULAR and NON_FINITE
REPARTITION, NOT_CONVERGED, VELOCITIES_KEPT = 3, 4, 5
#: κ₂ above which every partition is handed back to Python (which raises for a user's)
SINGULAR_CONDITION = 1e12


def runs(model: Model, chosen: object, integrator: str, u: object, project: bool, steps_exact: bool) -> bool:
    """True when this loop can run the simulation: rk4 with t_end a multiple of dt, matrix R,
    a compiled holonomic model, constant inputs, no drift projection (matrix R needs none)."""
    return (integrator == "rk4" and isinstance(chosen, MatrixR) and model_kernel(model) is not None
            and not model.nonholonomic.any() and not callable(u) and not project and steps_exact)


@njit(cache=True)
def _factor_dependent(buffer, n, m, rows, dependent, Ad, pivots):
    """LU factors (in ``Ad``, ``pivots``) of the dependent block A_d of the A in ``buffer``:
    the partition's constraint rows and dependent columns.  False when exactly singular."""
    A = buffer[n + m:n + m + m * n].reshape((m, n))
    for a in range(rows.shape[0]):
        for j in range(rows.shape[0]):
            Ad[a, j] = A[rows[a], dependent[j]]
    return lu_in_place(Ad, pivots)


@njit(cache=True)
def _norms(buffer, n, m, rows, dependent, Ad, pivots, side, rows_too):
    """(‖A_r‖₁, ‖A_d⁻¹‖₁, ‖A_r‖∞, ‖A_d⁻¹‖∞) from the A in ``buffer`` (A_r: the partition's rows,
    all columns) and the LU factors of A_d in ``Ad``, ``pivots``: A_d⁻¹ column by column (r
    triangular solve pairs); the ∞-norms only when ``rows_too`` (else 0).  ``side`` is
    overwritten."""
    r = rows.shape[0]
    A = buffer[n + m:n + m + m * n].reshape((m, n))
    norm_one = inverse_one = norm_inf = inverse_inf = 0.0
    for c in range(n):
        column = 0.0
        for a in range(r):
            column += abs(A[rows[a], c])
        norm_one = max(norm_one, column)
    if rows_too:
        for a in range(r):
            row = 0.0
            for c in range(n):
                row += abs(A[rows[a], c])
            norm_inf = max(norm_inf, row)
    row_sums = np.zeros(r if rows_too else 0)
    for j in range(r):
        for a in range(r):
            side[a] = 0.0
        side[j] = 1.0
        lu_solve(Ad, pivots, side)
        column = 0.0
        for a in range(r):
            column += abs(side[a])
            if rows_too:
                row_sums[a] += abs(side[a])
        inverse_one = max(inverse_one, column)
    for a in range(row_sums.shape[0]):
        inverse_inf = max(inverse_inf, row_sums[a])
    return norm_one, inverse_one, norm_inf, inverse_inf


@njit(cache=True)
def _condition_one(buffer, n, m, rows, dependent, Ad, pivots, side):
    """κ₁ = ‖A_r‖₁ ‖A_d⁻¹‖₁ (as :func:`cmbs.dynamics.matrix_r.partition_condition` with norm 1),
    by :func:`_norms`."""
    if rows.shape[0] == 0:
        return 1.0
    norm_one, inverse_one, _, _ = _norms(buffer, n, m, rows, dependent, Ad, pivots, side, False)
    return norm_one * inverse_one


@njit(cache=True)
def _condition_two_bound(buffer, n, m, rows, dependent, Ad, pivots, side):
    """An upper bound of κ₂ = ‖A_r‖₂ ‖A_d⁻¹‖₂: sqrt(κ₁ κ_∞) ≥ κ₂, since ‖B‖₂ ≤ sqrt(‖B‖₁ ‖B‖∞)
    for every matrix B (Golub & Van Loan, Matrix Computations, 4th ed., §2.3.3), by
    :func:`_norms`: r triangular solve pairs instead of SVDs."""
    if rows.shape[0] == 0:
        return 1.0
    norm_one, inverse_one, norm_inf, inverse_inf = _norms(buffer, n, m, rows, dependent, Ad, pivots, side, True)
    return np.sqrt(norm_one * inverse_one * norm_inf * inverse_inf)


@njit(cache=True)
def _recover(model, q, qd, t, u_zero, buffer, n, m, rows, dependent, independent, tolerance,
             iterations, limit, Ad, pivots, side, worst):
    """Dependent coordinates (Newton, in place in ``q``) and velocities (in place in ``qd``);
    leaves A at the recovered q in ``buffer`` and A_d's LU factors there in ``Ad``, ``pivots``.
    Returns OK, NOT_CONVERGED or NON_FINITE, or VELOCITIES_KEPT (positions recovered, q̇
    unchanged) where κ₁ at the given q exceeds ``limit``
    (:attr:`MatrixRSolver.recovery_limit`); raises ``worst`` = [κ₁, t] when that
    condition is the largest so far."""
    r = rows.shape[0]
    zeros = np.zeros(n)
    converged = False
    velocities_kept = False
    for iteration in range(iterations):
        evaluate(model, q, zeros, t, u_zero, buffer)
        largest = 0.0
        for a in range(r):
            value = abs(buffer[n + rows[a]])
            if not value < np.inf:
                return NON_FINITE
            largest = max(largest, value)
        if not _factor_dependent(buffer, n, m, rows, dependent, Ad, pivots):
            return NON_FINITE
        if iteration == 0:
            condition = _condition_one(buffer, n, m, rows, dependent, Ad, pivots, side)
            if condition > worst[0]:
                worst[0], worst[1] = condition, t
            velocities_kept = condition > limit
        if largest < tolerance:
            converged = True
            break
        for a in range(r):
            side[a] = buffer[n + rows[a]]
        lu_solve(Ad, pivots, side)
        for j in range(r):
            q[dependent[j]] -= side[j]
    if not converged:
        return NOT_CONVERGED
    if velocities_kept:
        return VELOCITIES_KEPT
    A = buffer[n + m:n + m + m * n].reshape((m, n))
    phi_t = buffer[n + 2 * m + m * n:n + 3 * m + m * n]
    for a in range(r):                       # A_d's factors at the recovered q are in Ad, pivots
        total = -phi_t[rows[a]]
        for j in range(independent.shape[0]):
            total -= A[rows[a], independent[j]] * qd[independent[j]]
        side[a] = total
    lu_solve(Ad, pivots, side)
    for j in range(r):
        qd[dependent[j]] = side[j]
    return OK


@njit(cache=True)
def _stage(model, q, qd, t, u, u_zero, buffer, n, m, rows, dependent, independent, tolerance,
           iterations, limit, qdd, lam, work, worst):
    """Recover (q, q̇) in place (q only where :func:`_recover` keeps the velocities), then q̈ and λ
    by matrix R at that state (``worst`` as in :func:`_recover`)."""
    Ad, pivots, side, R, reduced, zrhs, S, MR, force = work
    status = _recover(model, q, qd, t, u_zero, buffer, n, m, rows, dependent, independent, tolerance,
                      iterations, limit, Ad, pivots, side, worst)
    if status != OK and status != VELOCITIES_KEPT:
        return status
    evaluate(model, q, qd, t, u, buffer)
    Q = buffer[:n]
    A = buffer[n + m:n + m + m * n].reshape((m, n))
    gamma = buffer[n + m + m * n:n + 2 * m + m * n]
    M = terms_views(model, n, m, buffer)[5]
    r, k = rows.shape[0], independent.shape[0]
    R[:, :] = 0.0                            # A_d's factors at this q are in Ad, pivots (_recover)
    for b in range(k):                       # R's column b: e_z(b) - A_d⁻¹ A_z e_b on the dependent rows
        R[independent[b], b] = 1.0
        for a in range(r):
            side[a] = A[rows[a], independent[b]]
        lu_solve(Ad, pivots, side)
        for j in range(r):
            R[dependent[j], b] = -side[j]
    S[:] = 0.0
    for a in range(r):
        side[a] = gamma[rows[a]]
    lu_solve(Ad, pivots, side)
    for j in range(r):
        S[dependent[j]] = side[j]
    for i in range(n):                       # M R (skipping M's zeros: a natural model's M is sparse) and Q - M S
        force[i] = Q[i]
        for c in range(k):
            MR[i, c] = 0.0
        for j in range(n):
            mass_ij = M[i, j]
            if mass_ij != 0.0:
                force[i] -= mass_ij * S[j]
                for c in range(k):
                    MR[i, c] += mass_ij * R[j, c]
    for b in range(k):                       # Rᵀ (M R), symmetric, and Rᵀ (Q - M S)
        for c in range(b, k):
            total = 0.0
            for i in range(n):
                total += R[i, b] * MR[i, c]
            reduced[b, c] = total
            reduced[c, b] = total
        total = 0.0
        for i in range(n):
            total += R[i, b] * force[i]
        zrhs[b] = total
    if not solve_in_place(reduced, zrhs):
        return SINGULAR
    for i in range(n):
        total = S[i]
        for b in range(k):
            total += R[i, b] * zrhs[b]
        qdd[i] = total
    for a in range(m):
        lam[a] = 0.0
    for j in range(r):                       # (M q̈ - Q)_d = -A_dᵀ λ_r
        c = dependent[j]
        total = -Q[c]
        for i in range(n):
            total += M[c, i] * qdd[i]
        side[j] = -total
    lu_solve_transposed(Ad, pivots, side)
    for a in range(r):
        lam[rows[a]] = side[a]
    for i in range(n):
        if not (abs(qdd[i]) < np.inf):
            return NON_FINITE
    return OK


@njit(cache=True)
def _condition(buffer, n, m, rows, dependent):
    """κ₂ = ‖A_r‖₂ / σ_min(A_d) of the A in ``buffer``, as
    :func:`cmbs.dynamics.matrix_r.partition_condition` (the Python solver's test) computes it."""
    r = rows.shape[0]
    if r == 0:
        return 1.0
    A = buffer[n + m:n + m + m * n].reshape((m, n))
    block = np.empty((r, r))
    partition_rows = np.empty((r, n))
    for a in range(r):
        for c in range(n):
            partition_rows[a, c] = A[rows[a], c]
        for j in range(r):
            block[a, j] = A[rows[a], dependent[j]]
    smallest = np.linalg.svd(block)[1][-1]
    return np.linalg.norm(partition_rows, 2) / smallest if smallest > 0 else np.inf


@njit(cache=True)
def rk4(model, q0, qd0, u, h, first, steps, every, buffer_size, m, rows, dependent, independent,
        tolerance, iterations, limit, reference_condition, growth, automatic, worst, T, Qs, QDs, QDDs, LAMs, PHI, PHID,
        FORCE):
    """RK4 steps ``first`` .. ``steps`` (t = step·h) from the state (q0, q̇0) at step ``first``,
    recording every ``every``-th step into the given arrays (row = step // every; the rows up to
    ``first`` > 0 are already there), and the largest stage κ₁ and its time into ``worst``.  Returns (status, step
    reached, rows recorded, q, q̇ at the step reached): OK at
    the end; REPARTITION when κ₂ at the step reached calls for a new partition; a
    failure code where a stage of that step failed."""
    n = q0.shape[0]
    r, k = rows.shape[0], independent.shape[0]
    buffer = np.zeros(buffer_size)
    terms = terms_views(model, n, m, buffer)
    u_zero = np.zeros(u.shape[0])
    work = (np.empty((max(r, 1), max(r, 1))), np.empty(max(r, 1), dtype=np.int64), np.empty(max(r, 1)),
            np.empty((n, k)), np.empty((k, k)), np.empty(k), np.empty(n), np.empty((n, k)), np.empty(n))
    q, qd = q0.copy(), qd0.copy()
    k1v, k2v, k3v, k4v = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    lam, stage_lam = np.empty(m), np.empty(m)
    recorded = first // every + 1 if first > 0 else 0
    for step in range(first, steps + 1):
        t = step * h
        status = _stage(model, q, qd, t, u, u_zero, buffer, n, m, rows, dependent, independent,
                        tolerance, iterations, limit, k1v, lam, work, worst)
        if status != OK:
            return status, step, recorded, q, qd
        if step > first or first == 0:
            if step % every == 0:
                row = step // every
                T[row] = t
                Qs[row] = q
                QDs[row] = qd
                QDDs[row] = k1v
                LAMs[row] = lam
                record_constraints(terms, qd, lam, PHI, PHID, FORCE, row)
                recorded = row + 1
            limit_two = min(growth * reference_condition, SINGULAR_CONDITION) if automatic else SINGULAR_CONDITION
            # the SVD only where the bound from the recovery's LU factors cannot rule the test out
            if _condition_two_bound(buffer, n, m, rows, dependent, work[0], work[1], work[2]) > limit_two \
                    and _condition(buffer, n, m, rows, dependent) > limit_two:
                return REPARTITION, step, recorded, q, qd
        if step == steps:
            break
        k1q = qd.copy()                      # the recovered velocities are dq/dt
        sq, sv = q + 0.5 * h * k1q, qd + 0.5 * h * k1v
        status = _stage(model, sq, sv, t + 0.5 * h, u, u_zero, buffer, n, m, rows, dependent,
                        independent, tolerance, iterations, limit, k2v, stage_lam, work, worst)
        if status != OK:
            return status, step, recorded, q, qd
        k2q = sv.copy()
        sq, sv = q + 0.5 * h * k2q, qd + 0.5 * h * k2v
        status = _stage(model, sq, sv, t + 0.5 * h, u, u_zero, buffer, n, m, rows, dependent,
                        independent, tolerance, iterations, limit, k3v, stage_lam, work, worst)
        if status != OK:
            return status, step, recorded, q, qd
        k3q = sv.copy()
        sq, sv = q + h * k3q, qd + h * k3v
        status = _stage(model, sq, sv, t + h, u, u_zero, buffer, n, m, rows, dependent,
                        independent, tolerance, iterations, limit, k4v, stage_lam, work, worst)
        if status != OK:
            return status, step, recorded, q, qd
        k4q = sv
        q = q + h / 6.0 * (k1q + 2.0 * k2q + 2.0 * k3q + k4q)
        qd = qd + h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
    return OK, steps, recorded, q, qd


def run(model: Model, solver: MatrixRSolver, u: np.ndarray, q0: np.ndarray, qd0: np.ndarray, dt: float,
        steps: int, every: int = 1) -> tuple[tuple[np.ndarray, ...], int, int, str, int]:
    """Run :func:`rk4` over ``steps`` steps of ``dt`` from (q0, q̇0), handing every re-partition
    to ``solver`` (which chooses the new partition or raises).  Returns the records
    (t, q, q̇, q̈, λ, |Φ|max, |Φ̇|max, f_c) of every ``every``-th step, the number recorded, the
    steps completed, the failure message ("" on success) and the number of re-partitions; the
    largest stage κ₁ goes to ``solver.note_condition``."""
    kernel = model_kernel(model)
    n, m = model.n, model.m
    size = steps // every + 1
    records = (np.zeros(size), np.zeros((size, n)), np.zeros((size, n)), np.zeros((size, n)),
               np.zeros((size, m)), np.zeros(size), np.zeros(size), np.zeros((size, n)))
    parameters = solver.p
    q, qd, first = np.array(q0, dtype=float), np.array(qd0, dtype=float), 0
    repartitions = 0
    worst = np.zeros(2)
    failures = {NOT_CONVERGED: f"matrix-r position recovery did not converge in {parameters.max_iterations} "
                               "iterations", SINGULAR: "singular block A_d or reduced mass matrix Rᵀ M R",
                NON_FINITE: "non-finite state or accelerations: the motion diverged"}
    while True:
        part = solver.partition
        status, reached, recorded, q, qd = rk4(
            kernel, q, qd, np.ascontiguousarray(u, dtype=float), dt, first, steps, every, model.new_terms().buffer.size, m,
            part.rows.astype(np.int64), part.dependent.astype(np.int64), part.independent.astype(np.int64),
            parameters.position_tolerance, parameters.max_iterations, solver.recovery_limit,
            float(solver.reference_condition),
            parameters.condition_growth, solver.user is None, worst, *records)
        solver.note_condition(worst[0], worst[1])
        t = reached * dt
        if status == OK:
            return records, recorded, reached, "", repartitions
        if status != REPARTITION:
            return records, recorded, reached, f"model {model.name!r} at t={t:.6g}: {failures[status]}", repartitions
        before = solver.repartitions
        try:
            solver.update_partition(model.jacobian(q, t), t)
        except CmbsError as error:
            return records, recorded, reached, str(error), repartitions
        if solver.repartitions == before:    # numpy's κ₂ disagrees with the loop's: cannot go on
            return records, recorded, reached, (f"model {model.name!r} at t={t:.6g}: the partition's condition calls "
                                                "for a new partition but none was chosen"), repartitions
        repartitions += 1
        first = reached
