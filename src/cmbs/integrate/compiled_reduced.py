"""The implicit trapezoidal rule in matrix R's independent coordinates, compiled: the problem
:func:`cmbs.integrate.implicit.newton_steps` takes for a model with a compiled kernel and
constant inputs (the driver is :func:`cmbs.simulate`'s ``_run_reduced``, the same for a model
with Python callables, whose problem is a :class:`~cmbs.integrate.implicit.CallbackProblem`).

The unknowns are the independent coordinates z of the partition (thesis eq. 3.51-3.57).  At an
iterate (z, ż, z̈) the residual kernel expands it to the full state, from the last accepted one
with z, ż, z̈ put in: dependent coordinates by Newton on Φ_r = 0 and their velocities from
A_d ḋ = -A_z ż - Φ_t (:func:`cmbs.dynamics.matrix_r_kernels.recover`), dependent accelerations
from A_d q̈_d = γ_r - A_z z̈ (``dependent_accelerations``); then, with R = [-A_d⁻¹A_z; I] (rows in the partition's order)::

    f = Rᵀ(M q̈ - Q),   M̄ = Rᵀ M R,   C̄ = Rᵀ C_t R,   K̄ = Rᵀ K_t R

where C_t = -∂Q/∂q̇ and K_t = -∂Q/∂q are forward differences over all n coordinates with the
steps 1e-7 max(1, |x_k|) and the inputs held (:func:`cmbs.integrate.implicit.forward_difference_tangents`).
After a step the accepted full state is the expansion at the last iterate evaluated, the
partition is updated there as matrix R's after-step hook in the explicit loops updates it
(:func:`cmbs.dynamics.matrix_r_kernels.update_partition`: chosen again in place when κ₂ has
grown by ``condition_growth``), and the integrator's z, ż, z̈ are taken from it in the
independent coordinates of that partition (their number is fixed).  The branch watch
(:func:`cmbs.integrate.continuity.left_branch`) then sees the accepted full state.
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple

import numpy as np

from cmbs.dynamics.base import OK
from cmbs.dynamics.matrix_r import singular_partition_message
from cmbs.dynamics.matrix_r_kernels import (MET, NOT_CONVERGED, MatrixRKernel, dependent_accelerations, recover,
                                            update_partition, velocity_matrix)
from cmbs.integrate.compiled_index3 import dense_newton_back_solve, dense_newton_factor
from cmbs.integrate.continuity import left_branch
from cmbs.integrate.implicit import DIVERGED, STOPPED, forward_difference_tangents
from cmbs.jit import njit
from cmbs.model.compiled import evaluate, terms_views

#: Why a :class:`ReducedProblem` stopped its run (``failure[0]``): the position recovery did not
#: converge, it met a non-finite Φ or an exactly singular A_d, the forces or the mass matrix are
#: not finite, the partition's A_d is singular (κ₂ above 1e12, no better partition).
RECOVERY_NOT_CONVERGED, RECOVERY_FAILED, NON_FINITE_TERMS, PARTITION_SINGULAR = 1, 2, 3, 4


class ReducedProblem(NamedTuple):
    """The trapezoidal rule's problem: the model's kernel, its constant inputs u and terms buffer;
    matrix R's kernel (:class:`MatrixRKernel`: the partition, updated in place, the recovery's
    tolerance and iterations, zero inputs and ``worst``, the largest κ₁ a recovery met); the
    accepted full state ``full`` and the last expansion ``last`` (each q, q̇, q̈), shared by the
    problems of a run; its work arrays; ``failure`` (why the problem stopped the run: code, value,
    time); ``records`` (q, q̇, q̈ of the kept outputs); the model's name and its coordinate names
    (one per line) for the messages."""

    model: NamedTuple
    u: np.ndarray
    buffer: np.ndarray
    partition: MatrixRKernel
    full: tuple
    last: tuple
    work: tuple
    failure: np.ndarray
    records: tuple
    name: str
    coordinate_names: str

    def stop_message(self) -> str:
        """The message of the failure the problem stopped the run for (as the Python path's)."""
        code, value, t = self.failure
        if code == RECOVERY_NOT_CONVERGED:
            return (f"model {self.name!r} at t={t:.6g}: matrix-r position recovery did not converge in "
                    f"{self.partition.iterations} iterations (residual {value:.3g})")
        if code == RECOVERY_FAILED:
            return (f"model {self.name!r} at t={t:.6g}: matrix-r position recovery met non-finite constraints or "
                    "a singular block A_d")
        if code == PARTITION_SINGULAR:
            return singular_partition_message(self.name, self.coordinate_names.split("\n"), self.partition, t)
        return f"model {self.name!r} at t={t:.6g}: non-finite forces or mass matrix"


def reduced_problems(kernel: NamedTuple, model: object, solver: object, u: np.ndarray, full: tuple, last: tuple,
                     outputs: int) -> Callable[[], ReducedProblem]:
    """The maker of the :class:`ReducedProblem` of ``model`` (``kernel``) with inputs ``u`` under
    ``solver`` (a :class:`~cmbs.dynamics.matrix_r.MatrixRSolver`: its
    :meth:`~cmbs.dynamics.matrix_r.MatrixRSolver.kernel`, whose partition and ``worst`` are the
    solver's) for a run or its retry, all sharing the full states ``full`` and ``last``, the terms
    buffer, the work arrays and the records of ``outputs`` outputs, each with a ``failure`` of its
    own."""
    n = model.n
    partition = solver.kernel()
    buffer, work = model.new_terms().buffer.copy(), reduced_work(n, partition.independent.size, partition.rows.size)
    records = (np.zeros((outputs, n)), np.zeros((outputs, n)), np.zeros((outputs, n)))
    names = "\n".join(model.coordinate_names)
    return lambda: ReducedProblem(kernel, u, buffer, partition, full, last, work, np.zeros(3), records, model.name,
                                  names)


def reduced_work(n: int, k: int, r: int) -> tuple:
    """The work arrays of a :class:`ReducedProblem` with ``k`` independent coordinates and ``r``
    dependent ones: A_d's LU factors and pivots, a side vector, R, M, M q̈ - Q, -Q, X R (X = M, K_t
    or C_t), K_t, C_t, a shifted state, zeros (n), -Q at a shifted state."""
    return (np.empty((r, r)), np.empty(r, dtype=np.int64), np.empty(r), np.empty((n, k)), np.empty((n, n)),
            np.empty(n), np.empty(n), np.empty((n, k)), np.empty((n, n)), np.empty((n, n)), np.empty(n), np.zeros(n),
            np.empty(n))


@njit(cache=True)
def _expand(problem, t, z, zd, zdd):
    """The full state of the iterate (z, ż, z̈) into ``problem.last`` and the terms at it into the
    buffer (A_d's LU factors at it in the work arrays); returns OK, or STOPPED with the
    ``failure`` noted."""
    q, qd, qdd = problem.last
    full_q, full_qd, full_qdd = problem.full
    Ad, pivots, side = problem.work[0], problem.work[1], problem.work[2]
    partition = problem.partition
    rows, dependent, independent = partition.rows, partition.dependent, partition.independent
    n, m, r = q.shape[0], partition.m, rows.shape[0]
    q[:] = full_q
    qd[:] = full_qd
    qdd[:] = full_qdd
    for b in range(independent.shape[0]):
        q[independent[b]] = z[b]
        qd[independent[b]] = zd[b]
        qdd[independent[b]] = zdd[b]
    status = recover(problem.model, q, qd, t, partition.no_input, problem.buffer, n, m, rows, dependent, independent,
                     partition.tolerance, partition.iterations, np.inf, Ad, pivots, side, partition.worst)
    if status != OK:
        largest = 0.0
        for a in range(r):
            largest = max(largest, abs(problem.buffer[n + rows[a]]))
        code = RECOVERY_NOT_CONVERGED if status == NOT_CONVERGED else RECOVERY_FAILED
        problem.failure[0], problem.failure[1], problem.failure[2] = code, largest, t
        return STOPPED
    evaluate(problem.model, q, qd, t, problem.u, problem.buffer)
    Q, _, A, gamma, _, M = terms_views(problem.model, n, m, problem.buffer)
    dependent_accelerations(A, gamma, rows, dependent, Ad, pivots, side, qdd)   # A_d's factors: recover's
    for i in range(n):
        if not math.isfinite(Q[i]):
            problem.failure[0], problem.failure[1], problem.failure[2] = NON_FINITE_TERMS, 0.0, t
            return STOPPED
        for j in range(n):
            if not math.isfinite(M[i, j]):
                problem.failure[0], problem.failure[1], problem.failure[2] = NON_FINITE_TERMS, 0.0, t
                return STOPPED
    return OK


@njit(cache=True)
def _reduce(R, X, XR, out):
    """out = Rᵀ X R (XR: scratch n x k)."""
    n, k = R.shape
    for i in range(n):
        for c in range(k):
            total = 0.0
            for j in range(n):
                total += X[i, j] * R[j, c]
            XR[i, c] = total
    for b in range(k):
        for c in range(k):
            total = 0.0
            for i in range(n):
                total += R[i, b] * XR[i, c]
            out[b, c] = total


@njit(cache=True)
def _residual(problem, step, stage, t, state, out):
    """The residual kernel (module docstring): f, M̄, C̄, K̄ at the iterate ``state`` into ``out``;
    OK, STOPPED by the expansion (:func:`_expand`), or DIVERGED where Q at a shifted state of
    the tangents is not finite."""
    z, zd, zdd, _ = state
    f, _, M_bar, _, C_bar, K_bar = out
    status = _expand(problem, t, z, zd, zdd)
    if status != OK:
        return status
    q, _, qdd = problem.last
    Ad, pivots, side, R, mass, force, base, XR, K, C, shifted, _, column = problem.work
    partition = problem.partition
    rows, dependent, independent = partition.rows, partition.dependent, partition.independent
    n, m, k = q.shape[0], partition.m, independent.shape[0]
    Q, _, A, _, _, M = terms_views(problem.model, n, m, problem.buffer)
    velocity_matrix(A, rows, dependent, independent, Ad, pivots, side, R)     # A_d's factors: _expand's
    for i in range(n):
        total = -Q[i]
        for j in range(n):
            mass[i, j] = M[i, j]
            total += M[i, j] * qdd[j]
        force[i] = total
        base[i] = -Q[i]
    for b in range(k):
        total = 0.0
        for i in range(n):
            total += R[i, b] * force[i]
        f[b] = total
    _reduce(R, mass, XR, M_bar)
    if not forward_difference_tangents(problem, problem.last, t, np.int64(0), base, shifted, column, (K, C)):
        return DIVERGED
    _reduce(R, K, XR, K_bar)
    _reduce(R, C, XR, C_bar)
    return OK


@njit(cache=True, inline="always")
def _differenced(problem, point, t, step, which, shifted, out):
    """The function whose tangents are taken (:data:`cmbs.integrate.implicit.differenced`): -Q at
    the expansion ``point`` = (q, q̇, q̈) with q (``which`` 0) or q̇ (1) replaced by ``shifted``,
    the inputs held."""
    q, qd = point[0], point[1]
    if which == 0:
        q = shifted
    else:
        qd = shifted
    evaluate(problem.model, q, qd, t, problem.u, problem.buffer)
    for i in range(out.shape[0]):
        out[i] = -problem.buffer[i]


@njit(cache=True)
def _record(problem, row, step, stage, t, state):
    """Row ``row`` of the records: the accepted full state."""
    records_q, records_qd, records_qdd = problem.records
    full_q, full_qd, full_qdd = problem.full
    for i in range(full_q.shape[0]):        # element by element (cmbs.jit.njit)
        records_q[row, i] = full_q[i]
        records_qd[row, i] = full_qd[i]
        records_qdd[row, i] = full_qdd[i]


@njit(cache=True)
def _after_step(problem, t, state):
    """The accepted full state is the last expansion; the partition is updated there
    (:func:`update_partition`; a singular one noted in ``failure``, for :func:`_at_output`), and
    the integrator's z, ż, z̈ (and the auxiliary acceleration) are taken from it in the
    partition's independent coordinates."""
    z, zd, zdd, _, x = state
    full_q, full_qd, full_qdd = problem.full
    last_q, last_qd, last_qdd = problem.last
    for i in range(full_q.shape[0]):        # element by element (cmbs.jit.njit)
        full_q[i] = last_q[i]
        full_qd[i] = last_qd[i]
        full_qdd[i] = last_qdd[i]
    partition = problem.partition
    n, m = full_q.shape[0], partition.m
    evaluate(problem.model, full_q, problem.work[11], t, partition.no_input, problem.buffer)
    if update_partition(terms_views(problem.model, n, m, problem.buffer)[2], partition) != OK:
        problem.failure[0], problem.failure[1], problem.failure[2] = PARTITION_SINGULAR, partition.conditions[MET], t
    independent = partition.independent
    for b in range(independent.shape[0]):
        c = independent[b]
        z[b] = full_q[c]
        zd[b] = full_qd[c]
        zdd[b] = full_qdd[c]
        x[b] = full_qdd[c]


@njit(cache=True)
def _left_branch(problem, watch, t, state):
    """The branch watch at the accepted full state (q, q̇, q̈) at t, A(q) evaluated there (the terms
    stay in the buffer): True when the run left its branch."""
    q, qd, qdd = problem.full
    evaluate(problem.model, q, qd, t, problem.u, problem.buffer)
    return left_branch(watch, t, qd, qdd, terms_views(problem.model, q.shape[0], problem.partition.m,
                                                      problem.buffer)[2])


@njit(cache=True)
def _at_output(problem, t):
    """STOPPED where the step's partition update found A_d singular (:func:`_after_step`), else OK."""
    return STOPPED if problem.failure[0] == PARTITION_SINGULAR else OK


ReducedProblem.residual = staticmethod(_residual)
ReducedProblem.differenced = staticmethod(_differenced)
ReducedProblem.newton_factor = staticmethod(dense_newton_factor)
ReducedProblem.newton_back_solve = staticmethod(dense_newton_back_solve)
ReducedProblem.record = staticmethod(_record)
ReducedProblem.after_step = staticmethod(_after_step)
ReducedProblem.at_output = staticmethod(_at_output)
ReducedProblem.left_branch_at = staticmethod(_left_branch)
