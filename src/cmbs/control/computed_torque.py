"""Computed-torque control (feedback linearisation) in independent coordinates via matrix R
(thesis ch. 6; THEORY §5).

With z the actuated (independent) coordinates, q̇ = R ż and q̈ = R z̈ + S (S = [A_d⁻¹γ; 0]), the
generalized force on z that produces a chosen z̈_c is

    τ_z = Rᵀ (M (R z̈_c + S) - Q),      z̈_c = z̈_ref + K_d ė + K_p e,   e = z_ref - z,

so that with an exact model the error obeys ë + K_d ė + K_p e = 0.  Q is the model's force with
zero inputs; the inputs u realise τ_z through the model's actuators on z.  z, τ_z and the gains
follow the order of the reference's coordinates (R's columns are taken in that order).
:func:`cmbs.simulate` runs this law compiled (:mod:`cmbs.control.compiled_torque`) when it can.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from cmbs.control.base import Reference, gain_vector, input_map
from cmbs.dynamics import MatrixR
from cmbs.model.model import Model


class ComputedTorque:
    """Computed-torque law; ``kp``, ``kd`` scalars or (k,) arrays (s⁻², s⁻¹)."""

    def __init__(self, model: Model, reference: Reference, *, kp: float | Sequence[float],
                 kd: float | Sequence[float]):
        self.model = model
        self.reference = reference
        self.columns = model.coordinate_indices(list(reference.coordinates))
        self.kp = gain_vector(kp, self.columns.size, "kp")
        self.kd = gain_vector(kd, self.columns.size, "kd")
        self.solver = MatrixR(independent=tuple(reference.coordinates)).bind(model)
        # R's columns follow the partition's sorted independent coordinates; z̈_c, τ_z follow ``columns``
        self.order = np.searchsorted(self.solver.partition.independent, self.columns)
        self.inverse_gains = input_map(model, reference.coordinates)
        self.terms = model.new_terms()
        self.no_input = np.zeros(model.n_u)

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        z_ref, zd_ref, zdd_ref = self.reference(t)
        error = z_ref - q[self.columns]
        error_rate = zd_ref - qd[self.columns]
        zdd = zdd_ref + self.kd * error_rate + self.kp * error
        terms = self.model.evaluate(q, qd, t, self.no_input, out=self.terms)
        part = self.solver.partition
        R = self.solver.velocity_matrix(terms)[:, self.order]
        S = np.zeros(self.model.n)
        if part.dependent.size:
            S[part.dependent] = np.linalg.solve(terms.A[np.ix_(part.rows, part.dependent)], terms.gamma[part.rows])
        qdd = R @ zdd + S
        force = R.T @ (terms.M @ qdd - terms.Q)
        return self.inverse_gains @ force
