"""Dense products and checks for the compiled solves of the penalty and Udwadia-Kalaba, written
out by hand.

The matrices of one evaluation are small (n ≤ a few dozen), where a call of LAPACK through numpy
costs more than the arithmetic.  These kernels work in place on arrays their caller owns (work
arrays allocated once per bound solver), compiled by :func:`cmbs.jit.njit` (plain Python
without numba).  The Cholesky factor and its triangular solves are those of
:mod:`cmbs.dynamics.kkt` with its dense profile (:data:`cmbs.dynamics.kkt.DENSE`).
"""

from __future__ import annotations

import numpy as np

from cmbs.dynamics.base import NON_FINITE, SINGULAR
from cmbs.jit import njit

#: The status of a compiled solve whose symmetric matrix to factor was not numerically positive
#: definite: the engine's SINGULAR (:mod:`cmbs.dynamics.base`; OK and NON_FINITE are its too).
NOT_POSITIVE_DEFINITE = SINGULAR


@njit(cache=True)
def add_scaled_gram(M: np.ndarray, A: np.ndarray, scale: float, out: np.ndarray) -> None:
    """out ← M + scale · AᵀA (lower triangle and diagonal; the upper triangle is not written)."""
    n = M.shape[0]
    for i in range(n):
        for j in range(i + 1):
            total = 0.0
            for k in range(A.shape[0]):
                total += A[k, i] * A[k, j]
            out[i, j] = M[i, j] + scale * total


@njit(cache=True)
def multiply(A: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    """out ← A x."""
    for i in range(A.shape[0]):
        total = 0.0
        for j in range(A.shape[1]):
            total += A[i, j] * x[j]
        out[i] = total


@njit(cache=True)
def multiply_transposed(A: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    """out ← Aᵀ x."""
    out[:] = 0.0
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            out[j] += A[i, j] * x[i]


@njit(cache=True, inline="always")
def copy_vector(source: np.ndarray, target: np.ndarray) -> None:
    """``target[:] = source`` element by element (a slice assignment compiles numba's formatted
    shape-mismatch error, about 2 s of a first compilation per array rank)."""
    for i in range(target.shape[0]):
        target[i] = source[i]


@njit(cache=True, inline="always")
def copy_matrix(source: np.ndarray, target: np.ndarray) -> None:
    """``target[:, :] = source`` element by element (see :func:`copy_vector`)."""
    for i in range(target.shape[0]):
        for j in range(target.shape[1]):
            target[i, j] = source[i, j]


@njit(cache=True)
def max_abs(x: np.ndarray) -> float:
    """max |x| over all entries (0 for an empty array; NaN when one is NaN)."""
    largest = 0.0
    for value in x.flat:
        size = abs(value)
        if size != size:
            return size
        largest = max(largest, size)
    return largest


@njit(cache=True)
def all_finite(x: np.ndarray) -> bool:
    """True when no entry of ``x`` is NaN or infinite."""
    for value in x.flat:
        if not np.isfinite(value):
            return False
    return True


@njit(cache=True)
def fill_nan(qdd: np.ndarray, lam: np.ndarray, force: np.ndarray) -> int:
    """Fill a solve's outputs with NaN; returns :data:`NON_FINITE`, the status of such a solve."""
    qdd[:] = np.nan
    lam[:] = np.nan
    force[:] = np.nan
    return NON_FINITE
