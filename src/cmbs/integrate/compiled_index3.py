"""The index-3 DAE of a model with a compiled kernel as :func:`cmbs.integrate.implicit.integrate`
takes it: backward Euler and generalized-α compiled, model terms and tangents included.

:class:`Index3Problem` carries the model's kernel tuple (:mod:`cmbs.model.compiled`), its inputs
kernel (:class:`~cmbs.integrate.compiled_rk4.ConstantInputs` or a
:class:`~cmbs.control.compiled_torque.ComputedTorqueKernel`) and its work arrays.  At an
iterate (q, v, a, λ) of a step its residual kernel gives::

    r_dyn = M(q) a + A(q)ᵀ λ - Q(q, v, t, u),   Φ(q, t),   M,   A,
    K_t = ∂r_dyn/∂q,   C_t = ∂r_dyn/∂v   (a and λ held),

the tangents by forward differences with the steps 1e-7 max(1, |x_k|) of each coordinate or
velocity x_k (:func:`cmbs.integrate.implicit.forward_difference_tangents`), the inputs evaluated
at each shifted state (a computed-torque law's dependence on the state is part of the tangent; a
held law keeps the sample it took at the step's first iterate).  Its records at the outputs
are λ (Newton's), u, max|Φ|, max|A v + Φ_t| and f_c = -Aᵀλ.  After each step the branch watch
(:func:`cmbs.integrate.continuity.left_branch`) sees (t, v, a) with A(q) there.  At an iterate where the loop keeps
its factored Newton matrix, the residual kernel gives r_dyn and Φ only (:data:`residual_value`:
one model evaluation instead of the 2n + 1 of the tangents).  The Newton matrix is factored by
LU with partial pivoting (:func:`cmbs.dynamics.kkt.lu_in_place`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cmbs.dynamics.base import OK
from cmbs.dynamics.dense import copy_matrix, copy_vector
from cmbs.dynamics.kkt import lu_in_place, lu_solve
from cmbs.integrate.compiled_rk4 import apply_inputs, record_constraints
from cmbs.integrate.continuity import left_branch
from cmbs.integrate.implicit import DIVERGED, dynamic_residual, forward_difference_tangents
from cmbs.jit import njit
from cmbs.model.compiled import evaluate, terms_views


class Index3Problem(NamedTuple):
    """A model's index-3 DAE for :func:`cmbs.integrate.implicit.integrate`: its kernel tuple,
    inputs kernel and inputs u (n_u,), its terms buffer, two scratch vectors (n,) and the records
    (λ (k, m), u (k, n_u), max|Φ| (k,), max|Φ̇| (k,), f_c (k, n)) of its k outputs."""

    model: NamedTuple
    inputs: NamedTuple
    u: np.ndarray
    buffer: np.ndarray
    base: np.ndarray
    shifted: np.ndarray
    records: tuple


def index3_problem(model_kernel: NamedTuple, inputs: NamedTuple, u0: np.ndarray, buffer_size: int, n: int, m: int,
                   outputs: int) -> Index3Problem:
    """An :class:`Index3Problem` with inputs starting at ``u0`` and room for ``outputs`` records."""
    n_u = u0.size
    records = (np.zeros((outputs, m)), np.zeros((outputs, n_u)), np.zeros(outputs), np.zeros(outputs),
               np.zeros((outputs, n)))
    return Index3Problem(model_kernel, inputs, np.array(u0, dtype=float), np.zeros(buffer_size), np.empty(n),
                         np.empty(n), records)


@njit(cache=True)
def _dynamic_residual(problem, q, v, a, lam, t, step, stage, r):
    """r = M a + Aᵀλ - Q (:func:`~cmbs.integrate.implicit.dynamic_residual`) at (q, v, t) with the
    inputs applied there (``step``, ``stage`` as :func:`~cmbs.integrate.compiled_rk4.apply_inputs`
    takes them); the terms stay in the buffer."""
    n, m = q.shape[0], lam.shape[0]
    apply_inputs(problem.inputs, step, stage, q, v, t, problem.u)
    evaluate(problem.model, q, v, t, problem.u, problem.buffer)
    Q, _, A, _, _, M = terms_views(problem.model, n, m, problem.buffer)
    dynamic_residual(M, A, Q, a, lam, r)


@njit(cache=True, inline="always")
def _differenced(problem, point, t, step, which, shifted, out):
    """The function whose tangents are taken (:data:`cmbs.integrate.implicit.differenced`): r_dyn
    at the iterate ``point`` = (q, v, a, λ) with q (``which`` 0) or v (1) replaced by ``shifted``,
    the inputs applied there (a held law keeps its sample)."""
    q, v, a, lam = point
    if which == 0:
        q = shifted
    else:
        v = shifted
    _dynamic_residual(problem, q, v, a, lam, t, step, np.int64(1), out)


@njit(cache=True)
def _residual(problem, step, stage, t, state, out):
    """The residual kernel (module docstring): r_dyn, Φ, M, A at the iterate ``state`` and the
    tangents K_t, C_t (:func:`~cmbs.integrate.implicit.forward_difference_tangents`), into ``out``;
    OK, or DIVERGED where r_dyn is not finite, there or at a shifted state."""
    q, v, a, lam = state
    r, phi, M, A, C, K = out
    n, m = q.shape[0], lam.shape[0]
    _dynamic_residual(problem, q, v, a, lam, t, step, stage, r)
    _, phi_now, A_now, _, _, M_now = terms_views(problem.model, n, m, problem.buffer)
    copy_matrix(M_now, M)
    copy_matrix(A_now, A)
    copy_vector(phi_now, phi)
    if not forward_difference_tangents(problem, state, t, step, r, problem.shifted, problem.base, (K, C)):
        return DIVERGED
    return OK


@njit(cache=True)
def _residual_value(problem, step, stage, t, state, out):
    """r_dyn and Φ at the iterate ``state`` into ``out`` (:data:`cmbs.integrate.implicit.residual_value`:
    the loop keeps its matrix); OK."""
    q, v, a, lam = state
    r, phi = out[0], out[1]
    n, m = q.shape[0], lam.shape[0]
    _dynamic_residual(problem, q, v, a, lam, t, step, stage, r)
    _, phi_now, _, _, _, _ = terms_views(problem.model, n, m, problem.buffer)
    copy_vector(phi_now, phi)
    return OK


@njit(cache=True)
def dense_newton_factor(problem, matrix, pivots):
    """The LU factors with partial pivoting of the Newton matrix in place, its row swaps in
    ``pivots``; False when exactly singular.  The ``newton_factor`` of this module's and
    :mod:`cmbs.integrate.compiled_reduced`'s problems."""
    return lu_in_place(matrix, pivots)


