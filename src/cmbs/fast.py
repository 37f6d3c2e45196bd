"""Compiled fixed-step simulation: the whole RK4 loop, model kernel and formulation solve in one
numba function, for natural- and joint-coordinate models.

Used by :func:`cmbs.simulate` when the run allows it (integrator ``rk4``; formulation
``lagrange``, ``baumgarte`` or ``projection`` with the standard inertia; constant inputs; no
drift projection; no Python-callable time functions); otherwise the Python path runs, which
gives the same results (tested to 1e-12), including where Lagrange and Baumgarte stop at a
singular configuration (the rank of A is checked at every evaluation, as in Python).  The formulations are those of
:mod:`cmbs.dynamics` (same equations, same singularity check for Lagrange/Baumgarte)::

    lagrange/baumgarte   [M Aᵀ; A 0][q̈; λ] = [Q; γ - 2ξωΦ̇ - ω²Φ]
    projection           (M̂ + PM - M̂P) q̈ = PQ + M̂A⁺γ,   f_c = (I - P)(Mq̈ - Q),   λ = -(Aᵀ)⁺f_c
"""

from __future__ import annotations

import math

import numba
import numpy as np

from cmbs.model.joints import JointEquations, _evaluate_kernel as _joint_kernel
from cmbs.model.model import Model
from cmbs.model.natural import NaturalEquations, _evaluate as _natural_kernel

KIND_NATURAL, KIND_JOINT = 0, 1
LAGRANGE, BAUMGARTE, PROJECTION = 0, 1, 2
METHODS = {"lagrange": LAGRANGE, "baumgarte": BAUMGARTE, "projection": PROJECTION}
# status codes of the loop
OK, SINGULAR, NON_FINITE = 0, 1, 2


def supported(model: Model) -> int | None:
    """The kernel kind of ``model`` if the compiled path can run it, else None."""
    equations = model.equations
    if isinstance(equations, NaturalEquations) and not equations.time_functions.python:
        return KIND_NATURAL
    if isinstance(equations, JointEquations) and not equations.python:
        return KIND_JOINT
    return None


@numba.njit(cache=True)
def _evaluate(kind, q, qd, t, u, ints, reals, buffer):
    if kind == KIND_NATURAL:
        _natural_kernel(q, qd, t, u, ints, reals, buffer)
    else:
        _joint_kernel(ints, reals, q, qd, t, u, buffer)


@numba.njit(cache=True)
def _singular(A, row_scale, tolerance):
    """True when σ_min/σ_max of the row-scaled A is below ``tolerance`` (as KKTSolver; the σ² are
    the eigenvalues of the small Gram matrix, cheaper than an SVD here)."""
    m = A.shape[0]
    if m == 0:
        return False
    if m > A.shape[1]:
        return True
    scaled = A * row_scale.reshape((m, 1))
    eigenvalues = np.linalg.eigvalsh(scaled @ scaled.T)  # σ² of the scaled A, ascending
    smallest, largest = math.sqrt(max(eigenvalues[0], 0.0)), math.sqrt(max(eigenvalues[m - 1], 0.0))
    return smallest < tolerance * max(largest, 1.0)


@numba.njit(cache=True)
def _solve_in_place(K, rhs):
    """Gaussian elimination with partial pivoting on a small dense system; the solution
    overwrites ``rhs``.  Returns False for an exactly singular matrix."""
    size = rhs.shape[0]
    for column in range(size):
        pivot = column
        largest = abs(K[column, column])
        for row in range(column + 1, size):
            if abs(K[row, column]) > largest:
                largest = abs(K[row, column])
                pivot = row
        if largest == 0.0:
            return False
        if pivot != column:
            for k in range(size):
                K[column, k], K[pivot, k] = K[pivot, k], K[column, k]
            rhs[column], rhs[pivot] = rhs[pivot], rhs[column]
        for row in range(column + 1, size):
            factor = K[row, column] / K[column, column]
            if factor != 0.0:
                for k in range(column, size):
                    K[row, k] -= factor * K[column, k]
                rhs[row] -= factor * rhs[column]
    for row in range(size - 1, -1, -1):
        total = rhs[row]
        for k in range(row + 1, size):
            total -= K[row, k] * rhs[k]
        rhs[row] = total / K[row, row]
    return True


