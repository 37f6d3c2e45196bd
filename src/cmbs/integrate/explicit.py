"""Explicit Runge-Kutta integration of y' = f(t, y): the stepping rule (a tableau) and the
step-size policy (fixed, or the PI controller of Hairer & Wanner, Solving ODEs I §II.4 and
Gustafsson 1991) kept apart.

After every accepted step an optional ``after_step(t, y) -> y`` may change the state (drift
projection, recovery of dependent coordinates); the derivative at the new point is then
re-evaluated.  Output is at the times of ``t_out``, by cubic Hermite interpolation between the
steps' end points and derivatives (dense output, O(h⁴)), by the method's own continuous
extension where it has one (DOP853: 7th order, three more evaluations in a step with outputs),
or exactly at the steps for a fixed step equal to the output interval; a fixed-step run may keep
only every k-th of those outputs (``keep_every``), and stores only those.  Failures come back as a status, never as a swallowed
exception.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from cmbs.integrate.tableaus import Tableau

VectorField = Callable[[float, np.ndarray], np.ndarray]
AfterStep = Callable[[float, np.ndarray], np.ndarray]
#: ``watch(t, y, y')`` at each accepted state: None, or (t_from, message) to end the run as failed
#: with the outputs after t_from dropped (:class:`cmbs.integrate.continuity.BranchWatch`).
Watch = Callable[[float, np.ndarray, np.ndarray], "tuple[float, str] | None"]


@dataclass
class Integration:
    """Result: output times ``t`` (k,), states ``y`` (k, d), derivatives ``dy`` (k, d), the
    status (``"success"`` or ``"failed"``), a message and counters."""

    t: np.ndarray
    y: np.ndarray
    dy: np.ndarray
    status: str
    message: str
    counters: dict = field(default_factory=dict)


def _step(f: VectorField, tableau: Tableau, t: float, y: np.ndarray, h: float, k1: np.ndarray,
          stages: np.ndarray) -> np.ndarray:
    """One Runge-Kutta step; fills ``stages`` (s, d) and returns y_{n+1}."""
    stages[0] = k1
    a, c = tableau.a, tableau.c
    for i in range(1, len(c)):
        stages[i] = f(t + c[i] * h, y + h * (a[i, :i] @ stages[:i]))
    return y + h * (tableau.b @ stages)


def _hermite(t0: float, y0: np.ndarray, f0: np.ndarray, t1: float, y1: np.ndarray, f1: np.ndarray,
             times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cubic Hermite values and derivatives at ``times`` in [t0, t1]."""
    h = t1 - t0
    s = ((times - t0) / h)[:, None]
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    d00, d10, d01, d11 = (6 * s**2 - 6 * s) / h, 3 * s**2 - 4 * s + 1, (-6 * s**2 + 6 * s) / h, 3 * s**2 - 2 * s
    values = h00 * y0 + h10 * h * f0 + h01 * y1 + h11 * h * f1
    slopes = d00 * y0 + d10 * f0 + d01 * y1 + d11 * f1
    return values, slopes


