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
"""

from __future__ import annotations

import math

import numpy as np

from cmbs.dynamics.base import NON_FINITE, OK, SINGULAR
from cmbs.dynamics.field import field
from cmbs.integrate.compiled_rk4 import record_constraints
from cmbs.model.compiled import terms_views
from cmbs.jit import njit

#: statuses besides OK, SINGULAR and NON_FINITE
UNDERFLOW, TOO_MANY_STEPS = 5, 6


@njit(cache=True, inline="always")
def _rhs(model, formulation, y, t, u, buffer, terms, lam, out):
    """dy/dt = (q̇, q̈) into ``out``; returns the field's status."""
    n = y.shape[0] // 2
    status = field(model, formulation, y[:n], y[n:], t, u, buffer, terms, out[n:], lam)
    for i in range(n):
        out[i] = y[n + i]
    return status


@njit(cache=True)
def _rms(values, scale):
    total = 0.0
    for i in range(values.shape[0]):
        total += (values[i] / scale[i]) ** 2
    return math.sqrt(total / values.shape[0])


@njit(cache=True, inline="always")
def _record(model, formulation, t, y, slope, u, buffer, terms, k, T, Qs, QDs, QDDs, LAMs, PHI, PHID, FORCE):
    """Row ``k`` of the outputs at (t, y); returns 1 when the state was singular (q̈ from the
    interpolant's slope, λ = 0), else 0."""
    n = y.shape[0] // 2
    m = LAMs.shape[1]
    lam = np.zeros(m)
    qdd = np.empty(n)
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


