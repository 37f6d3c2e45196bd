"""Compiled adaptive Runge-Kutta loop: the rk45 (Dormand-Prince), rk23 (Bogacki-Shampine) and
dop853 (Dormand-Prince, 8th order) runs of :func:`cmbs.simulate` with the formulations of
:func:`cmbs.dynamics.field.field` (any model and formulation with a compiled kernel), constant
inputs.

The algorithm is that of :func:`cmbs.integrate.explicit.integrate`, step for step: the same
tableau (passed as arrays from :mod:`cmbs.integrate.tableaus`), Hairer's starting step, the
scaled RMS error ‖h Σ(b - b̂)_i k_i / (atol + rtol max(|y|, |y_new|))‖ ≤ 1, a rejected step
shrunk by max(0.2, 0.9 e^(-1/(p+1))), Gustafsson's PI controller for accepted steps
(0.9 e^(-0.7/(p+1)) e_old^(0.4/(p+1)), growth within [0.2, 5]), a non-finite step retried at a
tenth, FSAL, and cubic Hermite output at the requested times; for DOP853 its combined error norm
(:func:`cmbs.integrate.explicit.error_norm`) and its 7th-order continuous extension
(:func:`cmbs.integrate.explicit.dense_coefficients`).  At every output the accelerations,
multipliers, |Φ|, |Φ̇| and -Aᵀλ are evaluated at the interpolated state, as the Python path's
recording does (where that state is singular, q̈ is the interpolant's slope and λ is left 0).

The formulation's hooks (:mod:`cmbs.dynamics.field`) run as the Python path's ``stage_state``
and ``after_step`` do: every stage state is the hook's (matrix R: recovered; its q̇ is the
slope of q), every accepted state passes the after-step hook before its derivative is
evaluated (then without FSAL, as on the Python path), and every output state passes the output
hook before it is recorded (drift projection, :class:`cmbs.dynamics.drift.DriftProjection`, as
the Python path projects its interpolated outputs).  Matrix R chooses a new partition inside its
after-step hook, as the Python path's ``after_step`` does.
"""

from __future__ import annotations

import math

import numpy as np

from typing import NamedTuple

from cmbs.dynamics.base import NON_FINITE, OK, SINGULAR
from cmbs.dynamics.field import after_step, field, output_state, stage_state
from cmbs.integrate.compiled_rk4 import record_constraints
from cmbs.integrate.continuity import LEFT_BRANCH, jump_message, kept_records, left_branch, watch_array
from cmbs.integrate.tableaus import Tableau
from cmbs.jit import borrow, interpreted, njit
from cmbs.model.compiled import terms_views


@njit(cache=True, inline="always")
def _rhs(model, formulation, y, t, u, buffer, terms, lam, state, out, hooked=True):
    """dy/dt = (q̇, q̈) into ``out`` at the stage state: ``y`` copied into ``state`` and made the
    formulation's there (its stage hook: matrix R recovers it; not when ``hooked`` is False, for
    a state the after-step hook left), whose q̇ is the slope of q.  Returns the hook's status
    where it failed, else the field's."""
    d = y.shape[0]
    n = d // 2
    for i in range(d):
        state[i] = y[i]
    if hooked:
        status = stage_state(formulation, model, state[:n], state[n:], t, buffer)
        if status != OK:
            return status
    status = field(model, formulation, state[:n], state[n:], t, u, buffer, terms, out[n:], lam)
    for i in range(n):
        out[i] = state[n + i]
    return status


@njit(cache=True)
def _rms(values, scale):
    total = 0.0
    for i in range(values.shape[0]):
        total += (values[i] / scale[i]) ** 2
    return math.sqrt(total / values.shape[0])


