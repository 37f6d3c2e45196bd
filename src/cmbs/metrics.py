"""Pure functions measuring runs (THEORY §5; thesis ch. 6-7; Aghili 2005 Tables I-II).

All take time-major arrays: times t (k,), signals (k,) or (k, j).  Integrals use the trapezoidal
rule over the given samples.
"""

from __future__ import annotations

import numpy as np

from cmbs.errors import CmbsError


def _check(t: np.ndarray, *signals: np.ndarray) -> None:
    if t.ndim != 1 or t.size < 2 or np.any(np.diff(t) <= 0):
        raise CmbsError("metrics: times must be a strictly increasing 1-D array of at least 2 samples")
    for signal in signals:
        if signal.shape[0] != t.size:
            raise CmbsError(f"metrics: a signal has {signal.shape[0]} samples for {t.size} times")


def rmse(t: np.ndarray, value: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Root-mean-square error over time, sqrt(1/T ∫ (x - x_ref)² dt), per column."""
    t, value, reference = (np.asarray(a, dtype=float) for a in (t, value, reference))
    _check(t, value, reference)
    error = value - reference
    return np.sqrt(np.trapezoid(error**2, t, axis=0) / (t[-1] - t[0]))


def nrmse(t: np.ndarray, value: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """RMSE divided by the range of the reference (max - min), per column (thesis ch. 6)."""
    reference = np.asarray(reference, dtype=float)
    spread = np.ptp(reference, axis=0)
    if np.any(spread == 0):
        raise CmbsError("metrics: the reference has zero range; NRMSE is undefined")
    return rmse(t, value, reference) / spread


def settling_time(t: np.ndarray, error: np.ndarray, *, fraction: float = 0.01) -> float:
    """First time after which |error| stays within ``fraction`` of its initial magnitude (1 % by
    default); the largest over columns; ``inf`` if it never settles within the samples."""
    t, error = np.asarray(t, dtype=float), np.abs(np.asarray(error, dtype=float))
    _check(t, error)
    error = error.reshape(t.size, -1)
    band = fraction * np.max(error[0])
    if band == 0:
        return float(t[0])
    outside = np.flatnonzero(np.any(error > band, axis=1))
    if outside.size == 0:
        return float(t[0])
    if outside[-1] == t.size - 1:
        return float("inf")
    return float(t[outside[-1] + 1])


def rms_norm(t: np.ndarray, u: np.ndarray) -> float:
    """RMS norm of a vector signal, sqrt(1/T ∫ uᵀu dt) (Aghili 2005, Table I footnote)."""
    t, u = np.asarray(t, dtype=float), np.asarray(u, dtype=float).reshape(len(t), -1)
    _check(t, u)
    return float(np.sqrt(np.trapezoid(np.sum(u**2, axis=1), t) / (t[-1] - t[0])))


def peak_norm(u: np.ndarray) -> float:
    """Peak norm sup_t max_i |u_i(t)| (Aghili 2005, Table II)."""
    return float(np.max(np.abs(np.asarray(u, dtype=float)), initial=0.0))


def constraint_force_error(t: np.ndarray, lam: np.ndarray, desired: np.ndarray) -> float:
    """RMS norm of the constraint-force error, sqrt(1/T ∫ |λ - λ_d|² dt) (Aghili 2005 §VII-B:
    the force loop regulates λ to λ_d); ``desired`` (k, m) or (m,) held constant."""
    lam = np.asarray(lam, dtype=float).reshape(len(t), -1)
    desired = np.broadcast_to(np.asarray(desired, dtype=float), lam.shape)
    return rms_norm(t, lam - desired)
