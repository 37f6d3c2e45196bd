"""Compiled fixed-step RK4 of the matrix-R formulation (velocity transformation, THEORY §3.4).

The loop is that of :func:`cmbs.simulate` with ``integrator="rk4"``, ``formulation="matrix-r"``
on the Python path (:class:`cmbs.dynamics.matrix_r.MatrixRSolver`), step for step, on the same
kernels (:mod:`cmbs.dynamics.matrix_r_kernels`): every stage evaluates the accelerations
(``accelerations``) at the recovered state (``recover``: dependent coordinates by Newton on
Φ_r = 0 with z held, started from the integrated values; dependent velocities from
A_d ḋ = -A_z ż - Φ_t).  A state whose κ₁ = ‖A_r‖₁ ‖A_d⁻¹‖₁ exceeds
:attr:`MatrixRSolver.recovery_limit` (near a singular position) keeps its integrated velocities
(positions recovered).  Every stage also keeps the largest κ₁ it met and its time (``worst``),
for the warning of :func:`cmbs.dynamics.matrix_r.rounding_note`.  After every step the state is
recovered and κ₂ tested against :meth:`MatrixRSolver.partition_limit` (``exceeds``).  Choosing
a new partition is Python's (:meth:`MatrixRSolver.update_partition`: pivoted QR and LU, rare):
the loop returns REPARTITION with the step reached, Python chooses again (or raises for a user
partition) and the loop resumes from there.  Holonomic models with constant inputs only (a
nonholonomic row makes some positions non-recoverable; see :meth:`MatrixRSolver.stage_state`).
"""

from __future__ import annotations

from cmbs.jit import njit
import numpy as np

from cmbs.dynamics.matrix_r import MatrixR, MatrixRSolver
from cmbs.dynamics.matrix_r_kernels import NOT_CONVERGED, VELOCITIES_KEPT, accelerations, exceeds, recover
from cmbs.errors import CmbsError
from cmbs.dynamics.base import NON_FINITE, OK, SINGULAR
from cmbs.integrate.compiled_rk4 import record_constraints
from cmbs.model.compiled import evaluate, model_kernel, terms_views
from cmbs.model.model import Model

#: the loop's status code besides OK, SINGULAR, NON_FINITE and the recovery's
REPARTITION = 3


def runs(model: Model, chosen: object, integrator: str, u: object, project: bool, steps_exact: bool) -> bool:
    """True when this loop can run the simulation: rk4 with t_end a multiple of dt, matrix R,
    a compiled holonomic model, constant inputs, no drift projection (matrix R needs none)."""
    return (integrator == "rk4" and isinstance(chosen, MatrixR) and model_kernel(model) is not None
            and not model.nonholonomic.any() and not callable(u) and not project and steps_exact)


@njit(cache=True)
def _stage(model, q, qd, t, u, u_zero, buffer, n, m, rows, dependent, independent, tolerance,
           iterations, limit, qdd, lam, work, worst):
    """Recover (q, q̇) in place (q only where :func:`~cmbs.dynamics.matrix_r_kernels.recover` keeps
    the velocities), then q̈ and λ by matrix R at that state (``worst`` as in ``recover``)."""
    status = recover(model, q, qd, t, u_zero, buffer, n, m, rows, dependent, independent, tolerance, iterations,
                     limit, work[0], work[1], work[2], worst)
    if status != OK and status != VELOCITIES_KEPT:
        return status
    evaluate(model, q, qd, t, u, buffer)
    Q, _, A, gamma, _, M = terms_views(model, n, m, buffer)
    return accelerations(Q, A, gamma, M, rows, dependent, independent, work, qdd, lam)  # A_d's factors: recover's


@njit(cache=True)
def rk4(model, q0, qd0, u, h, first, steps, every, buffer_size, m, rows, dependent, independent,
        tolerance, iterations, limit, partition_limit, worst, T, Qs, QDs, QDDs, LAMs, PHI, PHID, FORCE):
    """RK4 steps ``first`` .. ``steps`` (t = step·h) from the state (q0, q̇0) at step ``first``,
    recording every ``every``-th step into the given arrays (row = step // every; the rows up to
    ``first`` > 0 are already there), and the largest stage κ₁ and its time into ``worst``.  Returns (status, step
    reached, rows recorded, q, q̇ at the step reached): OK at
    the end; REPARTITION when κ₂ at the step reached exceeds ``partition_limit``
    (:meth:`MatrixRSolver.partition_limit`); a failure code where a stage of that step failed."""
    n = q0.shape[0]
    r, k = rows.shape[0], independent.shape[0]
    buffer = np.zeros(buffer_size)
    terms = terms_views(model, n, m, buffer)
    u_zero = np.zeros(u.shape[0])
    work = (np.empty((r, r)), np.empty(r, dtype=np.int64), np.empty(r), np.empty((n, k)), np.empty((k, k)),
            np.empty(k), np.empty(n), np.empty((n, k)), np.empty(n))       # as accelerations_work
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
            if exceeds(terms[2], rows, dependent, work[0], work[1], work[2], partition_limit):  # recovery's factors
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
            float(solver.partition_limit()), worst, *records)
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
        if solver.repartitions == before:    # Python's A disagrees with the loop's: cannot go on
            return records, recorded, reached, (f"model {model.name!r} at t={t:.6g}: the partition's condition calls "
                                                "for a new partition but none was chosen"), repartitions
        repartitions += 1
        first = reached