@njit(cache=True, inline="always")
def _record(model, formulation, t, y, slope, u, buffer, terms, k, T, Qs, QDs, QDDs, LAMs, PHI, PHID, FORCE):
    """Row ``k`` of the outputs at (t, y), made the formulation's output state first (its output
    hook: drift projection projects it; ``y`` is left as it is); returns 1 when the state was
    singular (q̈ from the interpolant's slope, λ = 0), else 0."""
    n = y.shape[0] // 2
    m = LAMs.shape[1]
    lam = np.zeros(m)
    qdd = np.empty(n)
    y = y.copy()
    status = output_state(formulation, model, y[:n], y[n:], t, buffer)
    if status == OK:
        status = field(model, formulation, y[:n], y[n:], t, u, buffer, terms, qdd, lam)
    unsolved = 0
    if status != OK:                         # the terms at the state are in the buffer all the same
        for i in range(n):
            qdd[i] = slope[n + i]
        lam[:] = 0.0
        unsolved = 1
    T[k] = t
    for i in range(n):
        Qs[k, i] = y[i]
        QDs[k, i] = y[n + i]
        QDDs[k, i] = qdd[i]
    for r in range(m):
        LAMs[k, r] = lam[r]
    record_constraints(terms, y[n:], lam, PHI, PHID, FORCE, k)
    return unsolved


@njit(cache=True)
def _combination(y, h, weights, stages, count, out):
    """out = y + h Σ_{j<count} w_j k_j, over the non-zero weights."""
    for i in range(out.shape[0]):
        out[i] = y[i]
    _add_stages(h, weights, stages, count, out)


@njit(cache=True)
def _add_stages(h, weights, stages, count, out):
    """out += h Σ_{j<count} w_j k_j, over the non-zero weights."""
    for j in range(count):
        if weights[j] != 0.0:
            factor = h * weights[j]
            for i in range(out.shape[0]):
                out[i] += factor * stages[j, i]


@njit(cache=True)
def _dense_coefficients(y, y_new, k1, k_new, h, dense_d, stages, F):
    """The continuous extension's coefficients F (:func:`cmbs.integrate.explicit.dense_coefficients`)."""
    d = y.shape[0]
    for i in range(d):
        delta = y_new[i] - y[i]
        F[0, i] = delta
        F[1, i] = h * k1[i] - delta
        F[2, i] = 2.0 * delta - h * (k1[i] + k_new[i])
    for r in range(dense_d.shape[0]):
        for i in range(d):
            total = 0.0
            for j in range(dense_d.shape[1]):
                total += dense_d[r, j] * stages[j, i]
            F[3 + r, i] = h * total


@njit(cache=True)
def _dense_value(F, y, x, h, value, slope):
    """Value and derivative at x = (t - t_n)/h of the continuous extension (factors x and 1 - x
    alternating from the innermost coefficient, as :func:`cmbs.integrate.explicit._dense`)."""
    rows = F.shape[0]
    for i in range(y.shape[0]):
        total, derivative = 0.0, 0.0
        for r in range(rows):
            total += F[rows - 1 - r, i]
            if r % 2 == 0:
                derivative = derivative * x + total
                total *= x
            else:
                derivative = derivative * (1.0 - x) - total
                total *= 1.0 - x
        value[i] = y[i] + total
        slope[i] = derivative / h


#: statuses besides OK, SINGULAR, NON_FINITE and the formulation's hooks' (matrix R's)
UNDERFLOW, TOO_MANY_STEPS = 5, 6
#: The steps after which an adaptive run stops with TOO_MANY_STEPS.
MAX_STEPS = 10_000_000


class AdaptiveRun(NamedTuple):
    """The end of an adaptive run: the records (t, q, q̇, q̈, λ, |Φ|, |Φ̇|, -Aᵀλ) and how many
    rows were recorded, the status and the time it refers to, the counters (steps, rejected,
    evaluations, outputs from the interpolant) and the state (q, q̇) the status refers to (where
    a stage failed, for a failed run) and the message of a run the branch watch ended ("" else)."""

    records: tuple
    recorded: int
    status: int
    t_stop: float
    steps: int
    rejected: int
    evaluations: int
    unsolved: int
    state: np.ndarray
    message: str


def adaptive(model: NamedTuple, formulation: NamedTuple, q0: np.ndarray, qd0: np.ndarray, t_out: np.ndarray,
             rtol: float, atol: float, u: np.ndarray, buffer_size: int, m: int, tableau: Tableau,
             adjusts_state: bool, max_steps: int = MAX_STEPS) -> AdaptiveRun:
    """Integrate from t_out[0] to t_out[-1] by ``tableau`` (the controller's exponent
    1/(min(p, p̂) + 1), the starting step's 1/(p + 1), DOP853's second error estimate and
    continuous extension, FSAL unless the formulation ``adjusts_state`` after each step, as the
    Python loop)."""
    method = loop_method(tableau, adjusts_state)
    times = np.ascontiguousarray(t_out, dtype=float)
    y, y_new, k1, stages, counts, where, buffer, records = run_arrays(
        np.asarray(q0, dtype=float), np.asarray(qd0, dtype=float), times, m, method[0], method[6], buffer_size)
    watch = interpreted(watch_array)(q0.shape[0], m)
    status, t_stop = _steps(model, formulation, y, y_new, k1, stages, counts, where, records, buffer, times,
                            float(rtol), float(atol), u, *method, int(max_steps), watch)
    message = jump_message(watch) if status == LEFT_BRANCH else ""
    return AdaptiveRun(records, int(counts[0]), int(status), float(t_stop), int(counts[1]), int(counts[2]),
                       int(counts[3]), int(counts[4]), where, message)


