"""Implicit one-step schemes for second-order systems, solved by Newton's method.

Index-3 DAE (Arnold & Brüls 2007, "Convergence of the generalized-α scheme for constrained
mechanical systems"): unknowns a_{n+1} (accelerations) and λ_{n+1}, with an auxiliary
acceleration x (x = a unless α_m, α_f ≠ 0)::

    (1 - α_m) x_{n+1} + α_m x_n = (1 - α_f) a_{n+1} + α_f a_n
    q_{n+1} = q_n + h v_n + h² (b₀ x_n + b₁ x_{n+1})
    v_{n+1} = v_n + h (g₀ x_n + g₁ x_{n+1})
    M(q_{n+1}) a_{n+1} + A(q_{n+1})ᵀ λ_{n+1} = Q(q_{n+1}, v_{n+1}, t_{n+1}),     Φ(q_{n+1}, t_{n+1}) = 0

Schemes (coefficients ``b₀, b₁, g₀, g₁, α_m, α_f``):

- backward Euler: v_{n+1} = v_n + h a_{n+1}, q_{n+1} = q_n + h v_{n+1}  → (0, 1, 0, 1, 0, 0), order 1;
- trapezoidal rule (Newmark, average acceleration): (¼, ¼, ½, ½, 0, 0), order 2;
- generalized-α with spectral radius ρ∞ (Chung & Hulbert 1993): α_m = (2ρ∞-1)/(ρ∞+1),
  α_f = ρ∞/(ρ∞+1), γ = ½ + α_f - α_m, β = ¼(γ + ½)², (½-β, β, 1-γ, γ, α_m, α_f), order 2.

Newton iteration matrix (with b' = b₁(1-α_f)/(1-α_m), g' = g₁(1-α_f)/(1-α_m), the derivatives
of q_{n+1} and v_{n+1} with respect to a_{n+1} divided by h² and h)::

    [ M + h g' C_t + h² b' K_t    Aᵀ ] [Δa]     [ r_dyn ]
    [ h² b' A                      0 ] [Δλ] = - [ Φ     ]

C_t = -∂Q/∂v and K_t = -∂Q/∂q are supplied by the caller (the forward differences of
:func:`forward_difference_tangents`, or zero).  The constraint row is divided by h² b' to keep
the matrix well scaled as h → 0.  Beside the residual's formula (:func:`dynamic_residual`) this
module knows nothing about mechanics: the caller gives the residual and the matrices as a problem, a kernel
tuple whose class carries them (:data:`residual_terms` and the other dispatches below).  The loop
(:func:`newton_steps`) is written once: compiled for a problem with compiled kernels
(:class:`cmbs.integrate.compiled_index3.Index3Problem`, and the trapezoidal rule's
:class:`cmbs.integrate.compiled_reduced.ReducedProblem`), interpreted for a problem given as Python
functions (:class:`CallbackProblem`, :func:`integrate_index3`: models and inputs with Python
callables).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, NamedTuple

import numpy as np

from cmbs.dynamics.base import OK
from cmbs.dynamics.kkt import lu_in_place, lu_solve
from cmbs.integrate.continuity import (IMPLICIT_ADVICE, LEFT_BRANCH, BranchWatch, jump_message, kept_records,
                                      watch_array)
from cmbs.integrate.explicit import Integration
from cmbs.jit import borrow, interpreted, njit, type_dispatch


@dataclass(frozen=True)
class Scheme:
    """Coefficients of a one-step scheme (see the module docstring)."""

    name: str
    b0: float
    b1: float
    g0: float
    g1: float
    alpha_m: float = 0.0
    alpha_f: float = 0.0
    order: int = 2

    @property
    def b_eff(self) -> float:
        return self.b1 * (1.0 - self.alpha_f) / (1.0 - self.alpha_m)

    @property
    def g_eff(self) -> float:
        return self.g1 * (1.0 - self.alpha_f) / (1.0 - self.alpha_m)


BACKWARD_EULER = Scheme("backward-euler", 0.0, 1.0, 0.0, 1.0, order=1)
TRAPEZOIDAL = Scheme("trapezoidal", 0.25, 0.25, 0.5, 0.5)


def generalized_alpha(rho_infinity: float = 0.9) -> Scheme:
    """Chung & Hulbert's generalized-α with high-frequency spectral radius ρ∞ ∈ [0, 1]."""
    if not 0.0 <= rho_infinity <= 1.0:
        raise ValueError(f"spectral radius must be in [0, 1], got {rho_infinity}")
    alpha_m = (2.0 * rho_infinity - 1.0) / (rho_infinity + 1.0)
    alpha_f = rho_infinity / (rho_infinity + 1.0)
    gamma = 0.5 + alpha_f - alpha_m
    beta = 0.25 * (gamma + 0.5) ** 2
    return Scheme(f"generalized-alpha({rho_infinity:g})", 0.5 - beta, beta, 1.0 - gamma, gamma, alpha_m, alpha_f)


