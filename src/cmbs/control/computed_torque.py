"""Computed-torque control (feedback linearisation) in independent coordinates via matrix R
(thesis ch. 6; THEORY §5).

With z the actuated (independent) coordinates, q̇ = R ż and q̈ = R z̈ + S (S = [A_d⁻¹γ; 0]), the
generalized force on z that produces a chosen z̈_c is

    τ_z = Rᵀ (M (R z̈_c + S) - Q),      z̈_c = z̈_ref + K_d ė + K_p e,   e = z_ref - z,

so that with an exact model the error obeys ë + K_d ė + K_p e = 0.  Q is the model's force with
zero inputs; the inputs u realise τ_z through the model's actuators on z.  z, τ_z and the gains
follow the order of the reference's coordinates.  The law is computed once, by
:func:`cmbs.control.compiled_torque.computed_torque_inputs` from the model's terms: a call
evaluates them in Python (any model), and :func:`cmbs.simulate` runs the law inside its compiled
loops on the model's kernel when it can.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from cmbs.control.base import Reference, gain_vector, input_map
from cmbs.control.compiled_torque import computed_torque_inputs, torque_law
from cmbs.dynamics import MatrixR
from cmbs.errors import SingularSystemError
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
        self.inverse_gains = input_map(model, reference.coordinates)
        #: the law's data (:class:`~cmbs.control.compiled_torque.TorqueLaw`)
        self.data = torque_law(model.n, reference._spline, self.columns, self.solver.partition, self.kp, self.kd,
                               self.inverse_gains)
        self.terms = model.new_terms()
        self.no_input = np.zeros(model.n_u)

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """The inputs u at (q, q̇, t); raises :class:`~cmbs.errors.SingularSystemError` where the
        partition's block A_d is singular."""
        q, qd = np.ascontiguousarray(q, dtype=float), np.ascontiguousarray(qd, dtype=float)
        terms = self.model.evaluate(q, qd, t, self.no_input, out=self.terms)
        u = np.empty(self.model.n_u)
        if not computed_torque_inputs(self.data, terms.Q, terms.A, terms.gamma, terms.M, q, qd, float(t), u):
            raise SingularSystemError(f"model {self.model.name!r} at t={float(t):.6g}: the computed-torque law's "
                                      "dependent block A_d is singular")
        return u