def loop_method(tableau: Tableau, adjusts_state: bool) -> tuple:
    """The method as :func:`_steps` takes it: :func:`_method_arrays`, then the controller's
    exponent 1/(min(p, p̂) + 1), the starting step's 1/(p + 1) and whether to use FSAL (not when
    the formulation ``adjusts_state`` after each step)."""
    return (*_method_arrays(tableau), 1.0 / (min(tableau.order, tableau.error_order) + 1), 1.0 / (tableau.order + 1),
            bool(tableau.first_same_as_last and not adjusts_state))


def run_arrays(q0, qd0, t_out, m, c, dense_c, buffer_size):
    """The arrays of an adaptive run from (q0, q̇0) with outputs at ``t_out`` and a method with
    the nodes ``c`` and the continuous extension's ``dense_c``: the state y = (q, q̇), the step's
    new state, the derivative at y, the stages (the step's, then the extension's), the counts of
    :func:`_steps`, the state of a failure, the terms buffer and the records."""
    n = q0.shape[0]
    d = 2 * n
    count = t_out.shape[0]
    records = (np.zeros(count), np.zeros((count, n)), np.zeros((count, n)), np.zeros((count, n)),
               np.zeros((count, m)), np.zeros(count), np.zeros(count), np.zeros((count, n)))
    y = np.concatenate((q0, qd0))
    stages = np.zeros((c.shape[0] + dense_c.shape[0], d))
    counts = np.zeros(5, dtype=np.int64)   # outputs recorded, steps, rejected, evaluations, from the interpolant
    return y, np.zeros(d), np.zeros(d), stages, counts, np.zeros(d), np.zeros(buffer_size), records


def _method_arrays(tableau: Tableau) -> tuple[np.ndarray, ...]:
    """The arrays of ``tableau`` the loop takes: c, a, b, b̂ (error weights), the second error
    estimate, the continuous extension's (a, c, d); empty where the method has none."""
    low = tableau.b_error_low if tableau.b_error_low is not None else np.zeros(0)
    dense = tableau.dense
    extension = (np.zeros((0, 0)), np.zeros(0), np.zeros((0, 0))) if dense is None else (dense.a, dense.c, dense.d)
    return tuple(np.ascontiguousarray(array, dtype=float) for array in
                 (tableau.c, tableau.a, tableau.b, tableau.b_error, low, *extension))


