"""Udwadia-Kalaba explicit equations of motion (Udwadia & Kalaba 1992; Nicoara 2016, eq. 7-12).

From Gauss's principle, with the unconstrained acceleration a = M⁻¹Q and B = A M^{-1/2}::

    q̈ = a + M^{-1/2} B⁺ (γ - A a) + M^{-1/2} (I - B⁺B) M^{-1/2} c
    Q_c = M^{1/2} B⁺ (γ - A a) + M^{1/2} (I - B⁺B) M^{-1/2} c

The second term is the ideal constraint force, the third the non-ideal one, with c a
user-given vector (function of t, q, q̇) describing the work done by the constraint forces on
virtual displacements.  Redundant (consistent) constraints are handled by the Moore-Penrose
inverse.  Any factor M = L Lᵀ can stand for M^{1/2}: Gauss's principle minimises
‖Lᵀ(q̈ - a)‖² = (q̈ - a)ᵀ M (q̈ - a) whatever the factor, and the non-ideal term is the same too,
so the Cholesky factor is used (B = A L⁻ᵀ, M^{-1/2} → L⁻ᵀ on the left, L⁻¹ on the right); the
test suite checks the result against the symmetric square root.

When M is only semi-definite (natural coordinates with massless angle coordinates) the
augmented mass M̂ = M + s AᵀA, Q̂ = Q + s Aᵀγ (s = trace(M)/n) is used (Udwadia & Phohomsiri
2006): since s AᵀA q̈ = s Aᵀγ on the constraint manifold, the motion is unchanged and M̂ is
positive definite when M is definite on null(A).  λ is recovered from Q_c = -Aᵀλ (minimum norm).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, ClassVar

import numpy as np

from cmbs.dynamics.base import Accelerations, StatelessSolver, check_parameters
from cmbs.dynamics.projection import pseudo_inverse, reference_row_scale
from cmbs.lazy import on_first_use
from cmbs.model.model import Model, Terms

linalg = on_first_use("scipy.linalg")


@dataclass(frozen=True)
class UdwadiaKalaba:
    """Udwadia-Kalaba formulation; ``nonideal(t, q, q̇) -> c`` adds non-ideal constraint work."""

    name: ClassVar[str] = "udwadia-kalaba"
    threshold: float = 1e-9  # on the singular values of A M^{-1/2}, rows normalised as in Projection
    nonideal: Callable[[float, np.ndarray, np.ndarray], np.ndarray] | None = None

    def __post_init__(self) -> None:
        check_parameters(self, threshold="non-negative")

    def bind(self, model: Model) -> "UdwadiaKalabaSolver":
        return UdwadiaKalabaSolver(model, self)


class UdwadiaKalabaSolver(StatelessSolver):
    def __init__(self, model: Model, parameters: UdwadiaKalaba):
        super().__init__(model)
        self.p = parameters
        M0 = model.mass_matrix(model.q0)
        self.scale = float(np.trace(M0)) / model.n
        self.mass_scale = np.sqrt(self.scale)  # B = A L⁻ᵀ: rows of A scaled by about 1/√m
        self.semi_definite = bool(np.linalg.eigvalsh(M0)[0] <= 1e-12 * max(np.abs(M0).max(), 1.0))
        self._constant_factor = np.linalg.cholesky(M0) if model.constant_mass and not self.semi_definite else None
        self.row_scale = reference_row_scale(model)

    def accelerations(self, terms: Terms, q: np.ndarray, qd: np.ndarray, t: float) -> Accelerations:
        A, gamma = terms.A, terms.gamma
        if self.semi_definite:
            M = terms.M + self.scale * (A.T @ A)
            Q = terms.Q + self.scale * (A.T @ gamma)
            L = np.linalg.cholesky(M)
        else:
            Q = terms.Q
            L = self._constant_factor if self._constant_factor is not None else np.linalg.cholesky(terms.M)
        a = linalg.cho_solve((L, True), Q, check_finite=False)
        B = linalg.solve_triangular(L, A.T, lower=True, check_finite=False).T  # A L⁻ᵀ
        B_pinv, null_projector = pseudo_inverse(B, self.p.threshold, self.row_scale * self.mass_scale)
        scaled_force = B_pinv @ (gamma - A @ a)
        if self.p.nonideal is not None:
            c = np.asarray(self.p.nonideal(t, q, qd), dtype=float)
            scaled_force = scaled_force + null_projector @ linalg.solve_triangular(L, c, lower=True,
                                                                                          check_finite=False)
        qdd = a + linalg.solve_triangular(L, scaled_force, lower=True, trans="T", check_finite=False)
        force = terms.M @ qdd - terms.Q  # = Q_c of the original system (ideal + non-ideal)
        A_pinv, _ = pseudo_inverse(A, self.p.threshold, self.row_scale)
        lam = -A_pinv.T @ force
        return Accelerations(qdd, lam, force)
