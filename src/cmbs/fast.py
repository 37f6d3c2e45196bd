"""Compiled fixed-step simulation: the whole RK4 loop, model kernel and formulation solve in one
numba function, for natural- and joint-coordinate models.

Used by :func:`cmbs.simulate` when the run allows it (integrator ``rk4``; formulation
``lagrange``, ``baumgarte`` or ``projection`` with the standard inertia; constant inputs or a
:class:`~cmbs.control.ComputedTorque` law, alone or in a :class:`~cmbs.control.ZeroOrderHold`
sampled every step; no drift projection; no Python-callable time functions); otherwise the
Python path runs, which gives the same results (tested to 1e-12, closed loops to 1e-10),
including where Lagrange and Baumgarte stop at a singular configuration (the rank of A is
checked at every evaluation, as in Python).  The formulations are those of
:mod:`cmbs.dynamics` (same equations, same singularity check for Lagrange/Baumgarte)::

    lagrange/baumgarte   [M Aᵀ; A 0][q̈; λ] = [Q; γ - 2ξωΦ̇ - ω²Φ]
    projection           (M̂ + PM - M̂P) q̈ = PQ + M̂A⁺γ,   f_c = (I - P)(Mq̈ - Q),   λ = -(Aᵀ)⁺f_c

The computed-torque law is evaluated on its own model (which may differ from the plant) as in
:func:`computed_torque`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from cmbs.control.base import ZeroOrderHold
from cmbs.control.computed_torque import ComputedTorque
from cmbs.model.drivers import evaluate_piecewise
from cmbs.model.joints import JointEquations, _evaluate_kernel as _joint_kernel
from cmbs.model.model import Model
from cmbs.model.natural import NaturalEquations, _evaluate as _natural_kernel

KIND_NATURAL, KIND_JOINT = 0, 1
LAGRANGE, BAUMGARTE, PROJECTION = 0, 1, 2
METHODS = {"lagrange": LAGRANGE, "baumgarte": BAUMGARTE, "projection": PROJECTION}
# status codes of the loop
OK, SINGULAR, NON_FINITE = 0, 1, 2
# inputs of the loop: constant, a computed-torque law at every stage, or that law sampled and held
CONSTANT, LAW, HELD = 0, 1, 2


def supported(model: Model) -> int | None:
    """The kernel kind of ``model`` if the compiled path can run it, else None."""
    equations = model.equations
    if isinstance(equations, NaturalEquations) and not equations.time_functions.python:
        return KIND_NATURAL
    if isinstance(equations, JointEquations) and not equations.python:
        return KIND_JOINT
    return None


def kernel(model: Model) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(kind, ints, reals, buffer, mass) of a supported model: its kernel's data, a zeroed
    :class:`~cmbs.model.model.Terms` buffer, and the constant M of a natural-coordinate model
    (zeros for a joint model, whose M is in the buffer)."""
    kind = supported(model)
    equations = model.equations
    terms = model.new_terms()
    if kind == KIND_NATURAL:
        return kind, equations.ints, equations.reals, terms.buffer, np.array(terms.M)
    return kind, equations.ip, equations.rp, terms.buffer, np.zeros((model.n, model.n))


def control(u: object, model: Model, dt: float) -> tuple[int, ComputedTorque | None] | None:
    """(input mode, law) when the loop can compute the inputs ``u`` of a run of ``model`` with
    step ``dt``, else None.

    Constant inputs (an array or None) give CONSTANT; a :class:`ComputedTorque` gives LAW; a
    :class:`ZeroOrderHold` of one with period ``dt`` exactly gives HELD.  The law's own model
    must be supported and have the plant's coordinates and inputs counts.  Anything else (a
    fault wrapper, another law, another period) is Python's."""
    if not callable(u):
        return CONSTANT, None
    mode, law = (HELD, u.law) if type(u) is ZeroOrderHold and u.period == dt else (LAW, u)
    if type(law) is not ComputedTorque or supported(law.model) is None or law.model.n != model.n \
            or law.model.n_u != model.n_u:
        return None
    return mode, law


