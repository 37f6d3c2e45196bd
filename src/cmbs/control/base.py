"""References and sampling shared by the controllers.

A controller is a callable ``u(t, q, q̇)`` that :func:`cmbs.simulate` calls with the state; it
sees the same model interface as everything else.  :class:`Reference` gives the desired
independent coordinates z_ref(t) with their first two derivatives, from a kinematic motion
(interpolated by a C² cubic spline) — typically the motion of the model's own drivers.
:class:`ZeroOrderHold` turns a continuous law into a digital controller sampled at a fixed
period (Aghili's experiment ran at 1 kHz): the input is computed at t = 0, T, 2T, ... and held
between samples, not re-evaluated at Runge-Kutta stages.
"""

from __future__ import annotations

import bisect

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from cmbs.errors import CmbsError
from cmbs.lazy import on_first_use
from cmbs.trajectory import Trajectory

interpolate = on_first_use("scipy.interpolate")

Law = Callable[[float, np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Reference:
    """Desired values of ``coordinates`` over time: z_ref(t), ż_ref(t), z̈_ref(t) from the motion's
    positions by a cubic spline (not-a-knot); held constant outside the motion's time span."""

    motion: Trajectory
    coordinates: tuple[str, ...]
    _spline: "interpolate.CubicSpline" = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        unknown = [name for name in self.coordinates if name not in self.motion.names]
        if unknown:
            raise CmbsError(f"reference: no coordinate(s) {', '.join(unknown)} in the motion "
                            f"({', '.join(self.motion.names)})")
        if self.motion.t.size < 4:
            raise CmbsError("reference: the motion needs at least 4 samples")
        columns = [self.motion.names.index(name) for name in self.coordinates]
        object.__setattr__(self, "coordinates", tuple(self.coordinates))
        object.__setattr__(self, "_spline", interpolate.CubicSpline(self.motion.t, self.motion.q[:, columns], axis=0))

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = min(max(t, self.motion.t[0]), self.motion.t[-1])
        return self._spline(t), self._spline(t, 1), self._spline(t, 2)


class ZeroOrderHold:
    """Sample ``law`` every ``period`` seconds and hold its value (a digital controller).

    The sample of instant t_k = k·period is taken at the first call with t ≥ t_k, with the state
    given in that call, and kept: a later call at any time in [t_k, t_{k+1}) — another stage, a
    retried step, or the recording of the run's inputs afterwards — returns that same value, so
    the recorded inputs are the applied ones.  Under RK4 with the step equal to the period the
    first call at t_k is the last stage of the step ending there, so the sample uses the stage's
    predicted state rather than the state the step reaches (a difference of order h⁴ in the
    state; 6e-5 rad over 2 s on the four-bar at 1 kHz against a hold fed the reached state).
    The compiled loop reproduces exactly this."""

    def __init__(self, law: Law, period: float):
        if not period > 0:
            raise CmbsError(f"sample period must be > 0, got {period}")
        self.law = law
        self.period = period
        self.samples: list[int] = []           # sample indices k taken so far, increasing
        self.values: list[np.ndarray] = []

    def reset(self) -> None:
        """Forget the samples (and reset the wrapped law if it keeps state), for a new run."""
        self.samples, self.values = [], []
        if hasattr(self.law, "reset"):
            self.law.reset()

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        k = int(np.floor(t / self.period + 1e-9))
        if not self.samples or k > self.samples[-1]:
            self.samples.append(k)
            self.values.append(np.array(self.law(t, q, qd), dtype=float))
            return self.values[-1]
        position = bisect.bisect_right(self.samples, k) - 1
        if position < 0:      # before the first sample taken: a new run started without reset()
            self.reset()
            return self(t, q, qd)
        return self.values[position]


def actuator_map(model, coordinates: Sequence[str]) -> np.ndarray:
    """(n_u, k) matrix B_z with u-to-generalized-force gains restricted to ``coordinates``: the
    generalized force on coordinate j from input i (measured from the model: Q(u = e_i) - Q(0))."""
    q, qd = model.q0, np.zeros(model.n)
    base = model.forces(q, qd, 0.0, np.zeros(model.n_u))
    columns = model.coordinate_indices(list(coordinates))
    gains = np.array([(model.forces(q, qd, 0.0, e) - base)[columns] for e in np.eye(model.n_u)])
    return gains


def gain_vector(value: float | Sequence[float], size: int, label: str) -> np.ndarray:
    """A scalar or per-coordinate gain as a (size,) array."""
    try:
        return np.broadcast_to(np.asarray(value, dtype=float), (size,)).copy()
    except ValueError:
        raise CmbsError(f"gain {label} must be a number or {size} numbers, got {value!r}") from None


def input_map(model, coordinates: Sequence[str]) -> np.ndarray:
    """(k, n_u) matrix turning generalized forces on ``coordinates`` into inputs u, after
    checking that the actuators can act on every one of them."""
    gains = actuator_map(model, coordinates)
    if np.linalg.matrix_rank(gains) < len(coordinates):
        raise CmbsError(f"model {model.name!r}: the actuators cannot act on every one of {', '.join(coordinates)}")
    return np.linalg.pinv(gains.T)