# residual(t, q, v, a, λ) -> (r_dyn (n,), phi (m,), M (n,n), A (m,n), C_t (n,n), K_t (n,n))
Residual = Callable[[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                    tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]

#: Status codes of :func:`newton_steps` besides OK (0): the Newton matrix is singular, the
#: correction (or the matrix) is not finite, Newton did not converge, the problem stopped the run.
SINGULAR, DIVERGED, NOT_CONVERGED, STOPPED = 1, 2, 3, 4
#: Newton iterations a step may take (in each of its attempts: :func:`newton_steps`).
NEWTON_ITERATIONS = 25
#: The contraction θ = |Δ_k| / |Δ_{k-1}| of two successive corrections with the same factored
#: Newton matrix above which :func:`newton_steps` forms the matrix afresh for the rest of the
#: step.  While θ ≤ 0.1 the error left after a correction Δ_k is at most θ/(1-θ) |Δ_k| ≤ 0.11 |Δ_k|
#: (the contraction bound of simplified Newton, Hairer & Wanner, Solving ODEs II, IV.8) and each
#: iteration gains a digit, for one residual and one back substitution: on the n-four-bar
#: (N = 40, n = 82, m = 81, 20 s at 1 ms) some fifty times less than the 2n + 1 model
#: evaluations and the factorisation of a fresh matrix.  Measured there (CPU s, factorisations,
#: iterations): 0.1: 4.5, 2 256, 106 530; 0.25: 4.8, 1 968, 132 412; 0.5: 5.3, 1 878, 168 796.
NEWTON_CONTRACTION = 0.1

#: ``residual(problem, step, stage, t, (q, v, a, λ), (r_dyn, Φ, M, A, C_t, K_t)) -> status``: the
#: residual and the matrices at an iterate of step ``step``, ``stage`` 3 at its first iterate and
#: 1 at the others (the stages at which an inputs kernel samples, as
#: :func:`cmbs.integrate.compiled_rk4.apply_inputs` takes them).
residual_terms = type_dispatch("residual")
#: ``newton_factor(problem, matrix, pivots) -> bool``: the LU factors with partial pivoting of
#: the Newton matrix in place, the row swaps in ``pivots`` (LAPACK's getrf, 0-based); False when
#: exactly singular.
newton_factor = type_dispatch("newton_factor")
#: ``newton_back_solve(problem, factors, pivots, rhs)``: the Newton correction into ``rhs`` by the
#: factors of :data:`newton_factor`.
newton_back_solve = type_dispatch("newton_back_solve")
#: ``record(problem, row, step, stage, t, (q, v, a, λ))``: what the problem records at an output beside (q, v, a).
record_output = type_dispatch("record")
#: ``after_step(problem, t, (q, v, a, λ, x))``: the problem may adjust the accepted state in place.
after_step = type_dispatch("after_step")
#: ``at_output(problem, t) -> status``: after the outputs of an instant of ``t_out`` are stored
#: (a progress bar; a check that may stop the run).
at_output = type_dispatch("at_output")
#: ``left_branch_at(problem, watch, t, (q, v, a, λ, x)) -> bool``: the branch watch
#: (:func:`cmbs.integrate.continuity.left_branch`, its state in ``watch``) at the accepted state at
#: t, in the full coordinates of the problem's model; True when the run left its assembly branch
#: there.
left_branch_at = type_dispatch("left_branch_at")
#: ``differenced(problem, point, t, step, which, shifted, out)``: the function f whose tangents
#: :func:`forward_difference_tangents` takes, into ``out``, at the iterate ``point`` = (q, v, ...) of
#: step ``step`` at t with q (``which`` 0) or v (``which`` 1) replaced by ``shifted``.
differenced = type_dispatch("differenced")


@njit(cache=True)
def _residual_with_matrices(problem, step, stage, t, state, out):
    """A problem's :data:`residual_value` where it has none: its :data:`residual_terms`."""
    return residual_terms(problem, step, stage, t, state, out)


#: ``residual_value(problem, step, stage, t, (q, v, a, λ), (r_dyn, Φ, M, A, C_t, K_t)) -> status``:
#: as :data:`residual_terms`, but only r_dyn and Φ need be set (the iterates at which the loop
#: keeps its factored matrix); a problem without it is given its :data:`residual_terms`.
residual_value = type_dispatch("residual_value", default=_residual_with_matrices)


@njit(cache=True, inline="always")
def forward_difference_tangents(problem, point, t, step, base, shifted, column, tangents):
    """The tangents (∂f/∂q, ∂f/∂v) into ``tangents`` of the problem's function f (:data:`differenced`)
    at the iterate ``point`` = (q, v, ...), where f is ``base``, by forward differences, column by
    column::

        ∂f/∂x_k ≈ (f(x + δ_k e_k) - f(x)) / δ_k,   δ_k = 1e-7 max(1, |x_k|),   x = q, then x = v

    (``shifted``, ``column``: scratch vectors of the sizes of x and f).  Returns False, before
    any difference with it, at a value of f that is not finite (an iterate of a diverging run),
    else True.  The one tangent routine:
    of the compiled problems (:mod:`cmbs.integrate.compiled_index3`, whose f is r_dyn with the
    inputs applied at the shifted state, and :mod:`cmbs.integrate.compiled_reduced`, whose f is
    -Q with the inputs held) and, run as Python (:func:`cmbs.jit.interpreted`), of the problems
    with Python callables (:func:`cmbs.simulate._force_derivatives`).  Compiled into its caller
    (``inline``): as a function of its own it added 2-3 s to a first compilation of the
    residual kernels (:func:`cmbs.jit.njit`)."""
    for i in range(base.shape[0]):
        if not math.isfinite(base[i]):
            return False
    for which in range(2):
        x, tangent = point[which], tangents[which]
        for k in range(x.shape[0]):
            for i in range(x.shape[0]):
                shifted[i] = x[i]
            increment = 1e-7 * max(1.0, abs(x[k]))
            shifted[k] += increment
            differenced(problem, point, t, step, which, shifted, column)
            for i in range(column.shape[0]):
                if not math.isfinite(column[i]):
                    return False
                tangent[i, k] = (column[i] - base[i]) / increment
    return True


@njit(cache=True, inline="always")
def dynamic_residual(M, A, Q, a, lam, r):
    """The dynamic rows of the index-3 residual (module docstring) into ``r``::

        r_dyn = M a + Aᵀλ - Q

    summed row by row from -Q_i.  The one residual routine: of the compiled problems
    (:mod:`cmbs.integrate.compiled_index3`, on the terms of the model's kernel) and, called from
    Python, of the problems with Python callables (:func:`cmbs.simulate._run_index3`), for which
    it is compiled too where numba is (a call costs 0.35 µs; run as Python, its 2n(n + m)
    operations on numpy scalars made a run of the human model, n = 38, 12× slower)."""
    n, m = a.shape[0], lam.shape[0]
    for i in range(n):
        total = -Q[i]
        for j in range(n):
            total += M[i, j] * a[j]
        for b in range(m):
            total += A[b, i] * lam[b]
        r[i] = total


class CallbackFunction(NamedTuple):
    """A function f(q, v) given as a Python callable, as :func:`forward_difference_tangents` takes
    it run as Python (:func:`python_tangents`)."""

    function: Callable[[np.ndarray, np.ndarray], np.ndarray]

    @staticmethod
    def differenced(problem: "CallbackFunction", point: tuple, t: float, step: int, which: int, shifted: np.ndarray,
                    out: np.ndarray) -> None:
        q, v = point
        out[:] = problem.function(shifted, v) if which == 0 else problem.function(q, shifted)


class NonFiniteResidual(ArithmeticError):
    """A Python residual (or its tangents) is not finite at an iterate: the run ends as a compiled
    one does there, with :data:`DIVERGED` (:class:`CallbackProblem`).  Raised before any
    arithmetic on the values, of which numpy would warn (inf - inf)."""


def python_tangents(function: Callable[[np.ndarray, np.ndarray], np.ndarray], q: np.ndarray,
                    v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(∂f/∂q, ∂f/∂v) of a Python function f(q, v) by :func:`forward_difference_tangents`, run as
    Python; :class:`NonFiniteResidual` when f is not finite at (q, v) or a shifted state."""
    base = function(q, v)
    K, C = np.zeros((base.size, q.size)), np.zeros((base.size, v.size))
    if not interpreted(forward_difference_tangents)(CallbackFunction(function), (q, v), 0.0, 0, base,
                                                    np.empty(q.size), np.empty(base.size), (K, C)):
        raise NonFiniteResidual("the tangents' forward differences met a non-finite residual")
    return K, C


class CallbackProblem(NamedTuple):
    """A problem given as Python functions: the loop then runs interpreted.  ``function`` is the
    residual (:data:`Residual`); a :class:`NonFiniteResidual` raised by it ends the run as
    :data:`DIVERGED`, an exception of the types ``stop_on`` raised by it (or by ``adjust``, at
    the next output instant) as :data:`STOPPED` with its text as the message (kept in
    ``stopped[0]``).  Optional: ``progress(t)`` at each output instant, ``adjust(t, (q, v, a, λ,
    x))`` after each step, ``keep(row, t, (q, v, a, λ))`` at each output kept, ``value(t, q, v,
    a, λ) -> (r_dyn, Φ)``: the residual without the matrices (else ``function`` serves),
    ``branch(t, (q, v, a, λ, x)) -> bool`` after each step and at the start: the branch watch
    (a :class:`cmbs.integrate.continuity.BranchWatch` on the model's full state; else none)."""

    function: Residual
    progress: Callable[[float], None] | None
    stop_on: tuple[type[Exception], ...]
    stopped: list
    adjust: Callable[[float, tuple], None] | None = None
    keep: Callable[[int, float, tuple], None] | None = None
    value: Callable[[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray], tuple] | None = None
    branch: Callable[[float, tuple], bool] | None = None

    def stop_message(self) -> str:
        return self.stopped[0]


def _callback_call(problem: CallbackProblem, function: Callable, t: float, state: tuple, out: tuple) -> int:
    """``function(t, *state)`` (the residual, or its value), copied into the first entries of ``out``."""
    try:
        values = function(t, *state)
    except NonFiniteResidual:
        return DIVERGED
    except problem.stop_on as error:
        problem.stopped[0] = str(error)
        return STOPPED
    for target, value in zip(out, values):
        target[...] = value
    return OK


def _callback_residual(problem: CallbackProblem, step: int, stage: int, t: float, state: tuple, out: tuple) -> int:
    """The Python residual at the iterate ``state``, copied into ``out``."""
    return _callback_call(problem, problem.function, t, state, out)


def _callback_value(problem: CallbackProblem, step: int, stage: int, t: float, state: tuple, out: tuple) -> int:
    """r_dyn and Φ at the iterate ``state`` (the problem's ``value``, else its residual) into ``out``."""
    return _callback_call(problem, problem.function if problem.value is None else problem.value, t, state, out)


def _callback_factor(problem: CallbackProblem, matrix: np.ndarray, pivots: np.ndarray) -> bool:
    """The compiled problems' LU factorisation (:func:`cmbs.dynamics.kkt.lu_in_place`), called
    compiled where numba is: the same factors to the bit as a compiled run's from the same matrix."""
    return lu_in_place(matrix, pivots)


def _callback_back_solve(problem: CallbackProblem, factors: np.ndarray, pivots: np.ndarray, rhs: np.ndarray) -> None:
    """The solve by the factors of :func:`_callback_factor` (:func:`cmbs.dynamics.kkt.lu_solve`) into ``rhs``."""
    lu_solve(factors, pivots, rhs)


def _callback_record(problem: CallbackProblem, row: int, step: int, stage: int, t: float, state: tuple) -> None:
    if problem.keep is not None:
        problem.keep(row, t, state)


def _callback_after_step(problem: CallbackProblem, t: float, state: tuple) -> None:
    if problem.adjust is not None:
        try:
            problem.adjust(t, state)
        except problem.stop_on as error:
            problem.stopped[0] = str(error)


def _callback_left_branch(problem: CallbackProblem, watch: np.ndarray, t: float, state: tuple) -> bool:
    """The problem's branch watch at the accepted state (on the array of its
    :class:`~cmbs.integrate.continuity.BranchWatch`, which the driver gives the loop as ``watch``)."""
    return problem.branch is not None and problem.branch(t, state)


def _callback_at_output(problem: CallbackProblem, t: float) -> int:
    if problem.progress is not None:
        problem.progress(t)
    return STOPPED if problem.stopped[0] else OK


CallbackProblem.residual = staticmethod(_callback_residual)
CallbackProblem.residual_value = staticmethod(_callback_value)
CallbackProblem.newton_factor = staticmethod(_callback_factor)
CallbackProblem.newton_back_solve = staticmethod(_callback_back_solve)
CallbackProblem.record = staticmethod(_callback_record)
CallbackProblem.after_step = staticmethod(_callback_after_step)
CallbackProblem.at_output = staticmethod(_callback_at_output)
CallbackProblem.left_branch_at = staticmethod(_callback_left_branch)


def integrate_index3(residual: Residual, q0: np.ndarray, v0: np.ndarray, a0: np.ndarray, lam0: np.ndarray,
                     t_out: np.ndarray, *, scheme: Scheme, step: float, tolerance: float = 1e-10,
                     max_iterations: int = NEWTON_ITERATIONS, progress: Callable[[float], None] | None = None,
                     stop_on: tuple[type[Exception], ...] = (), keep_every: int = 1,
                     value: Callable[..., tuple] | None = None, keep_matrix: bool = True,
                     branch: BranchWatch | None = None) -> Integration:
    """:func:`integrate` with the residual a Python function (:class:`CallbackProblem`, ``value``
    its residual without the matrices): the loop of :func:`newton_steps` runs interpreted, calling
    ``progress(t)`` at every output instant and, when given, the branch watch ``branch`` (on the
    state (q, v), (v, a)) after every step."""
    watched = None if branch is None else lambda t, state: branch.left_at(t, *state[:3])
    return integrate(CallbackProblem(residual, progress, stop_on, [""], value=value, branch=watched), q0, v0, a0,
                     lam0, t_out, scheme=scheme, step=step, tolerance=tolerance, max_iterations=max_iterations,
                     keep_every=keep_every, compiled=False, keep_matrix=keep_matrix,
                     watch=None if branch is None else branch.watch)


def integrate(problem: NamedTuple, q0: np.ndarray, v0: np.ndarray, a0: np.ndarray, lam0: np.ndarray,
              t_out: np.ndarray, *, scheme: Scheme, step: float, tolerance: float = 1e-10, max_iterations: int = NEWTON_ITERATIONS,
              keep_every: int = 1, compiled: bool = True, keep_matrix: bool = True,
              watch: np.ndarray | None = None) -> Integration:
    """Fixed-step integration of the index-3 DAE of ``problem`` (a kernel tuple whose class carries
    :data:`residual_terms`, :data:`newton_factor`, :data:`newton_back_solve`, :data:`record_output`,
    :data:`after_step`, :data:`at_output` and :data:`left_branch_at`, and may carry :data:`residual_value`) by
    :func:`newton_steps`, compiled or (``compiled`` False: a problem with Python callables)
    interpreted, keeping its factored Newton matrix while Newton contracts fast (``keep_matrix``;
    False: Newton's method proper, a matrix at every iterate); output at ``t_out`` (each reached
    by equal steps of at most the step, the last landing on it exactly: :func:`step_to_output`), of which only
    ``t_out[::keep_every]`` are stored (``keep_every`` must divide the number of intervals, so
    that the last is kept).  The problem's branch watch (:data:`left_branch_at`) keeps its state in
    ``watch`` (:func:`cmbs.integrate.continuity.watch_array` of the sizes of q and λ when not given).

    Returns an :class:`~cmbs.integrate.explicit.Integration` whose ``y`` holds (q, v) and ``dy``
    (v, a); ``counters`` include the Newton iterations and factorisations.  A failed run keeps the
    outputs before the failure; one the branch watch ended, those up to the start of the jump
    (:func:`cmbs.integrate.continuity.kept_records`).
    """
    if keep_every < 1 or (t_out.size - 1) % keep_every:
        raise ValueError(f"keep_every={keep_every} does not divide the {t_out.size - 1} output intervals")
    kept = t_out[::keep_every]
    out_y = np.zeros((kept.size, 2 * q0.size))
    out_dy = np.zeros((kept.size, 2 * q0.size))
    counts = newton_counters()
    state = newton_state(q0, v0, a0, lam0)
    if watch is None:
        watch = interpreted(watch_array)(q0.size, lam0.size)
    status, next_out, t_stop, change = newton_run(problem, state, t_out, 0, scheme, step, tolerance, max_iterations,
                                                  keep_every, out_y, out_dy, counts, compiled, watch, keep_matrix)
    counters = counter_dict(counts)
    if status == OK:
        return Integration(kept, out_y, out_dy, "success", "", counters)
    stored = stored_outputs(kept, next_out, keep_every, status, watch)
    return Integration(kept[:stored], out_y[:stored], out_dy[:stored], "failed",
                       failure_message(problem, status, t_stop, change, max_iterations, watch), counters)


def stored_outputs(kept: np.ndarray, next_out: int, keep_every: int, status: int, watch: np.ndarray) -> int:
    """How many of the ``kept`` output times a run :func:`newton_steps` ended with ``status`` while
    stepping to output ``next_out`` returns: the kept instants before that output, and of them,
    when the branch watch ended it, only those up to the start of the jump."""
    stored = -(-next_out // keep_every)
    return kept_records(kept, stored, watch) if status == LEFT_BRANCH else stored


def newton_state(q: np.ndarray, v: np.ndarray, a: np.ndarray, lam: np.ndarray) -> tuple[np.ndarray, ...]:
    """The state (q, v, a, λ, x) :func:`newton_steps` starts from (x = a: the auxiliary
    acceleration of a start), as new arrays."""
    return tuple(np.array(value, dtype=float) for value in (q, v, a, lam, a))


def newton_counters() -> np.ndarray:
    """The counters :func:`newton_steps` adds to, zero (:func:`counter_dict` names them)."""
    return np.zeros(4, dtype=np.int64)


def counter_dict(counts: np.ndarray) -> dict[str, int]:
    """The counters of :func:`newton_steps` by name: steps, Newton iterations, residual evaluations
    (each iterate's; the tangents' differences not included), factorisations of the Newton matrix
    (each with the tangents at its iterate)."""
    return {"steps": int(counts[0]), "newton_iterations": int(counts[1]), "evaluations": int(counts[2]),
            "factorizations": int(counts[3])}


def newton_run(problem: NamedTuple, state: tuple, t_out: np.ndarray, first: int, scheme: Scheme, step: float,
               tolerance: float, max_iterations: int, keep_every: int, out_y: np.ndarray, out_dy: np.ndarray,
               counts: np.ndarray, compiled: bool, watch: np.ndarray,
               keep_matrix: bool = False) -> tuple[int, int, float, float]:
    """:func:`newton_steps` from output instant ``first`` of ``t_out`` (with the work arrays it
    needs), compiled or interpreted, keeping its factored matrix only when told (``keep_matrix``:
    the index-3 runs of :func:`integrate`; the trapezoidal rule in matrix R's coordinates runs
    Newton's method proper), the branch watch's state in ``watch``; returns what it returns."""
    n, m = state[0].size, state[3].size
    work = (np.empty(n), np.empty(m), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(m),
            np.empty((n, n)), np.empty((m, n)), np.empty((n, n)), np.empty((n, n)), np.empty((n + m, n + m)),
            np.empty(n + m), np.empty(n + m, dtype=np.int64))
    s = scheme
    coefficients = (s.b0, s.b1, s.g0, s.g1, s.alpha_m, s.alpha_f, s.b_eff, s.g_eff)
    loop = newton_steps if compiled else interpreted(newton_steps)
    return loop(problem, np.ascontiguousarray(t_out, dtype=float), first, keep_every, coefficients, float(step),
                float(tolerance), int(max_iterations), bool(keep_matrix), state, work, out_y, out_dy, counts, watch)


def failure_message(problem: NamedTuple, status: int, t: float, change: float, max_iterations: int,
                    watch: np.ndarray) -> str:
    """Why :func:`newton_steps` stopped with ``status`` at t (``change``: its last scaled correction;
    ``watch``: the branch watch's state)."""
    if status == LEFT_BRANCH:
        return jump_message(watch, IMPLICIT_ADVICE)
    if status == SINGULAR:
        return f"singular Newton matrix at t={t:.6g} (redundant constraints or a singular configuration)"
    if status == DIVERGED:
        return f"Newton iteration diverged at t={t:.6g}"
    if status == NOT_CONVERGED:
        return (f"Newton iteration did not converge in {max_iterations} iterations at t={t:.6g} "
                f"(last correction {change:.3g}); reduce the step")
    return problem.stop_message()


#: The relative excess over the step of an interval still taken as one step by
#: :func:`step_to_output`: the rounding of output times that are multiples of the step, up to
#: ulp(t)/step = 2.2e-16 t/step, 2.2e-9 at the 1e7 instants :func:`cmbs.simulate.output_times` allows.
STEP_SLACK = 1e-6


@njit(cache=True)
def step_to_output(t, target, step):
    """The next step from t towards the output instant ``target``, and whether it lands there:
    the remaining interval d = target - t divided into k = ⌈d/step - :data:`STEP_SLACK`⌉ equal
    steps h = d/k ≤ step (1 + STEP_SLACK), the last of which ends at ``target`` exactly.

    No step is a sliver left by rounding: the time accumulated by t + h drifts from a grid of
    multiples of the step (at h = 1e-4 s, by 7e-12 s at t = 7.0058 s), and stepping by h =
    min(step, target - t) until |t - target| ≤ 1e-12 max(1, |t|) then took a step of 7e-12 s.
    The index-3 equations of such a step are ill-conditioned beyond use: the constraint row,
    Φ(q_n + h v_n + h² b₁ x) = 0, fixes a to the rounding of Φ divided by h² b' (1e-16 / 1e-23),
    and the pendulum left the step with λ ~ 1e7 and its energy wrong (generalized-α, backward
    Euler; :func:`newton_steps`)."""
    remaining = target - t
    count = max(1.0, math.ceil(remaining / step - STEP_SLACK))
    return remaining / count, count == 1.0


@njit(cache=True)
def newton_steps(problem, t_out, first, keep_every, coefficients, step, tolerance, max_iterations, keep_matrix, state,
                 work, out_y, out_dy, counters, watch):
    """The loop of :func:`integrate`: steps of ``step`` through the output times ``t_out`` from the
    state (q, v, a, λ, x) at ``t_out[first]`` (updated in place), storing (q, v) and (v, a) at
    every ``keep_every``-th output into ``out_y``, ``out_dy`` and calling :data:`record_output`
    there (at ``t_out[0]`` too when ``first`` is 0: a resumed run has its row);
    ``counters`` = (steps, Newton iterations, residual evaluations, factorisations).  After each
    step the problem may adjust the state (:data:`after_step`), then its branch watch
    (:data:`left_branch_at`, the state in ``watch``; started at ``t_out[0]`` when ``first`` is 0)
    may end the run (LEFT_BRANCH), and at each output instant the problem may stop the run or
    hand it back (:data:`at_output`).

    Each step solves for a_{n+1}, λ_{n+1} by Newton's method (module docstring), from the
    previous a and λ, until the scaled correction h² b' max|Δa| is below ``tolerance`` (1 +
    max|q_{n+1}|) after at least two iterations.  With ``keep_matrix`` the method is simplified
    Newton, as implicit multibody codes run it: the LU factors of the Newton matrix (with the
    tangents at the iterate where it was formed) serve the following iterations and steps while
    successive corrections contract by θ = |Δ_k|/|Δ_{k-1}| ≤ :data:`NEWTON_CONTRACTION`; when
    they do not, a matrix is formed at every remaining iterate of the step (the next step tries
    the last one again), and at the first iterate of a step of another size.
    A correction Δ_k of a kept matrix passes the test only if the error it leaves, at most
    θ/(1-θ) |Δ_k| (Hairer & Wanner, Solving ODEs II, IV.8), does too.  A step that fails with a
    matrix kept from an earlier step is tried again by Newton's method proper (a matrix at every
    iterate), whose failure is the run's.  Returns (status, index of the output being stepped to,
    time of the failed step or reached, last scaled correction).

    Its helpers are inner functions, compiled into it (numba's closures) and plain Python when it
    runs interpreted: a run on a Python residual compiles none of the loop (only, once, the small
    :func:`dynamic_residual` of the index-3 residual of :mod:`cmbs.simulate`).
    """
    problem, state, work = borrow((problem, state, work))
    b0, b1, g0, g1, alpha_m, alpha_f, b_eff, g_eff = coefficients
    q, v, a, lam, x = state
    a_new, lam_new, x_new, q_new, v_new, r, phi, M, A, C, K, matrix, rhs, pivots = work
    n, m = q.shape[0], lam.shape[0]

    def newton_matrix(damping, scale):
        """The Newton matrix [M + damping C + scale K, Aᵀ; A, 0] (module docstring) into
        ``matrix``; False when an entry is not finite."""
        for i in range(n):
            for j in range(n):
                matrix[i, j] = M[i, j] + damping * C[i, j] + scale * K[i, j]
            for b in range(m):
                matrix[i, n + b] = A[b, i]
                matrix[n + b, i] = A[b, i]
        for b in range(m):
            for c in range(m):
                matrix[n + b, n + c] = 0.0
        for i in range(n + m):
            for j in range(n + m):
                if not math.isfinite(matrix[i, j]):
                    return False
        return True

    def newton_rhs(scale):
        """The right-hand side -(r, Φ/scale) into ``rhs``; False when an entry is not finite."""
        for i in range(n):
            rhs[i] = -r[i]
        for b in range(m):
            rhs[n + b] = -(phi[b] / scale)
        for i in range(n + m):
            if not math.isfinite(rhs[i]):
                return False
        return True

    def settled(fresh, scale, damping, largest, largest_lam, rate):
        """The stopping test on the iterate after a correction (Δa, Δλ) of max|Δa| = ``largest``,
        max|Δλ| = ``largest_lam``, at a contraction ``rate`` θ from the previous correction.
        After a Newton correction (a ``fresh`` matrix) the error left is of second order: h² b'
        max|Δa| must be below ``tolerance`` (1 + max|q_{n+1}|).  After a correction by a kept
        matrix the error left is only θ/(1-θ) times the correction (Hairer & Wanner, Solving
        ODEs II, IV.8), and is left in every step alike: the bounds δa = max|Δa| max(1, θ/(1-θ))
        and δλ (of Δλ alike) must meet that test and, where the errors of the steps add up, the
        velocities' and impulses': h g' δa below ``tolerance`` (1 + max|v_{n+1}|) and h g' δλ below
        ``tolerance`` (1 + h g' max|λ_{n+1}|) (``scale`` h² b', ``damping`` h g')."""
        size, speed, force = 0.0, 0.0, 0.0
        for i in range(n):
            size = max(size, abs(q_new[i]))
            speed = max(speed, abs(v_new[i]))
        if fresh:
            return scale * largest < tolerance * (1.0 + size)
        if rate >= 1.0:
            return False
        for j in range(m):
            force = max(force, abs(lam_new[j]))
        factor = max(1.0, rate / (1.0 - rate))
        left, left_lam = largest * factor, largest_lam * factor
        return (scale * left < tolerance * (1.0 + size) and damping * left < tolerance * (1.0 + speed)
                and damping * left_lam < tolerance * (1.0 + damping * force))

    def solve_step(h, t_new, factored, every):
        """Newton's iterations of the step of size ``h`` to ``t_new`` into (a_new, λ_new), with
        the factors in ``matrix`` of a step of size ``factored`` (0: none) kept while they contract
        fast, or (``every``) a matrix formed and factored at every iterate.  Returns (status, last
        scaled correction, the size of the step the factors then in ``matrix`` were formed for)."""
        a_new[:] = a
        lam_new[:] = lam
        scale = h * h * b_eff
        fresh = every or abs(factored - h) > 1e-9 * h      # not a step short of h by rounding
        change = 0.0
        for iteration in range(max_iterations):
            for i in range(n):
                x_new[i] = ((1.0 - alpha_f) * a_new[i] + alpha_f * a[i] - alpha_m * x[i]) / (1.0 - alpha_m)
                q_new[i] = q[i] + h * v[i] + h * h * (b0 * x[i] + b1 * x_new[i])
                v_new[i] = v[i] + h * (g0 * x[i] + g1 * x_new[i])
            iterate, stage = (q_new, v_new, a_new, lam_new), 3 if iteration == 0 else 1
            if fresh:
                status = residual_terms(problem, counters[0] + 1, stage, t_new, iterate, (r, phi, M, A, C, K))
            else:
                status = residual_value(problem, counters[0] + 1, stage, t_new, iterate, (r, phi, M, A, C, K))
            if status != OK:
                return status, change, 0.0
            counters[2] += 1
            if fresh:
                if not newton_matrix(h * g_eff, scale):
                    return DIVERGED, change, 0.0
                counters[3] += 1
                if not newton_factor(problem, matrix, pivots):
                    return SINGULAR, change, 0.0
                factored = h
            if not newton_rhs(scale):
                return DIVERGED, change, factored
            newton_back_solve(problem, matrix, pivots, rhs)
            largest, largest_lam = 0.0, 0.0
            for i in range(n):
                a_new[i] += rhs[i]
                largest = max(largest, abs(rhs[i]))
            for j in range(m):
                lam_new[j] += rhs[n + j]
                largest_lam = max(largest_lam, abs(rhs[n + j]))
            counters[1] += 1
            previous, change = change, scale * largest
            for i in range(n + m):
                if not math.isfinite(rhs[i]):
                    return DIVERGED, change, factored
            rate = 0.0 if change == 0.0 else (change / previous if previous > 0.0 else math.inf)
            if iteration > 0 and settled(fresh, scale, h * g_eff, largest, largest_lam, rate):
                return OK, change, factored
            if not fresh and iteration > 0 and rate > NEWTON_CONTRACTION:
                every = True                # a kept matrix contracting slowly: Newton proper to the step's end
            fresh = every
        return NOT_CONVERGED, change, factored

    def store(row):
        """Row ``row`` of the outputs: (q, v) and (v, a)."""
        for i in range(n):
            out_y[row, i] = q[i]
            out_y[row, n + i] = v[i]
            out_dy[row, i] = v[i]
            out_dy[row, n + i] = a[i]

    t = t_out[first]
    if first == 0:
        store(0)
        record_output(problem, 0, 0, 0, t, (q, v, a, lam))
        left_branch_at(problem, watch, t, state)          # the first state starts the watch
    next_out = first + 1
    change = 0.0
    factored = 0.0                          # the step size of the factors in ``matrix`` (0: none)
    while next_out < t_out.shape[0]:
        h, lands = step_to_output(t, t_out[next_out], step)
        if h <= 1e-14 * max(1.0, abs(t)):
            next_out += 1
            continue
        t_new = t_out[next_out] if lands else t + h
        status, change, factored = solve_step(h, t_new, factored, not keep_matrix)
        if status != OK and keep_matrix:
            status, change, factored = solve_step(h, t_new, 0.0, True)
        if status != OK:
            return status, next_out, t_new, change
        for i in range(n):
            x_new[i] = ((1.0 - alpha_f) * a_new[i] + alpha_f * a[i] - alpha_m * x[i]) / (1.0 - alpha_m)
            q[i] = q[i] + h * v[i] + h * h * (b0 * x[i] + b1 * x_new[i])
            v[i] = v[i] + h * (g0 * x[i] + g1 * x_new[i])
        a[:] = a_new
        lam[:] = lam_new
        x[:] = x_new
        t = t_new
        counters[0] += 1
        after_step(problem, t, state)
        if left_branch_at(problem, watch, t, state):
            return LEFT_BRANCH, next_out, t, change
        if lands:
            if next_out % keep_every == 0:
                row = next_out // keep_every
                store(row)
                record_output(problem, row, counters[0], 1, t, (q, v, a, lam))
            next_out += 1
            status = at_output(problem, t)
            if status != OK:
                return status, next_out, t, change
    return OK, next_out, t, change
