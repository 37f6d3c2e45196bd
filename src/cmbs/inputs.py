"""Inputs given as samples: u(t) interpolated at the solver's times (THEORY §4: reference data at
fixed samples must be interpolated, linearly or by a spline)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cmbs.errors import CmbsError
from cmbs.lazy import on_first_use

interpolate = on_first_use("scipy.interpolate")


@dataclass(frozen=True)
class SampledInput:
    """u(t) from samples ``values`` (k, n_u) at ``times`` (k,), ``"linear"`` or ``"spline"``
    (cubic, not-a-knot); held at the end values outside the sampled range.  Callable as
    u(t, q, q̇) like any input function of :func:`cmbs.simulate`."""

    times: np.ndarray
    values: np.ndarray
    interpolation: str = "linear"
    _spline: object = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        times = np.asarray(self.times, dtype=float).ravel()
        values = np.asarray(self.values, dtype=float)
        values = values.reshape(times.size, -1) if values.size == times.size or values.ndim == 1 else values
        if values.shape[0] != times.size:
            raise CmbsError(f"sampled input: {times.size} times but {values.shape[0]} rows of values")
        if times.size < 2 or np.any(np.diff(times) <= 0):
            raise CmbsError("sampled input: times must be at least 2 and strictly increasing")
        if not (np.all(np.isfinite(times)) and np.all(np.isfinite(values))):
            raise CmbsError("sampled input: non-finite time or value")
        if self.interpolation not in ("linear", "spline"):
            raise CmbsError(f"sampled input: interpolation must be 'linear' or 'spline', got {self.interpolation!r}")
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "values", values)
        spline = interpolate.CubicSpline(times, values, axis=0) if self.interpolation == "spline" and times.size >= 4 else None
        if self.interpolation == "spline" and spline is None:
            raise CmbsError("sampled input: spline interpolation needs at least 4 samples")
        object.__setattr__(self, "_spline", spline)

    def __call__(self, t: float, q: np.ndarray | None = None, qd: np.ndarray | None = None) -> np.ndarray:
        t = min(max(t, self.times[0]), self.times[-1])
        if self._spline is not None:
            return np.asarray(self._spline(t), dtype=float)
        k = min(max(int(np.searchsorted(self.times, t, side="right")) - 1, 0), self.times.size - 2)
        s = (t - self.times[k]) / (self.times[k + 1] - self.times[k])
        return (1.0 - s) * self.values[k] + s * self.values[k + 1]
