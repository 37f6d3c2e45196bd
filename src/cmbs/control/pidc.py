"""Projected inverse-dynamics control (PIDC, Aghili 2005 §VII-A; THEORY §5).

The desired acceleration of the independent coordinates z, ``z̈_c = z̈_ref + K_d ė + K_p e``
(e = z_ref - z), is completed to a consistent full acceleration q̈_c (A q̈_c = γ, with the
z-components held), and the actuation is the minimum-norm generalized force producing it,

    τ = P (M q̈_c - Q_ext),   P = I - A⁺A   (or the W-weighted version),

which lies in null(A): no actuator effort is spent against the constraints.  With an exact
model the error obeys ë + K_d ė + K_p e = 0.  Every coordinate must be actuated (u = τ through
the model's actuator gains), as in Aghili's redundantly actuated arm on a slider.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from cmbs.control.base import Reference, gain_vector, input_map
from cmbs.inverse.projected import pidc_torque
from cmbs.kinematics import accelerations
from cmbs.model.model import Model


class PIDC:
    """Projected inverse-dynamics controller; ``weight`` (n, n) for mixed units."""

    def __init__(self, model: Model, reference: Reference, *, kp: float | Sequence[float],
                 kd: float | Sequence[float], weight: np.ndarray | None = None):
        self.model = model
        self.reference = reference
        self.columns = model.coordinate_indices(list(reference.coordinates))
        self.kp = gain_vector(kp, self.columns.size, "kp")
        self.kd = gain_vector(kd, self.columns.size, "kd")
        self.weight = weight
        self.inverse_gains = input_map(model, model.coordinate_names)  # PIDC acts on every coordinate

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        z_ref, zd_ref, zdd_ref = self.reference(t)
        zdd = zdd_ref + self.kd * (zd_ref - qd[self.columns]) + self.kp * (z_ref - q[self.columns])
        desired = np.zeros(self.model.n)
        desired[self.columns] = zdd
        qdd = accelerations(self.model, q, qd, t, qdd=desired, fixed=self.columns)
        return self.inverse_gains @ pidc_torque(self.model, q, qd, qdd, t, weight=self.weight)
