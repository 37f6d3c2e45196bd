"""Drift projection: coordinate and velocity projection onto Φ = 0, A q̇ + Φ_t = 0 (Aghili 2005,
§VI, eq. 45-47), written once for the Python loop and the compiled ones.

After each accepted step (and, in an adaptive run, at each output state) the coordinates are
moved by minimum-norm Newton steps on the holonomic rows h (a nonholonomic row has no
position-level constraint), until max |Φ_h| < tolerance or ``iterations`` steps:

    q ← q - A_h⁺ Φ_h(q)

then the velocities are projected with all rows at the new q:

    q̇ ← (I - A⁺A) q̇ - A⁺ Φ_t

A⁺ as the SVD gives it, singular values below ``threshold``·σ_max discarded (as
:func:`cmbs.dynamics.projection.pseudo_inverse`): each step x ← x - A⁺r is the minimum-norm
solution of [I Aᵀ; A 0][δ; λ] = [0; r], solved by the pivoted Schur complement of
:mod:`cmbs.dynamics.dependent_rows` (M = I) wherever its certificate shows the SVD would discard
exactly the rows it finds dependent (redundant constraints included), else by the SVD.  :func:`correct_positions` and
:func:`project_velocities` are the two steps on terms already evaluated, :func:`project` the
whole projection on a model's kernel tuple (or, run as Python, on a model only Python
evaluates); :func:`cmbs.simulate.project_state` calls it, and :class:`DriftProjection` is the
kernel tuple the compiled loops take: it wraps a formulation's kernel
(:mod:`cmbs.dynamics.field`), forwards its solve and stage hook and projects in its after-step
and output hooks.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cmbs.dynamics.base import NON_FINITE, OK
from cmbs.dynamics.dependent_rows import KEPT_LOW, RESIDUAL, TRACE, dependent_rows_arrays, solve_dependent_rows
from cmbs.dynamics.field import after_step
from cmbs.dynamics.projection import PROJECTION_REGULAR
from cmbs.jit import Delegated, njit
from cmbs.model.compiled import evaluate
from cmbs.model.model import Model

#: :func:`correct_positions` moved the coordinates (besides OK: within the tolerance, nothing done).
CORRECTED = 3


@njit(cache=True)
def _subtract_pseudo_inverse(A, b, threshold, x, row_space):
    """x ← x - A⁺ b - ``row_space`` · A⁺A x, with A⁺A = V Vᵀ and A⁺ = V Σ⁻¹ Uᵀ from the SVD of A
    (singular values below ``threshold``·σ_max discarded); ``row_space`` is 0.0 or 1.0."""
    U, sigma, Vt = np.linalg.svd(A, full_matrices=False)
    cutoff = threshold * max(sigma[0], 1e-300)
    n = x.shape[0]
    weights = np.zeros(sigma.shape[0])
    for k in range(sigma.shape[0]):
        if sigma[k] > cutoff:
            along = 0.0                     # (Uᵀ b)_k / σ_k + row_space (Vᵀ x)_k
            for a in range(b.shape[0]):
                along += U[a, k] * b[a]
            along /= sigma[k]
            for j in range(n):
                along += row_space * Vt[k, j] * x[j]
            weights[k] = along
    for j in range(n):
        total = 0.0
        for k in range(sigma.shape[0]):
            total += Vt[k, j] * weights[k]
        x[j] -= total


class DriftWork(NamedTuple):
    """Work arrays of :func:`project`, made once per run by :func:`drift_work`: the dependent-rows
    solve's (M = I, so λ_min(M) = 1 and the identity is M⁻¹: the arrays of
    :func:`~cmbs.dynamics.dependent_rows.dependent_rows_arrays`, X (m, n), A's row non-zeros
    (m, n) and counts (m,), unit row scales (m,)), the holonomic rows' A_h (r, n) and Φ_h (r,), a
    step δ (n), the right-hand side r and the multipliers (m,) and a zero force (n)."""

    dependent_floats: np.ndarray
    dependent_order: np.ndarray
    last_path: np.ndarray
    identity: np.ndarray
    X: np.ndarray
    columns: np.ndarray
    counts: np.ndarray
    ones: np.ndarray
    rows_matrix: np.ndarray
    rows_vector: np.ndarray
    step: np.ndarray
    right: np.ndarray
    multipliers: np.ndarray
    zero_force: np.ndarray


def drift_work(model: Model) -> DriftWork:
    """The :class:`DriftWork` of ``model``."""
    m, n, r = model.m, model.n, int(np.count_nonzero(model.holonomic))
    return DriftWork(*dependent_rows_arrays(m, n), np.eye(n), np.zeros((m, n)), np.zeros((m, n), dtype=np.int64),
                     np.zeros(m, dtype=np.int64), np.ones(m), np.zeros((r, n)), np.zeros(r), np.zeros(n), np.zeros(m),
                     np.zeros(m), np.zeros(n))


@njit(cache=True)
def _subtract_minimum_norm(work, A, b, threshold, x, row_space):
    """x ← x - A⁺ b - ``row_space`` · A⁺A x as :func:`_subtract_pseudo_inverse` (``row_space`` 0.0
    or 1.0), which is x - A⁺r with r = b + ``row_space`` · A x: δ = A⁺r is the minimum-norm
    solution of A δ = r, the q̈ of [I Aᵀ; A 0][δ; λ] = [0; r]
    (:func:`cmbs.dynamics.dependent_rows.solve_dependent_rows` with M = I).  Taken where its
    certificate shows that the SVD would keep exactly its rows: with σ_max² between trace(AAᵀ)/m
    and trace(AAᵀ), the kept singular values are above ``threshold``·σ_max (and at least
    PROJECTION_REGULAR·σ_max, for accuracy) and the discarded ones, at most ρ, are not; else the
    SVD."""
    m, n = A.shape
    right = work.right[:m]
    for a in range(m):
        total = b[a]
        if row_space != 0.0:
            for j in range(n):
                total += A[a, j] * x[j]
        right[a] = total
    certificate = solve_dependent_rows(1.0, work.dependent_floats, work.dependent_order, work.identity, work.zero_force,
                                       A, right, work.ones[:m], work.X, work.columns, work.counts, work.step,
                                       work.multipliers[:m])
    if certificate.shape[0] > 0:
        trace, low = certificate[TRACE], certificate[KEPT_LOW]
        if (low >= PROJECTION_REGULAR * PROJECTION_REGULAR * trace and low > threshold * threshold * trace
                and certificate[RESIDUAL] * m <= threshold * threshold * trace):
            for j in range(n):
                x[j] -= work.step[j]
            return
    _subtract_pseudo_inverse(A, b, threshold, x, row_space)


@njit(cache=True)
def correct_positions(A, phi, rows, tolerance, threshold, q, work):
    """One Newton step q ← q - A_h⁺ Φ_h on the holonomic ``rows`` h of the terms A, Φ at q, in
    place (``work``: :class:`DriftWork`).  Returns OK (nothing done) when max |Φ_h| <
    ``tolerance``, NON_FINITE for a non-finite Φ_h or A_h, else CORRECTED."""
    r, n = rows.shape[0], q.shape[0]
    A_h, phi_h = work.rows_matrix, work.rows_vector
    largest = 0.0
    for a in range(r):
        phi_h[a] = phi[rows[a]]
        if not np.isfinite(phi_h[a]):
            return NON_FINITE
        largest = max(largest, abs(phi_h[a]))
        for j in range(n):
            A_h[a, j] = A[rows[a], j]
            if not np.isfinite(A_h[a, j]):
                return NON_FINITE
    if largest < tolerance:
        return OK
    _subtract_minimum_norm(work, A_h, phi_h, threshold, q, 0.0)
    return CORRECTED


@njit(cache=True)
def project_velocities(A, phi_t, threshold, qd, work):
    """q̇ ← (I - A⁺A) q̇ - A⁺ Φ_t with every row of the terms A, Φ_t, in place (``work``:
    :class:`DriftWork`); OK, or NON_FINITE (q̇ unchanged) for non-finite terms or velocities."""
    m, n = A.shape
    for j in range(n):
        if not np.isfinite(qd[j]):
            return NON_FINITE
    for a in range(m):
        if not np.isfinite(phi_t[a]):
            return NON_FINITE
        for j in range(n):
            if not np.isfinite(A[a, j]):
                return NON_FINITE
    if m > 0:
        _subtract_minimum_norm(work, A, phi_t, threshold, qd, 1.0)
    return OK


class DriftProjection(NamedTuple):
    """A formulation's kernel (``inner``) with drift projection after each accepted step and at
    each output state of an adaptive loop: the holonomic ``rows``, the ``tolerance`` on max |Φ_h|,
    at most ``iterations`` Newton steps, the SVD ``threshold``, the number of constraints ``m``
    (the terms' layout), zero velocities and zero inputs (the terms are evaluated with them), and
    the projection's work arrays."""

    inner: NamedTuple
    rows: np.ndarray
    tolerance: float
    iterations: int
    threshold: float
    m: int
    zeros: np.ndarray
    u: np.ndarray
    work: DriftWork


def drift_projection(inner: NamedTuple, model: Model, tolerance: float, iterations: int = 10,
                     threshold: float = 1e-9) -> DriftProjection:
    """The kernel of ``inner`` (a formulation's kernel for ``model``) with drift projection to
    ``tolerance``, the arguments of :func:`cmbs.simulate.project_state`."""
    return DriftProjection(inner, np.flatnonzero(model.holonomic).astype(np.int64), float(tolerance),
                           int(iterations), float(threshold), int(model.m), np.zeros(model.n),
                           np.zeros(model.n_u), drift_work(model))


@njit(cache=True)
def project(model, q, qd, t, zeros, u, buffer, m, rows, tolerance, iterations, threshold, work):
    """The projection of (q, q̇) at t in place (module docstring): at most ``iterations`` Newton
    steps on the holonomic ``rows`` until max |Φ_h| < ``tolerance``, then the velocities; the
    terms evaluated by the ``model`` kernel at q̇ = ``zeros`` with inputs ``u`` into ``buffer``,
    laid out as :class:`~cmbs.model.model.Terms` with ``m`` constraints (``work``:
    :class:`DriftWork`).  OK, or NON_FINITE where the terms are not finite (the positions as the
    last finite step left them)."""
    n = q.shape[0]
    phi = buffer[n:n + m]
    A = buffer[n + m:n + m + m * n].reshape((m, n))
    phi_t = buffer[n + 2 * m + m * n:n + 3 * m + m * n]
    for _ in range(iterations if rows.shape[0] > 0 else 0):
        evaluate(model, q, zeros, t, u, buffer)
        status = correct_positions(A, phi, rows, tolerance, threshold, q, work)
        if status == NON_FINITE:
            return NON_FINITE
        if status == OK:
            break
    evaluate(model, q, zeros, t, u, buffer)
    return project_velocities(A, phi_t, threshold, qd, work)


@njit(cache=True)
def project_drift(kernel, model, q, qd, t, buffer):
    """The projection of (q, q̇) at t in place with the settings of the ``kernel``
    (:func:`project`); OK or NON_FINITE."""
    return project(model, q, qd, t, kernel.zeros, kernel.u, buffer, kernel.m, kernel.rows, kernel.tolerance,
                   kernel.iterations, kernel.threshold, kernel.work)


@njit(cache=True, inline="always")
def _after_step(kernel, model, q, qd, t, buffer):
    """The wrapped formulation's after-step hook, then the projection (as the Python loop's
    ``after_step``)."""
    status = after_step(kernel.inner, model, q, qd, t, buffer)
    if status != OK:
        return status
    return project_drift(kernel, model, q, qd, t, buffer)


# The solve and the stage hook are the wrapped formulation's own, called without a function between.
DriftProjection.solve = DriftProjection.stage_state = Delegated("inner")
DriftProjection.after_step = staticmethod(_after_step)
DriftProjection.output_state = staticmethod(project_drift)
