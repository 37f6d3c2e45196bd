"""The computed-torque law (:class:`~cmbs.control.computed_torque.ComputedTorque`), once:
:func:`computed_torque_inputs` takes the model's terms at the state and the law's data
(:class:`TorqueLaw`) and gives the inputs.  The Python law evaluates its model in Python (any
model, user equations included) and calls it; the compiled loops evaluate the model's kernel and
call it at their stages, through :class:`ComputedTorqueKernel` and its inputs kernel.

The loops take their inputs as a kernel tuple whose class carries ``apply(inputs, step, stage,
q, q̇, t, u)`` (:mod:`cmbs.integrate.compiled_rk4`): constant inputs do nothing there; this law
writes u, at every stage or (``held``, a :class:`~cmbs.control.ZeroOrderHold` of period h) at the
first stage of the run and every step's last stage.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cmbs.dynamics.kkt import lu_in_place, lu_solve, lu_solve_transposed
from cmbs.jit import njit
from cmbs.model.compiled import evaluate, model_kernel, terms_views
from cmbs.model.drivers import evaluate_piecewise


class TorqueLaw(NamedTuple):
    """The data of a computed-torque law: the reference's coordinates, the partition's constraint
    rows and dependent coordinates, the gains; the reference spline's breaks and coefficients (one
    row per coordinate in the flattened layout of :func:`~cmbs.model.drivers.evaluate_piecewise`);
    the inverse actuator gains; its work arrays (A_d's LU factors, q̈ and a side vector, pivots)."""

    columns: np.ndarray
    rows: np.ndarray
    dependent: np.ndarray
    kp: np.ndarray
    kd: np.ndarray
    breaks: np.ndarray
    coefficients: np.ndarray
    gains: np.ndarray
    K: np.ndarray
    rhs: np.ndarray
    pivots: np.ndarray


def torque_law(n: int, spline: object, columns: np.ndarray, partition: object, kp: np.ndarray, kd: np.ndarray,
               inverse_gains: np.ndarray) -> TorqueLaw:
    """The :class:`TorqueLaw` of a model with ``n`` coordinates tracking ``columns`` along
    ``spline`` (a scipy cubic spline, one column per tracked coordinate) with the partition
    ``partition`` (rows, dependent) of matrix R, gains ``kp``, ``kd`` and inverse actuator gains
    ``inverse_gains``."""
    coefficients = np.transpose(spline.c, (2, 1, 0)).reshape(columns.size, -1)  # [j, 4i + r] = c[r, i, j]
    r = partition.rows.size
    return TorqueLaw(np.ascontiguousarray(columns, dtype=np.int64), np.ascontiguousarray(partition.rows, dtype=np.int64),
                     np.ascontiguousarray(partition.dependent, dtype=np.int64), np.array(kp, dtype=float),
                     np.array(kd, dtype=float), np.ascontiguousarray(spline.x, dtype=float),
                     np.ascontiguousarray(coefficients, dtype=float), np.ascontiguousarray(inverse_gains, dtype=float),
                     np.empty((r, r)), np.empty(n + r), np.empty(r, dtype=np.int64))


class ComputedTorqueKernel(NamedTuple):
    """A computed-torque law for the compiled loops: its model's kernel, terms buffer, number of
    constraints and zero inputs, the law's data, and ``held`` for a zero-order hold of period h."""

    model: NamedTuple
    buffer: np.ndarray
    m: int
    no_input: np.ndarray
    law: TorqueLaw
    held: bool


def computed_torque_kernel(law: object, held: bool) -> ComputedTorqueKernel | None:
    """The kernel of a :class:`~cmbs.control.computed_torque.ComputedTorque` law (None when its
    model has no compiled kernel)."""
    kernel = model_kernel(law.model)
    if kernel is None:
        return None
    model = law.model
    return ComputedTorqueKernel(kernel, model.new_terms().buffer, model.m, np.zeros(model.n_u), law.data, bool(held))


@njit(cache=True, inline="always")
def _apply(law, step, stage, q, qd, t, u):
    """The law's inputs into ``u`` at a stage: every stage, or when ``held`` at the run's first
    stage and each step's last (at t_n + h, the next sample instant, with that stage's state
    y_n + h k₃: the hold cannot tell that stage from the next step's start), held through the
    next step's first three stages as :class:`~cmbs.control.ZeroOrderHold` holds it."""
    if not law.held or (step == 0 if stage == 0 else stage == 3):
        _computed_torque(law, q, qd, t, u)


ComputedTorqueKernel.apply = staticmethod(_apply)


@njit(cache=True)
def _computed_torque(law, q, qd, t, u):
    """The inputs at (q, q̇, t) into ``u`` (:func:`computed_torque_inputs`) from the terms of the
    model's kernel at zero inputs; NaN where A_d is singular (the Python law raises there).  A
    function of its own: compiled into the loops, it made the first compilation of the compiled
    RK4 loop with this law 1-2 s longer."""
    evaluate(law.model, q, qd, t, law.no_input, law.buffer)
    Q, _, A, gamma, _, M = terms_views(law.model, q.shape[0], law.m, law.buffer)
    computed_torque_inputs(law.law, Q, A, gamma, M, q, qd, t, u)


@njit(cache=True)
def computed_torque_inputs(law, Q, A, gamma, M, q, qd, t, u):
    """The inputs of :class:`~cmbs.control.ComputedTorque` at (q, q̇, t) into ``u``, from the
    terms of its model there with zero inputs (Q₀ = ``Q``, A, γ, M); False (and u NaN) when the
    partition's block A_d is singular, else True.

    The law (thesis ch. 6) is τ_z = Rᵀ(M(R z̈_c + S) - Q₀), u = G τ_z, with G the inverse
    actuator gains, and::

        z̈_c = z̈_ref + K_d (ż_ref - ż) + K_p (z_ref - z)

    where z_ref, ż_ref, z̈_ref come from the reference's cubic spline at t clamped to the spline's
    span (as :meth:`~cmbs.control.Reference.__call__`).  With the partition's r constraint rows
    A_r = [A_d A_z] split into its dependent (d) and independent (z) columns (r = n - k, A_d
    invertible), R = [-A_d⁻¹A_z; I] and S = [A_d⁻¹γ_r; 0] (THEORY §5), so one LU factorisation
    of A_d gives everything::

        q̈_z = z̈_c,   q̈_d = A_d⁻¹(γ_r - A_z z̈_c),   f = M q̈ - Q₀,
        τ_z = f_z + R_dᵀ f_d = f_z - A_zᵀ A_d⁻ᵀ f_d

    ``law`` is a :class:`TorqueLaw`.
    """
    columns, rows, kp, kd = law.columns, law.rows, law.kp, law.kd
    breaks, coefficients, gains, dependent, K, rhs, pivots = (law.breaks, law.coefficients, law.gains, law.dependent,
                                                              law.K, law.rhs, law.pivots)
    n = q.shape[0]
    r = rows.shape[0]
    k = columns.shape[0]
    qdd = rhs[:n]
    side = rhs[n:n + r]
    clamped = min(max(t, breaks[0]), breaks[breaks.shape[0] - 1])
    for b in range(k):
        reference = evaluate_piecewise(breaks, coefficients[b], clamped)
        c = columns[b]
        qdd[c] = reference[2] + kd[b] * (reference[1] - qd[c]) + kp[b] * (reference[0] - q[c])
    Ad = K[:r, :r]
    for a in range(r):
        row = rows[a]
        total = gamma[row]
        for b in range(k):
            total -= A[row, columns[b]] * qdd[columns[b]]
        side[a] = total
        for j in range(r):
            Ad[a, j] = A[row, dependent[j]]
    if not lu_in_place(Ad, pivots):
        u[:] = np.nan
        return False
    lu_solve(Ad, pivots, side)
    for j in range(r):
        qdd[dependent[j]] = side[j]
    for j in range(r):                      # f_d into side
        c = dependent[j]
        total = -Q[c]
        for i in range(n):
            total += M[c, i] * qdd[i]
        side[j] = total
    lu_solve_transposed(Ad, pivots, side)  # A_d⁻ᵀ f_d
    for i in range(u.shape[0]):
        u[i] = 0.0
    for b in range(k):
        c = columns[b]
        force = -Q[c]
        for i in range(n):
            force += M[c, i] * qdd[i]
        for a in range(r):
            force -= A[rows[a], c] * side[a]
        for i in range(u.shape[0]):
            u[i] += gains[i, b] * force
    return True
