"""Runge-Kutta tableaus as plain data (Hairer, Nørsett & Wanner, Solving ODEs I, §II.1-II.5).

``b_error`` holds b - b̂ (the difference between the propagating solution and the embedded one),
so the local error estimate is h Σ (b - b̂)_i k_i.  ``first_same_as_last`` (FSAL): the last stage
is evaluated at the new point and is the next step's first stage.

DOP853 (Dormand & Prince's 8th-order pair, Hairer, Nørsett & Wanner §II.10) also has a 3rd-order
estimate ``b_error_low`` for its combined error norm and a 7th-order dense output (``dense``):
three more stages and the interpolation weights.  Its coefficients are read from scipy, which
ships them with its own DOP853 (``scipy.integrate._ivp.dop853_coefficients``, Hairer's dop853.f).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Tableau:
    """Butcher tableau: nodes ``c`` (s,), matrix ``a`` (s, s), weights ``b`` (s,), error weights
    ``b_error`` (s,) or None for fixed-step methods, the order of ``b`` and of the embedded
    estimate."""

    name: str
    c: np.ndarray
    a: np.ndarray
    b: np.ndarray
    b_error: np.ndarray | None
    order: int
    error_order: int
    first_same_as_last: bool
    b_error_low: np.ndarray | None = None
    dense: "DenseOutput | None" = None


@dataclass(frozen=True)
class DenseOutput:
    """Continuous extension of a step (Hairer, Nørsett & Wanner §II.6): ``extra`` more stages,
    stage i at t + c_i h from y + h Σ_j a_ij k_j over all the stages before it (``a`` (e, s + e),
    ``c`` (e,)), and the weights ``d`` (p - 3, s + e) of the interpolant's upper coefficients
    (:func:`cmbs.integrate.explicit.dense_coefficients`)."""

    a: np.ndarray
    c: np.ndarray
    d: np.ndarray


def _tableau(name, c, a, b, b_hat, order, error_order, fsal):
    b = np.array(b, dtype=float)
    return Tableau(name, np.array(c, dtype=float), np.array(a, dtype=float), b,
                   None if b_hat is None else b - np.array(b_hat, dtype=float), order, error_order, fsal)


RK4 = _tableau(
    "rk4", [0, 0.5, 0.5, 1],
    [[0, 0, 0, 0], [0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 1, 0]],
    [1 / 6, 1 / 3, 1 / 3, 1 / 6], None, 4, 4, False)

# Bogacki & Shampine (1989): 3rd order with a 2nd-order estimate, FSAL (MATLAB ode23)
RK23 = _tableau(
    "rk23", [0, 1 / 2, 3 / 4, 1],
    [[0, 0, 0, 0], [1 / 2, 0, 0, 0], [0, 3 / 4, 0, 0], [2 / 9, 1 / 3, 4 / 9, 0]],
    [2 / 9, 1 / 3, 4 / 9, 0], [7 / 24, 1 / 4, 1 / 3, 1 / 8], 3, 2, True)

# Dormand & Prince (1980): 5th order with a 4th-order estimate, FSAL (MATLAB ode45)
RK45 = _tableau(
    "rk45", [0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1, 1],
    [[0, 0, 0, 0, 0, 0, 0],
     [1 / 5, 0, 0, 0, 0, 0, 0],
     [3 / 40, 9 / 40, 0, 0, 0, 0, 0],
     [44 / 45, -56 / 15, 32 / 9, 0, 0, 0, 0],
     [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0, 0, 0],
     [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656, 0, 0],
     [35 / 384, 0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0]],
    [35 / 384, 0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0],
    [5179 / 57600, 0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40], 5, 4, True)

TABLEAUS = {tableau.name: tableau for tableau in (RK4, RK23, RK45)}
#: every explicit method by name (DOP853 built on first use: importing scipy.integrate takes 0.5 s)
NAMES = (*TABLEAUS, "dop853")


@functools.cache
def dop853() -> Tableau:
    """Dormand & Prince (1980), DOP853: 8th order, error estimates of orders 5 and 3, 7th-order
    dense output; written as 13 stages with the last evaluated at the new point (FSAL)."""
    from scipy.integrate._ivp import dop853_coefficients as coefficients

    stages = coefficients.N_STAGES + 1
    return Tableau("dop853", coefficients.C[:stages].copy(), coefficients.A[:stages, :stages].copy(),
                   np.concatenate([coefficients.B, [0.0]]), coefficients.E5.copy(), 8, 7, True,
                   b_error_low=coefficients.E3.copy(),
                   dense=DenseOutput(coefficients.A[stages:].copy(), coefficients.C[stages:].copy(),
                                     coefficients.D.copy()))


def tableau(name: str) -> Tableau:
    """The explicit method ``name`` (one of :data:`NAMES`)."""
    return dop853() if name == "dop853" else TABLEAUS[name]