@njit(cache=True)
def adaptive(model, formulation, q0, qd0, t_out, rtol, atol, u, buffer_size, m, c, a, b, b_error, exponent, start_exponent, first_same_as_last, max_steps, b_error_low, dense_a,
             dense_c, dense_d):
    """Integrate from t_out[0] to t_out[-1] with the tableau (c, a, b, b_error), the controller's
    exponent 1/(min(p, p̂) + 1) and the starting step's 1/(p + 1); ``b_error_low`` (empty if
    none) the second error estimate and (dense_a, dense_c, dense_d) the continuous extension
    (empty: cubic Hermite) of :class:`~cmbs.integrate.tableaus.Tableau`; returns the
    outputs (t, q, q̇, q̈, λ, |Φ|, |Φ̇|, -Aᵀλ), the number recorded, the status, the time
    reached, the counters (steps, rejected, evaluations, outputs from the interpolant) and the
    state (q, q̇) the status refers to (where a stage failed, for a failed run)."""
    n = q0.shape[0]
    d = 2 * n
    count = t_out.shape[0]
    T, Qs, QDs, QDDs = np.zeros(count), np.zeros((count, n)), np.zeros((count, n)), np.zeros((count, n))
    LAMs, PHI, PHID, FORCE = np.zeros((count, m)), np.zeros(count), np.zeros(count), np.zeros((count, n))
    buffer = np.zeros(buffer_size)
    terms = terms_views(model, n, m, buffer)
    lam = np.empty(m)
    s = c.shape[0]
    extra = dense_c.shape[0]
    stages = np.zeros((s + extra, d))       # the step's stages, then the continuous extension's
    F = np.zeros((3 + dense_d.shape[0], d))
    low = np.empty(d)
    value = np.empty(d)
    slope = np.empty(d)
    y = np.empty(d)
    for i in range(n):
        y[i] = q0[i]
        y[n + i] = qd0[i]
    k1 = np.empty(d)
    steps, rejected, evaluations, unsolved = 0, 0, 0, 0
    t = t_out[0]
    status = _rhs(model, formulation, y, t, u, buffer, terms, lam, k1)
    evaluations += 1
    if status != OK:
        return T, Qs, QDs, QDDs, LAMs, PHI, PHID, FORCE, 0, status, t, steps, rejected, evaluations, unsolved, y
    next_out = np.int64(0)   # not a literal 0: numba would compile _record once more for each constant
    unsolved += _record(model, formulation, t, y, k1, u, buffer, terms, next_out, T, Qs, QDs, QDDs, LAMs, PHI, PHID,
                        FORCE)
    next_out += 1
    t_end = t_out[count - 1]
    # Hairer & Wanner's starting step (Solving ODEs I, §II.4), as the Python loop
    scale = atol + np.abs(y) * rtol
    d0, d1 = _rms(y, scale), _rms(k1, scale)
    h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    h0 = min(h0, t_end - t)
    probe = np.empty(d)
    status = _rhs(model, formulation, y + h0 * k1, t + h0, u, buffer, terms, lam, probe)
    evaluations += 1
    d2 = _rms(probe - k1, scale) / h0
    h1 = max(1e-6, h0 * 1e-3) if max(d1, d2) <= 1e-15 else (0.01 / max(d1, d2)) ** start_exponent
    h = min(100.0 * h0, h1, t_end - t)
    factor_old = 1e-4
    y_new = np.empty(d)
    k_new = np.empty(d)
    work = np.empty(d)
    while next_out < count:
        if steps >= max_steps:
            return T, Qs, QDs, QDDs, LAMs, PHI, PHID, FORCE, next_out, TOO_MANY_STEPS, t, steps, rejected, \
                evaluations, unsolved, y
        h_try = min(h, t_end - t)
        for i in range(d):
            stages[0, i] = k1[i]
        finite = True
        for i in range(1, s):
            _combination(y, h_try, a[i], stages, i, work)
            status = _rhs(model, formulation, work, t + c[i] * h_try, u, buffer, terms, lam, stages[i])
            evaluations += 1
            if status == SINGULAR:
                return T, Qs, QDs, QDDs, LAMs, PHI, PHID, FORCE, next_out, SINGULAR, t + c[i] * h_try, steps, \
                    rejected, evaluations, unsolved, work
            if status != OK:
                finite = False
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
            return T, Qs, QDs, QDDs, LAMs, PHI, PHID, FORCE, next_out, NON_FINITE, t + h_try, steps, rejected, \
                evaluations, unsolved, y
        for i in range(d):
            scale[i] = atol + rtol * max(abs(y[i]), abs(y_new[i]))
        if b_error_low.shape[0] == 0:
            work[:] = 0.0
            _add_stages(h_try, b_error, stages, s, work)
            error = _rms(work, scale)
        else:                                   # DOP853's combined norm
            work[:] = 0.0
            low[:] = 0.0
            _add_stages(1.0, b_error, stages, s, work)
            _add_stages(1.0, b_error_low, stages, s, low)
            high_sum, low_sum = 0.0, 0.0
            for i in range(d):
                high_sum += (work[i] / scale[i]) ** 2
                low_sum += (low[i] / scale[i]) ** 2
            denominator = high_sum + 0.01 * low_sum
            error = 0.0 if denominator == 0.0 else abs(h_try) * high_sum / math.sqrt(denominator * d)
        if error > 1.0:
            h = h_try * max(0.2, 0.9 * error ** -exponent)
            rejected += 1
            if h < 1e-14 * max(1.0, abs(t)):
                return T, Qs, QDs, QDDs, LAMs, PHI, PHID, FORCE, next_out, UNDERFLOW, t, steps, rejected, \
                    evaluations, unsolved, y
            continue
        error = max(error, 1e-10)
        growth = 0.9 * error ** (-0.7 * exponent) * factor_old ** (0.4 * exponent)
        h = h_try * min(5.0, max(0.2, growth))
        factor_old = error
        t_new = t + h_try
        if first_same_as_last:
            for i in range(d):
                k_new[i] = stages[s - 1, i]
        else:
            status = _rhs(model, formulation, y_new, t_new, u, buffer, terms, lam, k_new)
            evaluations += 1
            if status == SINGULAR:
                return T, Qs, QDs, QDDs, LAMs, PHI, PHID, FORCE, next_out, SINGULAR, t_new, steps, rejected, \
                    evaluations, unsolved, y_new
        steps += 1
        if extra > 0 and next_out < count and t_out[next_out] <= t_new + 1e-12 * max(1.0, abs(t_new)):
            for i in range(extra):              # the continuous extension's stages
                _combination(y, h_try, dense_a[i], stages, s + i, work)
                status = _rhs(model, formulation, work, t + dense_c[i] * h_try, u, buffer, terms, lam,
                              stages[s + i])
                evaluations += 1
                if status != OK:
                    return T, Qs, QDs, QDDs, LAMs, PHI, PHID, FORCE, next_out, status, t + dense_c[i] * h_try, \
                        steps, rejected, evaluations, unsolved, work
            _dense_coefficients(y, y_new, k1, k_new, h_try, dense_d, stages, F)
        while next_out < count and t_out[next_out] <= t_new + 1e-12 * max(1.0, abs(t_new)):
            x = (t_out[next_out] - t) / h_try
            if extra > 0:
                _dense_value(F, y, x, h_try, value, slope)
            else:                               # cubic Hermite on [t, t_new]
                h00, h10 = 2 * x**3 - 3 * x**2 + 1, x**3 - 2 * x**2 + x
                h01, h11 = -2 * x**3 + 3 * x**2, x**3 - x**2
                d00, d10 = (6 * x**2 - 6 * x) / h_try, 3 * x**2 - 4 * x + 1
                d01, d11 = (-6 * x**2 + 6 * x) / h_try, 3 * x**2 - 2 * x
                for i in range(d):
                    value[i] = h00 * y[i] + h10 * h_try * k1[i] + h01 * y_new[i] + h11 * h_try * k_new[i]
                    slope[i] = d00 * y[i] + d10 * k1[i] + d01 * y_new[i] + d11 * k_new[i]
            unsolved += _record(model, formulation, t_out[next_out], value, slope, u, buffer, terms, next_out, T, Qs,
                                QDs, QDDs, LAMs, PHI, PHID, FORCE)
            next_out += 1
        t = t_new
        for i in range(d):
            y[i] = y_new[i]
            k1[i] = k_new[i]
    return T, Qs, QDs, QDDs, LAMs, PHI, PHID, FORCE, next_out, OK, t, steps, rejected, evaluations, unsolved, y


#: reasons of the failure statuses, for messages
REASONS = {UNDERFLOW: "step size underflow", TOO_MANY_STEPS: "step limit reached",
           NON_FINITE: "the state became non-finite"}
