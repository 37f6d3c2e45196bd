"""PD control of independent coordinates (thesis ch. 6): ``τ = K_p e + K_d ė`` on the actuated
coordinates, e = z_ref - z, with an optional feed-forward of the inverse-dynamics force."""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from cmbs.control.base import Reference, gain_vector, input_map
from cmbs.model.model import Model


class PD:
    """u such that the generalized forces on ``reference.coordinates`` are K_p e + K_d ė
    (+ feed_forward(t)); K_p, K_d scalars or (k,) arrays."""

    def __init__(self, model: Model, reference: Reference, *, kp: float | Sequence[float],
                 kd: float | Sequence[float], feed_forward: Callable[[float], np.ndarray] | None = None):
        self.columns = model.coordinate_indices(list(reference.coordinates))
        self.reference = reference
        self.kp = gain_vector(kp, self.columns.size, "kp")
        self.kd = gain_vector(kd, self.columns.size, "kd")
        self.inverse_gains = input_map(model, reference.coordinates)
        self.feed_forward = feed_forward

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        z_ref, zd_ref, _ = self.reference(t)
        force = self.kp * (z_ref - q[self.columns]) + self.kd * (zd_ref - qd[self.columns])
        if self.feed_forward is not None:
            force = force + self.feed_forward(t)
        return self.inverse_gains @ force