def integrate(f: VectorField, y0: np.ndarray, t_out: np.ndarray, *, tableau: Tableau, rtol: float = 1e-6,
              atol: float = 1e-9, step: float | None = None, after_step: AfterStep | None = None,
              max_steps: int = 10_000_000, progress: Callable[[float], None] | None = None,
              stop_on: tuple[type[Exception], ...] = (), retry_on: tuple[type[Exception], ...] = (),
              keep_every: int = 1, watch: Watch | None = None) -> Integration:
    """Integrate from ``t_out[0]`` through ``t_out[-1]``.

    Parameters
    ----------
    tableau
        The method; adaptive when it has an error estimate and ``step`` is None.
    rtol, atol
        Tolerances of the adaptive step-size controller: the scaled error
        ``‖e_i / (atol + rtol max(|y_i|, |y_new,i|))‖_RMS`` must be ≤ 1.
    step
        Fixed step (required for tableaus without error estimate).  The last step of each
        output interval is shortened to hit the output times exactly.
    stop_on
        Exception types raised by ``f`` or ``after_step`` that end the run with status
        ``"failed"`` and their message (the output computed so far is kept).
    retry_on
        Of those, the types that a stage of an adaptive step may raise because the step is too
        long (a singular system: a trial stage can leave the constraints far enough to lose
        rank): the step is tried again ten times shorter, as for a non-finite state, and the run
        ends only when the step would underflow.
    keep_every
        With a fixed ``step``: of the instants ``t_out`` (which the steps hit), keep only
        ``t_out[::keep_every]`` (whose last must be ``t_out[-1]``); the others are stepped through
        but not stored, so the kept outputs are those of the run that keeps all, bit for bit.
    watch
        Called with every accepted state (the first included) and its derivative; when it
        returns (t_from, message) the run ends as failed with that message, keeping the outputs
        up to t_from.
    """
    t_out = np.asarray(t_out, dtype=float)
    y = np.array(y0, dtype=float)
    d = y.size
    adaptive = step is None
    if adaptive and tableau.b_error is None:
        raise ValueError(f"{tableau.name} has no error estimate: give a fixed step")
    if keep_every != 1 and (adaptive or keep_every < 1 or (t_out.size - 1) % keep_every):
        raise ValueError(f"keep_every={keep_every} needs a fixed step and {t_out.size - 1} output intervals that "
                         "it divides")
    kept = t_out[::keep_every]
    out_y = np.zeros((kept.size, d))
    out_dy = np.zeros((kept.size, d))
    counters = {"steps": 0, "rejected": 0, "evaluations": 0}

    def field(t: float, state: np.ndarray) -> np.ndarray:
        counters["evaluations"] += 1
        return f(t, state)

    t = float(t_out[0])
    next_out = 0

    def fail(message: str, until: float = np.inf) -> Integration:
        stored = -(-next_out // keep_every)          # the kept instants before t_out[next_out]
        stored = min(stored, int(np.searchsorted(kept, until + 1e-12 * max(1.0, abs(until)), side="right")))
        return Integration(kept[:stored], out_y[:stored], out_dy[:stored], "failed", message, counters)

    try:
        k1 = field(t, y)
    except stop_on as error:
        return fail(str(error))
    out_y[0], out_dy[0] = y, k1
    if watch is not None:                           # the first state starts the watch
        watch(t, y, k1)
    stages = np.zeros((len(tableau.c), d))
    next_out = 1
    t_end = float(t_out[-1])
    h = step if step is not None else _initial_step(field, t, y, k1, tableau, rtol, atol, t_end)
    factor_old = 1e-4
    exponent = 1.0 / (min(tableau.order, tableau.error_order) + 1)

    while next_out < t_out.size:
        if counters["steps"] >= max_steps:
            return fail(f"step limit {max_steps} reached at t={t:.6g}")
        h_try = min(h, t_end - t)
        if not adaptive:
            h_try = min(h_try, t_out[next_out] - t) if t_out[next_out] - t > 1e-12 * max(1.0, abs(t)) else h_try
        try:
            y_new = _step(field, tableau, t, y, h_try, k1, stages)
        except stop_on as error:
            if adaptive and isinstance(error, retry_on) and h_try > 1e-14 * max(1.0, abs(t)):
                h = h_try / 10.0
                counters["rejected"] += 1
                continue
            return fail(str(error))
        if not np.all(np.isfinite(y_new)):
            if adaptive and h_try > 1e-14 * max(1.0, abs(t)):
                h = h_try / 10.0
                counters["rejected"] += 1
                continue
            return fail(f"the state became non-finite at t={t + h_try:.6g}")
        if adaptive:
            scale = atol + rtol * np.maximum(np.abs(y), np.abs(y_new))
            error = error_norm(tableau, stages, h_try, scale)
            if error > 1.0:
                h = h_try * max(0.2, 0.9 * error**-exponent)
                counters["rejected"] += 1
                if h < 1e-14 * max(1.0, abs(t)):
                    return fail(f"step size underflow at t={t:.6g} (error estimate {error:.3g})")
                continue
            # PI controller (Gustafsson): beta = 0.4/(order+1)
            error = max(error, 1e-10)
            growth = 0.9 * error**(-0.7 * exponent) * factor_old**(0.4 * exponent)
            h = h_try * min(5.0, max(0.2, growth))
            factor_old = error
        t_new = t + h_try
        try:
            if after_step is not None:
                y_new = after_step(t_new, y_new)
            k_new = stages[-1].copy() if (tableau.first_same_as_last and after_step is None) \
                else field(t_new, y_new)
        except stop_on as error:
            return fail(str(error))
        counters["steps"] += 1
        left = watch(t_new, y_new, k_new) if watch is not None else None
        if left is not None:
            return fail(left[1], left[0])
        while next_out < t_out.size and t_out[next_out] <= t_new + 1e-12 * max(1.0, abs(t_new)):
            end = next_out
            while end < t_out.size and t_out[end] <= t_new + 1e-12 * max(1.0, abs(t_new)):
                end += 1
            rows = np.arange(-(-next_out // keep_every), -(-end // keep_every))   # kept rows in [next_out, end)
            next_out = end
            if rows.size == 0:
                continue
            if tableau.dense is None:
                values, slopes = _hermite(t, y, k1, t_new, y_new, k_new, kept[rows])
            else:
                try:
                    coefficients = dense_coefficients(field, tableau, t, y, h_try, y_new, k_new, stages)
                except stop_on as error:
                    return fail(str(error))
                values, slopes = _dense(coefficients, t, y, h_try, kept[rows])
            out_y[rows], out_dy[rows] = values, slopes
        t, y, k1 = t_new, y_new, k_new
        if progress is not None:
            progress(t)
    return Integration(kept, out_y, out_dy, "success", "", counters)


def error_norm(tableau: Tableau, stages: np.ndarray, h: float, scale: np.ndarray) -> float:
    """The scaled error of a step: ‖h Σ e_i k_i / scale‖_RMS, or for a tableau with a second,
    low-order estimate (DOP853; Hairer, Nørsett & Wanner §II.10, as dop853.f and scipy)
    h ‖e5‖² / √(N (‖e5‖² + 0.01 ‖e3‖²)) with e5 = Σ b_error_i k_i / scale and e3 likewise."""
    if tableau.b_error_low is None:
        return float(np.sqrt(np.mean((h * (tableau.b_error @ stages) / scale) ** 2)))
    high = float(np.sum(((tableau.b_error @ stages) / scale) ** 2))
    low = float(np.sum(((tableau.b_error_low @ stages) / scale) ** 2))
    denominator = high + 0.01 * low
    return 0.0 if denominator == 0.0 else abs(h) * high / np.sqrt(denominator * scale.size)


def dense_coefficients(f: VectorField, tableau: Tableau, t: float, y: np.ndarray, h: float, y_new: np.ndarray,
                       f_new: np.ndarray, stages: np.ndarray) -> np.ndarray:
    """Coefficients F (p, d) of the continuous extension of the step from (t, y) to
    (t + h, y_new) (Hairer, Nørsett & Wanner §II.6; dop853.f's CONTD8): the extra stages, then
    F0 = Δy, F1 = h k1 - Δy, F2 = 2Δy - h (k1 + f_new), F3.. = h D K."""
    dense = tableau.dense
    count = stages.shape[0]
    extended = np.zeros((count + dense.c.size, y.size))
    extended[:count] = stages
    for i, (a, c) in enumerate(zip(dense.a, dense.c)):
        extended[count + i] = f(t + c * h, y + h * (a[:count + i] @ extended[:count + i]))
    delta = y_new - y
    upper = h * (dense.d @ extended)
    return np.vstack([delta, h * stages[0] - delta, 2.0 * delta - h * (stages[0] + f_new), upper])


def _dense(F: np.ndarray, t0: float, y0: np.ndarray, h: float, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values and derivatives at ``times`` of the continuous extension with coefficients F:
    y0 + F0 x + F1 x(1-x) + F2 x²(1-x) + F3 x²(1-x)² + ... (factors x and 1-x alternating),
    x = (t - t0)/h, evaluated inside out with its derivative."""
    values = np.empty((times.size, y0.size))
    slopes = np.empty((times.size, y0.size))
    for k, time in enumerate(times):
        x = (time - t0) / h
        value = np.zeros(y0.size)
        derivative = np.zeros(y0.size)
        for i, row in enumerate(F[::-1]):
            value = value + row
            if i % 2 == 0:
                derivative = derivative * x + value
                value = value * x
            else:
                derivative = derivative * (1.0 - x) - value
                value = value * (1.0 - x)
        values[k] = y0 + value
        slopes[k] = derivative / h
    return values, slopes


def _initial_step(f: VectorField, t: float, y: np.ndarray, f0: np.ndarray, tableau: Tableau, rtol: float,
                  atol: float, t_end: float) -> float:
    """Hairer & Wanner's starting step (Solving ODEs I, §II.4)."""
    scale = atol + np.abs(y) * rtol
    d0, d1 = np.sqrt(np.mean((y / scale) ** 2)), np.sqrt(np.mean((f0 / scale) ** 2))
    h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    h0 = min(h0, t_end - t)
    f1 = f(t + h0, y + h0 * f0)
    d2 = np.sqrt(np.mean(((f1 - f0) / scale) ** 2)) / h0
    h1 = max(1e-6, h0 * 1e-3) if max(d1, d2) <= 1e-15 else (0.01 / max(d1, d2)) ** (1.0 / (tableau.order + 1))
    return float(min(100 * h0, h1, t_end - t))
