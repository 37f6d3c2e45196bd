"""PD control of independent coordinates (thesis ch. 6): ``τ = K_p e + K_d ė`` on the actuated
coordinates, e = z_ref - z, with an optional feed-forward of the inverse-dynamics force."""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from cmbs.control.base import Reference, actuator_map
from cmbs.errors import CmbsError
from cmbs.model.model import Model


class PD:
    """u such that the generalized forces on ``reference.coordinates`` are K_p e + K_d ė
    (+ feed_forward(t)); K_p, K_d scalars or (k,) arrays."""

    def __init__(self, model: Model, reference: Reference, *, kp: float | Sequence[float],
                 kd: float | Sequence[float], feed_forward: Callable[[float], np.ndarray] | None = None):
        self.columns = model.coordinate_indices(list(reference.coordinates))
        self.reference = reference
        k = self.columns.size
        self.kp = np.broadcast_to(np.asarray(kp, dtype=float), (k,)).copy()
        self.kd = np.broadcast_to(np.asarray(kd, dtype=float), (k,)).copy()
        gains = actuator_map(model, reference.coordinates)  # (n_u, k)
        if np.linalg.matrix_rank(gains) < k:
            raise CmbsError(f"model {model.name!r}: the actuators cannot act on every one of "
                            f"{', '.join(reference.coordinates)}")
        self.inverse_gains = np.linalg.pinv(gains.T)  # u = pinv(B_zᵀ) τ_z
        self.feed_forward = feed_forward

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        z_ref, zd_ref, _ = self.reference(t)
        force = self.kp * (z_ref - q[self.columns]) + self.kd * (zd_ref - qd[self.columns])
        if self.feed_forward is not None:
            force = force + self.feed_forward(t)
        return self.inverse_gains @ force