@njit(cache=True)
def dense_newton_back_solve(problem, factors, pivots, rhs):
    """The Newton correction into ``rhs`` by the factors of :func:`dense_newton_factor`."""
    lu_solve(factors, pivots, rhs)


@njit(cache=True)
def _record(problem, row, step, stage, t, state):
    """Row ``row`` of the records at the output state: λ, u (applied there), max|Φ|, max|Φ̇|, f_c."""
    q, v, a, lam = state
    n, m = q.shape[0], lam.shape[0]
    lams, us, largest, rates, forces = problem.records
    apply_inputs(problem.inputs, step, stage, q, v, t, problem.u)
    evaluate(problem.model, q, v, t, problem.u, problem.buffer)
    lams[row] = lam
    us[row] = problem.u
    record_constraints(terms_views(problem.model, n, m, problem.buffer), v, lam, largest, rates, forces, row)


@njit(cache=True)
def _after_step(problem, t, state):
    """Nothing: the state is the integrator's."""


@njit(cache=True)
def _left_branch(problem, watch, t, state):
    """The branch watch at the accepted state (q, v, a) at t, A(q) evaluated there (one model
    evaluation a step; the terms stay in the buffer): True when the run left its branch."""
    q, v, a, lam = state[0], state[1], state[2], state[3]
    evaluate(problem.model, q, v, t, problem.u, problem.buffer)
    return left_branch(watch, t, v, a, terms_views(problem.model, q.shape[0], lam.shape[0], problem.buffer)[2])


@njit(cache=True)
def _at_output(problem, t):
    """Go on (a compiled run shows no progress)."""
    return OK


Index3Problem.residual = staticmethod(_residual)
Index3Problem.differenced = staticmethod(_differenced)
Index3Problem.residual_value = staticmethod(_residual_value)
Index3Problem.newton_factor = staticmethod(dense_newton_factor)
Index3Problem.newton_back_solve = staticmethod(dense_newton_back_solve)
Index3Problem.record = staticmethod(_record)
Index3Problem.after_step = staticmethod(_after_step)
Index3Problem.at_output = staticmethod(_at_output)
Index3Problem.left_branch_at = staticmethod(_left_branch)