def law_arrays(law: ComputedTorque | None, model: Model) -> tuple:
    """The tuple :func:`computed_torque` reads for ``law`` (its model's kernel, workspace and
    zero inputs; its coordinates, constraint rows and gains; the reference spline's breaks and
    coefficients, one row per coordinate in the flattened layout of
    :func:`~cmbs.model.drivers.evaluate_piecewise`; the inverse actuator gains).  For no law
    (constant inputs) the same types, empty, on ``model``'s kernel: numba needs them typed."""
    if law is None:
        kind, ints, reals, buffer, mass = kernel(model)
        empty = np.zeros(0)
        return (kind, ints, reals, buffer, mass, model.m, np.zeros(model.n_u), np.zeros(0, dtype=np.int64),
                np.zeros(0, dtype=np.int64), empty, empty, empty, np.zeros((0, 0)), np.zeros((model.n_u, 0)))
    kind, ints, reals, buffer, mass = kernel(law.model)
    spline = law.reference._spline
    coefficients = np.transpose(spline.c, (2, 1, 0)).reshape(law.columns.size, -1)  # [j, 4i + r] = c[r, i, j]
    return (kind, ints, reals, buffer, mass, law.model.m, np.zeros(law.model.n_u), law.columns.astype(np.int64),
            law.solver.partition.rows.astype(np.int64), np.array(law.kp, dtype=float),
            np.array(law.kd, dtype=float), np.ascontiguousarray(spline.x, dtype=float),
            np.ascontiguousarray(coefficients, dtype=float), np.ascontiguousarray(law.inverse_gains, dtype=float))


@numba.njit(cache=True)
def _evaluate(kind, q, qd, t, u, ints, reals, buffer):
    if kind == KIND_NATURAL:
        _natural_kernel(q, qd, t, u, ints, reals, buffer)
    else:
        _joint_kernel(ints, reals, q, qd, t, u, buffer)


@numba.njit(cache=True)
def _gram_extremes(G):
    """Smallest and largest eigenvalue of the small symmetric matrix ``G`` (overwritten) by
    cyclic Jacobi rotations (Golub & Van Loan §8.5): for a few rows this avoids LAPACK's call
    and workspace overhead, which is larger than the arithmetic."""
    m = G.shape[0]
    for sweep in range(60):
        off = 0.0
        scale = 0.0
        for i in range(m):
            scale += G[i, i] * G[i, i]
            for j in range(i + 1, m):
                off += G[i, j] * G[i, j]
        if off <= 1e-32 * scale:
            break
        for p in range(m - 1):
            for r in range(p + 1, m):
                if G[p, r] == 0.0:
                    continue
                theta = (G[r, r] - G[p, p]) / (2.0 * G[p, r])
                t = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                for k in range(m):      # columns p, r
                    gkp, gkr = G[k, p], G[k, r]
                    G[k, p] = c * gkp - s * gkr
                    G[k, r] = s * gkp + c * gkr
                for k in range(m):      # rows p, r
                    gpk, grk = G[p, k], G[r, k]
                    G[p, k] = c * gpk - s * grk
                    G[r, k] = s * gpk + c * grk
    smallest, largest = G[0, 0], G[0, 0]
    for i in range(1, m):
        smallest = min(smallest, G[i, i])
        largest = max(largest, G[i, i])
    return smallest, largest