@njit(cache=True, nogil=True)
def _steps(model, formulation, y, y_new, k1, stages, counts, where, records, buffer, t_out, rtol, atol, u, c, a, b,
           b_error, b_error_low, dense_a, dense_c, dense_d, exponent, start_exponent, first_same_as_last, max_steps,
           watch):
    """The loop of :func:`adaptive` from the state ``y`` at t_out[0], into ``counts`` = (outputs
    recorded, steps, rejected, evaluations, outputs from the interpolant): it evaluates the
    derivative ``k1`` there, records t_out[0], chooses the starting step and steps to t_out[-1].
    The branch watch (:mod:`cmbs.integrate.continuity`) sees each accepted state with its
    derivative, and ends the run (LEFT_BRANCH) where the motion left its branch, the outputs
    after the jump's start dropped.  Returns the status and the time it refers to; a failed
    stage's state in ``where``."""
    model, formulation, y, y_new, k1, stages, counts, where, records, buffer, u, watch = borrow(
        (model, formulation, y, y_new, k1, stages, counts, where, records, buffer, u, watch))
    d = y.shape[0]
    n = d // 2
    T, Qs, QDs, QDDs, LAMs, PHI, PHID, FORCE = records
    m = LAMs.shape[1]
    count = t_out.shape[0]
    terms = terms_views(model, n, m, buffer)
    lam = np.empty(m)
    s = c.shape[0]
    extra = dense_c.shape[0]
    F = np.zeros((3 + dense_d.shape[0], d))
    low, value, slope, state = np.empty(d), np.empty(d), np.empty(d), np.empty(d)
    work, k_new, scale = np.empty(d), np.empty(d), np.empty(d)
    next_out, steps, rejected, evaluations, unsolved = 0, 0, 0, 0, 0
    t, h, factor_old = t_out[0], 0.0, 1e-4
    t_end = t_out[count - 1]
    t_stop = t
    status = _rhs(model, formulation, y, t, u, buffer, terms, lam, state, k1)
    evaluations += 1
    if status != OK:
        _copy(state, where)
    else:
        left_branch(watch, t, y[n:], k1[n:], terms[2])     # the first state starts the watch
        unsolved += _record(model, formulation, t, y, k1, u, buffer, terms, next_out, T, Qs, QDs, QDDs, LAMs, PHI,
                            PHID, FORCE)
        next_out += 1
        # Hairer & Wanner's starting step (Solving ODEs I, §II.4), as the Python loop
        for i in range(d):
            scale[i] = atol + abs(y[i]) * rtol
        d0, d1 = _rms(y, scale), _rms(k1, scale)
        h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
        h0 = min(h0, t_end - t)
        for i in range(d):
            work[i] = y[i] + h0 * k1[i]
        _rhs(model, formulation, work, t + h0, u, buffer, terms, lam, state, k_new)
        evaluations += 1
        for i in range(d):
            work[i] = k_new[i] - k1[i]
        d2 = _rms(work, scale) / h0
        h1 = max(1e-6, h0 * 1e-3) if max(d1, d2) <= 1e-15 else (0.01 / max(d1, d2)) ** start_exponent
        h = min(100.0 * h0, h1, t_end - t)
    while status == OK and next_out < count:
        if steps >= max_steps:
            status, t_stop = TOO_MANY_STEPS, t
            break
        h_try = min(h, t_end - t)
        for i in range(d):
            stages[0, i] = k1[i]
        finite = True
        for i in range(1, s):
            _combination(y, h_try, a[i], stages, i, work)
            status = _rhs(model, formulation, work, t + c[i] * h_try, u, buffer, terms, lam, state, stages[i])
            evaluations += 1
            if status != OK:
                t_stop = t + c[i] * h_try
                break
        if status == NON_FINITE or (status == SINGULAR and h_try > 1e-14 * max(1.0, abs(t))):
            # retried with a smaller step below: a trial stage may leave the constraints far enough
            # to lose rank (as the Python loop's retry_on); a singular stage of a step that would
            # underflow ends the run
            status = OK
            finite = False
        elif status != OK:              # a singular stage, or its hook failed: the run ends
            _copy(state, where)
            break
        if finite:
            _combination(y, h_try, b, stages, s, y_new)
            for i in range(d):
                if not math.isfinite(y_new[i]):
                    finite = False
        if not finite:
            if h_try > 1e-14 * max(1.0, abs(t)):
                h = h_try / 10.0
                rejected += 1
                continue
            status, t_stop = NON_FINITE, t + h_try
            _copy(y, where)
            break
        for i in range(d):
            scale[i] = atol + rtol * max(abs(y[i]), abs(y_new[i]))
        error = _error_norm(h_try, b_error, b_error_low, stages, s, scale, work, low)
        if error > 1.0:
            h = h_try * max(0.2, 0.9 * error ** -exponent)
            rejected += 1
            if h < 1e-14 * max(1.0, abs(t)):
                status, t_stop = UNDERFLOW, t
                _copy(y, where)
                break
            continue
        error = max(error, 1e-10)
        growth = 0.9 * error ** (-0.7 * exponent) * factor_old ** (0.4 * exponent)
        h = h_try * min(5.0, max(0.2, growth))
        factor_old = error
        status = after_step(formulation, model, y_new[:n], y_new[n:], t + h_try, buffer)
        if status != OK:
            t_stop = t + h_try
            _copy(y_new, where)
            break
        t_new = t + h_try
        if first_same_as_last:
            for i in range(d):
                k_new[i] = stages[s - 1, i]
        else:                               # the after-step hook's state: the stage hook leaves it
            status = _rhs(model, formulation, y_new, t_new, u, buffer, terms, lam, state, k_new, False)
            evaluations += 1
            if status == NON_FINITE:        # as the Python loop: the next step meets it
                status = OK
            elif status != OK:
                t_stop = t_new
                _copy(state, where)
                break
        steps += 1
        if left_branch(watch, t_new, y_new[n:], k_new[n:], terms[2]):
            status, t_stop = LEFT_BRANCH, t_new
            next_out = kept_records(T, next_out, watch)
            break
        if extra > 0 and next_out < count and t_out[next_out] <= t_new + 1e-12 * max(1.0, abs(t_new)):
            for i in range(extra):              # the continuous extension's stages
                _combination(y, h_try, dense_a[i], stages, s + i, work)
                status = _rhs(model, formulation, work, t + dense_c[i] * h_try, u, buffer, terms, lam, state,
                              stages[s + i])
                evaluations += 1
                if status != OK:
                    t_stop = t + dense_c[i] * h_try
                    _copy(state, where)
                    break
            if status != OK:
                break
            _dense_coefficients(y, y_new, k1, k_new, h_try, dense_d, stages, F)
        while next_out < count and t_out[next_out] <= t_new + 1e-12 * max(1.0, abs(t_new)):
            x = (t_out[next_out] - t) / h_try
            if extra > 0:
                _dense_value(F, y, x, h_try, value, slope)
            else:
                _hermite(y, k1, y_new, k_new, x, h_try, value, slope)
            unsolved += _record(model, formulation, t_out[next_out], value, slope, u, buffer, terms, next_out, T, Qs,
                                QDs, QDDs, LAMs, PHI, PHID, FORCE)
            next_out += 1
        t = t_new
        t_stop = t
        _copy(y_new, y)
        _copy(k_new, k1)
    counts[0], counts[1], counts[2], counts[3], counts[4] = next_out, steps, rejected, evaluations, unsolved
    return status, t_stop