@numba.njit(cache=True)
def field(kind, method, parameters, q, qd, t, u, ints, reals, buffer, mass, row_scale, qdd, lam, K, rhs,
          check_rank):
    """q̈ and λ at (q, q̇, t, u) into ``qdd``, ``lam``; returns a status code.

    ``parameters`` = (ξ, ω, singularity tolerance or SVD threshold, mass-regularisation scale s,
    semi-definite flag); ``mass`` is the constant M (natural) or unused (joint: M from buffer);
    ``K`` (n+m, n+m) and ``rhs`` (n+m,) are workspace.  Lagrange/Baumgarte check the rank of A
    when ``check_rank``.
    """
    n = q.shape[0]
    m = lam.shape[0]
    _evaluate(kind, q, qd, t, u, ints, reals, buffer)
    Q = buffer[:n]
    phi = buffer[n:n + m]
    A = buffer[n + m:n + m + m * n].reshape((m, n))
    gamma = buffer[n + m + m * n:n + 2 * m + m * n]
    phi_t = buffer[n + 2 * m + m * n:n + 3 * m + m * n]
    M = mass if kind == KIND_NATURAL else buffer[n + 3 * m + m * n:n + 3 * m + m * n + n * n].reshape((n, n))
    if method == LAGRANGE or method == BAUMGARTE:
        if check_rank and _singular(A, row_scale, parameters[2]):
            return SINGULAR
        for i in range(n):
            for j in range(n):
                K[i, j] = M[i, j]
            rhs[i] = Q[i]
        for r in range(m):
            value = gamma[r]
            if method == BAUMGARTE:
                rate = phi_t[r]
                for j in range(n):
                    rate += A[r, j] * qd[j]
                value -= 2.0 * parameters[0] * parameters[1] * rate + parameters[1] * parameters[1] * phi[r]
            rhs[n + r] = value
            for j in range(n):
                K[n + r, j] = A[r, j]
                K[j, n + r] = A[r, j]
            for j in range(m):
                K[n + r, n + j] = 0.0
        if not _solve_in_place(K, rhs):
            return SINGULAR
        qdd[:] = rhs[:n]
        lam[:] = rhs[n:]
    else:
        pinv = np.zeros((n, m))
        P = np.eye(n)
        if m > 0:
            scaled = A * row_scale.reshape((m, 1))
            U, sigma, Vt = np.linalg.svd(scaled, full_matrices=False)
            for k in range(sigma.shape[0]):
                if sigma[k] > parameters[2]:
                    v = Vt[k]
                    P -= np.outer(v, v)
                    pinv += np.outer(v / sigma[k], U[:, k] * row_scale)
        I_P = np.eye(n) - P
        M_hat = M + parameters[3] * I_P if parameters[4] > 0.0 else M.copy()
        matrix = M_hat + P @ M - M_hat @ P
        rhs = P @ Q + M_hat @ (pinv @ gamma)
        qdd[:] = np.linalg.solve(matrix, rhs)
        force = I_P @ (M @ qdd - Q)
        lam[:] = -(pinv.T @ force)
    for k in range(n):
        if not math.isfinite(qdd[k]):
            return NON_FINITE
    return OK


@numba.njit(cache=True)
def rk4(kind, method, parameters, q0, qd0, h, steps, every, u, ints, reals, buffer_size, mass, row_scale, m):
    """Fixed-step RK4 for ``steps`` steps of size ``h`` from t = 0; records (t, q, q̇, q̈, λ, |Φ|max,
    |Φ̇|max) every ``every`` steps.  Returns the records, the number recorded and a status code
    with the time it refers to (for a failed run: where the formulation could not go on)."""
    n = q0.shape[0]
    records = steps // every + 1
    T = np.zeros(records)
    Qs = np.zeros((records, n))
    QDs = np.zeros((records, n))
    QDDs = np.zeros((records, n))
    LAMs = np.zeros((records, m))
    PHI = np.zeros(records)
    PHID = np.zeros(records)
    buffer = np.zeros(buffer_size)
    q, qd = q0.copy(), qd0.copy()
    k1q, k1v, k2q, k2v, k3q, k3v, k4q, k4v = (np.empty(n), np.empty(n), np.empty(n), np.empty(n),
                                              np.empty(n), np.empty(n), np.empty(n), np.empty(n))
    lam = np.empty(m)
    stage_lam = np.empty(m)
    K = np.empty((n + m, n + m))
    rhs = np.empty(n + m)
    recorded = 0
    for step in range(steps + 1):
        t = step * h
        status = field(kind, method, parameters, q, qd, t, u, ints, reals, buffer, mass, row_scale, k1v, lam, K, rhs,
                       True)
        if status != OK:
            return T, Qs, QDs, QDDs, LAMs, PHI, PHID, recorded, status, t, q, qd
        if step % every == 0:
            T[recorded] = t
            Qs[recorded] = q
            QDs[recorded] = qd
            QDDs[recorded] = k1v
            LAMs[recorded] = lam
            phi = buffer[n:n + m]
            A = buffer[n + m:n + m + m * n].reshape((m, n))
            phid = A @ qd + buffer[n + 2 * m + m * n:n + 3 * m + m * n]
            PHI[recorded] = np.max(np.abs(phi)) if m else 0.0
            PHID[recorded] = np.max(np.abs(phid)) if m else 0.0
            recorded += 1
        if step == steps:
            break
        k1q[:] = qd
        sq, sv, st = q + 0.5 * h * k1q, qd + 0.5 * h * k1v, t + 0.5 * h
        status = field(kind, method, parameters, sq, sv, st, u, ints, reals, buffer, mass, row_scale, k2v, stage_lam,
                       K, rhs, True)
        k2q[:] = qd + 0.5 * h * k1v
        if status == OK:
            sq, sv = q + 0.5 * h * k2q, qd + 0.5 * h * k2v
            status = field(kind, method, parameters, sq, sv, st, u, ints, reals, buffer, mass, row_scale, k3v,
                           stage_lam, K, rhs, True)
        k3q[:] = qd + 0.5 * h * k2v
        if status == OK:
            sq, sv, st = q + h * k3q, qd + h * k3v, t + h
            status = field(kind, method, parameters, sq, sv, st, u, ints, reals, buffer, mass, row_scale, k4v,
                           stage_lam, K, rhs, True)
        k4q[:] = qd + h * k3v
        if status != OK:
            return T, Qs, QDs, QDDs, LAMs, PHI, PHID, recorded, status, st, sq, sv
        q = q + (h / 6.0) * (k1q + 2.0 * k2q + 2.0 * k3q + k4q)
        qd = qd + (h / 6.0) * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
    return T, Qs, QDs, QDDs, LAMs, PHI, PHID, recorded, OK, steps * h, q, qd