@numba.njit(cache=True)
def _singular(A, row_scale, tolerance):
    """True when σ_min/σ_max of the row-scaled A is below ``tolerance`` (as KKTSolver; the σ² are
    the eigenvalues of the small Gram matrix, cheaper than an SVD here)."""
    m = A.shape[0]
    if m == 0:
        return False
    if m > A.shape[1]:
        return True
    n = A.shape[1]
    gram = np.empty((m, m))            # (S A)(S A)ᵀ, S = diag(row_scale), by loops: no BLAS call
    for i in range(m):
        for j in range(i, m):
            value = 0.0
            for k in range(n):
                value += A[i, k] * A[j, k]
            gram[i, j] = gram[j, i] = value * row_scale[i] * row_scale[j]
    if m <= 12:
        low, high = _gram_extremes(gram)
    else:
        eigenvalues = np.linalg.eigvalsh(gram)  # σ² of the scaled A, ascending
        low, high = eigenvalues[0], eigenvalues[m - 1]
    smallest, largest = math.sqrt(max(low, 0.0)), math.sqrt(max(high, 0.0))
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
def computed_torque(law, q, qd, t, K, rhs, u):
    """The inputs of :class:`~cmbs.control.ComputedTorque` at (q, q̇, t) into ``u``; NaN when its
    linear system is singular (the Python law raises there).

    The law (thesis ch. 6) is τ_z = Rᵀ(M(R z̈_c + S) - Q₀), u = G τ_z, with M, Q₀ (Q at u = 0),
    A, γ of the law's model, G its inverse actuator gains, and::

        z̈_c = z̈_ref + K_d (ż_ref - ż) + K_p (z_ref - z)

    where z_ref, ż_ref, z̈_ref come from the reference's cubic spline at t clamped to the spline's
    span (as :meth:`~cmbs.control.Reference.__call__`).  Without forming R, with A_r the
    partition's r constraint rows and E_z (n, k) the columns of the identity at the k independent
    coordinates (r + k = n, A_d invertible)::

        [M    A_rᵀ  -E_z] [q̈  ]   [Q₀ ]
        [A_r  0     0   ] [λ  ] = [γ_r]
        [E_zᵀ 0     0   ] [τ_z]   [z̈_c]

    The last two rows give A_r q̈ = γ_r, q̈_z = z̈_c, i.e. q̈ = R z̈_c + S; premultiplying the
    first by Rᵀ, with A_r R = 0 and E_zᵀ R = I, gives τ_z = Rᵀ(M q̈ - Q₀): the law's τ_z.

    ``law`` is the tuple of :func:`law_arrays`; ``K`` (n+r+k, n+r+k) and ``rhs`` (n+r+k,) are
    workspace.
    """
    kind, ints, reals, buffer, mass, m, no_input, columns, rows, kp, kd, breaks, coefficients, gains = law
    n = q.shape[0]
    r = rows.shape[0]
    k = columns.shape[0]
    _evaluate(kind, q, qd, t, no_input, ints, reals, buffer)
    A = buffer[n + m:n + m + m * n].reshape((m, n))
    gamma = buffer[n + m + m * n:n + 2 * m + m * n]
    M = mass if kind == KIND_NATURAL else buffer[n + 3 * m + m * n:n + 3 * m + m * n + n * n].reshape((n, n))
    K[:, :] = 0.0
    for i in range(n):
        for j in range(n):
            K[i, j] = M[i, j]
        rhs[i] = buffer[i]
    for a in range(r):
        for j in range(n):
            K[n + a, j] = A[rows[a], j]
            K[j, n + a] = A[rows[a], j]
        rhs[n + a] = gamma[rows[a]]
    clamped = min(max(t, breaks[0]), breaks[breaks.shape[0] - 1])
    for b in range(k):
        reference = evaluate_piecewise(breaks, coefficients[b], clamped)
        c = columns[b]
        K[c, n + r + b] = -1.0
        K[n + r + b, c] = 1.0
        rhs[n + r + b] = reference[2] + kd[b] * (reference[1] - qd[c]) + kp[b] * (reference[0] - q[c])
    if not _solve_in_place(K, rhs):
        u[:] = np.nan
        return
    for i in range(u.shape[0]):
        total = 0.0
        for b in range(k):
            total += gains[i, b] * rhs[n + r + b]
        u[i] = total