@njit(cache=True)
def _copy(source, target):
    """target = source, element by element."""
    for i in range(source.shape[0]):
        target[i] = source[i]


@njit(cache=True)
def _error_norm(h, b_error, b_error_low, stages, s, scale, work, low):
    """The scaled error of a step (:func:`cmbs.integrate.explicit.error_norm`): the RMS of
    h Σ b̂_i k_i / scale, or DOP853's combined norm when ``b_error_low`` is not empty."""
    d = scale.shape[0]
    for i in range(d):
        work[i] = 0.0
    if b_error_low.shape[0] == 0:
        _add_stages(h, b_error, stages, s, work)
        return _rms(work, scale)
    for i in range(d):
        low[i] = 0.0
    _add_stages(1.0, b_error, stages, s, work)
    _add_stages(1.0, b_error_low, stages, s, low)
    high_sum, low_sum = 0.0, 0.0
    for i in range(d):
        high_sum += (work[i] / scale[i]) ** 2
        low_sum += (low[i] / scale[i]) ** 2
    denominator = high_sum + 0.01 * low_sum
    return 0.0 if denominator == 0.0 else abs(h) * high_sum / math.sqrt(denominator * d)


@njit(cache=True)
def _hermite(y, k1, y_new, k_new, x, h, value, slope):
    """Value and derivative at x = (t - t_n)/h of the cubic Hermite interpolant on [t_n, t_n + h]."""
    h00, h10 = 2 * x**3 - 3 * x**2 + 1, x**3 - 2 * x**2 + x
    h01, h11 = -2 * x**3 + 3 * x**2, x**3 - x**2
    d00, d10 = (6 * x**2 - 6 * x) / h, 3 * x**2 - 4 * x + 1
    d01, d11 = (-6 * x**2 + 6 * x) / h, 3 * x**2 - 2 * x
    for i in range(y.shape[0]):
        value[i] = h00 * y[i] + h10 * h * k1[i] + h01 * y_new[i] + h11 * h * k_new[i]
        slope[i] = d00 * y[i] + d10 * k1[i] + d01 * y_new[i] + d11 * k_new[i]


#: reasons of the failure statuses, for messages
REASONS = {UNDERFLOW: "step size underflow", TOO_MANY_STEPS: "step limit reached",
           NON_FINITE: "the state became non-finite"}