@numba.njit(cache=True)
def rk4(kind, method, parameters, q0, qd0, h, steps, every, u0, ints, reals, buffer_size, mass, row_scale, m, mode,
        law):
    """Fixed-step RK4 for ``steps`` steps of size ``h`` from t = 0; records (t, q, q̇, q̈, λ, u,
    |Φ|max, |Φ̇|max) every ``every`` steps.  Returns the records, the number recorded and a status
    code with the time, state and inputs it refers to (for a failed run: where the formulation
    could not go on).

    The inputs (``mode``): CONSTANT keeps ``u0``; LAW evaluates :func:`computed_torque` (``law``
    from :func:`law_arrays`) at every stage; HELD reproduces :class:`~cmbs.control.ZeroOrderHold`
    with period h on the Python loop: the law is sampled at t = 0 and at every step's last stage
    (at t_n + h, which is the next sample instant, with that stage's state y_n + h k₃: the hold
    cannot tell that stage from the next step's start), and the value is held through the next
    step's first three stages.  The recorded u at t_n is the input applied from t_n on (the
    held value, as the hold returns it when :func:`cmbs.simulate` records the run), with q̈, λ
    evaluated with it.
    """
    n = q0.shape[0]
    records = steps // every + 1
    T = np.zeros(records)
    Qs = np.zeros((records, n))
    QDs = np.zeros((records, n))
    QDDs = np.zeros((records, n))
    LAMs = np.zeros((records, m))
    Us = np.zeros((records, u0.shape[0]))
    PHI = np.zeros(records)
    PHID = np.zeros(records)
    buffer = np.zeros(buffer_size)
    q, qd, u = q0.copy(), qd0.copy(), u0.copy()
    k1q, k1v, k2q, k2v, k3q, k3v, k4q, k4v = (np.empty(n), np.empty(n), np.empty(n), np.empty(n),
                                              np.empty(n), np.empty(n), np.empty(n), np.empty(n))
    lam = np.empty(m)
    stage_lam = np.empty(m)
    K = np.empty((n + m, n + m))
    rhs = np.empty(n + m)
    size = n + law[7].shape[0] + law[8].shape[0]  # n + k independent coordinates + r constraint rows
    law_K = np.empty((size, size))
    law_rhs = np.empty(size)
    recorded = 0
    for step in range(steps + 1):
        t = step * h
        if mode == LAW or (mode == HELD and step == 0):
            computed_torque(law, q, qd, t, law_K, law_rhs, u)
        status = field(kind, method, parameters, q, qd, t, u, ints, reals, buffer, mass, row_scale, k1v, lam, K, rhs,
                       True)
        if status != OK:
            return T, Qs, QDs, QDDs, LAMs, Us, PHI, PHID, recorded, status, t, q, qd, u
        if step % every == 0:
            T[recorded] = t
            Qs[recorded] = q
            QDs[recorded] = qd
            QDDs[recorded] = k1v
            LAMs[recorded] = lam
            Us[recorded] = u
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
        if mode == LAW:
            computed_torque(law, sq, sv, st, law_K, law_rhs, u)
        status = field(kind, method, parameters, sq, sv, st, u, ints, reals, buffer, mass, row_scale, k2v, stage_lam,
                       K, rhs, True)
        k2q[:] = qd + 0.5 * h * k1v
        if status == OK:
            sq, sv = q + 0.5 * h * k2q, qd + 0.5 * h * k2v
            if mode == LAW:
                computed_torque(law, sq, sv, st, law_K, law_rhs, u)
            status = field(kind, method, parameters, sq, sv, st, u, ints, reals, buffer, mass, row_scale, k3v,
                           stage_lam, K, rhs, True)
        k3q[:] = qd + 0.5 * h * k2v
        if status == OK:
            sq, sv, st = q + h * k3q, qd + h * k3v, t + h
            if mode != CONSTANT:
                computed_torque(law, sq, sv, st, law_K, law_rhs, u)
            status = field(kind, method, parameters, sq, sv, st, u, ints, reals, buffer, mass, row_scale, k4v,
                           stage_lam, K, rhs, True)
        k4q[:] = qd + h * k3v
        if status != OK:
            return T, Qs, QDs, QDDs, LAMs, Us, PHI, PHID, recorded, status, st, sq, sv, u
        q = q + (h / 6.0) * (k1q + 2.0 * k2q + 2.0 * k3q + k4q)
        qd = qd + (h / 6.0) * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
    return T, Qs, QDs, QDDs, LAMs, Us, PHI, PHID, recorded, OK, steps * h, q, qd, u
