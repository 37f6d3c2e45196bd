"""Penalty formulation and its augmented-Lagrangian iteration (thesis §3.5.3; Bayo, García de
Jalón & Serna 1988).

The constraints act as stiff springs with multipliers λ = α(Φ̈ + 2μΩΦ̇ + Ω²Φ), Φ̈ = A q̈ - γ::

    (M + Aᵀ α A) q̈ = Q + Aᵀ α (γ - 2μΩ Φ̇ - Ω² Φ).

It copes with redundant constraints and singular positions (M + AᵀαA stays invertible while M is
positive definite on the null space of A); α trades constraint accuracy against conditioning.
With ``iterations`` > 0 the augmented Lagrangian removes the penalty error: starting from the
previous evaluation's λ*,

    (M + AᵀαA) q̈_k = Q - Aᵀλ*_k + Aᵀα(γ - 2μΩΦ̇ - Ω²Φ),
    λ*_{k+1} = λ*_k + α (A q̈_k - γ + 2μΩΦ̇ + Ω²Φ),

until the change of q̈ is below ``tolerance`` (relative).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from cmbs.dynamics.base import Accelerations, StatelessSolver, check_parameters, constraint_velocity
from cmbs.errors import ConvergenceError
from cmbs.lazy import lazy_module
from cmbs.model.model import Model, Terms

linalg = lazy_module("scipy.linalg")


@dataclass(frozen=True)
class Penalty:
    """Penalty method: α (default 1e7), μ (1), Ω (10 s⁻¹); ``iterations`` > 0 turns on the
    augmented-Lagrangian iteration (up to that many updates of λ* per evaluation)."""

    name: ClassVar[str] = "penalty"
    alpha: float = 1e7
    mu: float = 1.0
    Omega: float = 10.0
    iterations: int = 0
    tolerance: float = 1e-12

    def __post_init__(self) -> None:
        check_parameters(self, alpha="positive", mu="non-negative", Omega="non-negative", iterations="count", tolerance="positive")

    def bind(self, model: Model) -> "PenaltySolver":
        return PenaltySolver(model, self)


class PenaltySolver(StatelessSolver):
    def __init__(self, model: Model, parameters: Penalty):
        super().__init__(model)
        self.p = parameters
        self.lam_star = np.zeros(model.m)

    def accelerations(self, terms: Terms, q: np.ndarray, qd: np.ndarray, t: float) -> Accelerations:
        p, A = self.p, terms.A
        target = terms.gamma - 2.0 * p.mu * p.Omega * constraint_velocity(terms, qd) - p.Omega**2 * terms.phi
        matrix = terms.M + p.alpha * (A.T @ A)
        factor = linalg.cho_factor(matrix, check_finite=False)
        base = terms.Q + p.alpha * (A.T @ target)
        if p.iterations == 0:
            qdd = linalg.cho_solve(factor, base, check_finite=False)
            lam = p.alpha * (A @ qdd - target)
            return Accelerations(qdd, lam, -A.T @ lam)
        lam_star = self.lam_star
        qdd = linalg.cho_solve(factor, base - A.T @ lam_star, check_finite=False)
        for _ in range(p.iterations):
            lam_star = lam_star + p.alpha * (A @ qdd - target)
            new = linalg.cho_solve(factor, base - A.T @ lam_star, check_finite=False)
            change = np.max(np.abs(new - qdd)) / max(np.max(np.abs(new)), 1.0)
            qdd = new
            if change < p.tolerance:
                break
        else:
            raise ConvergenceError(
                f"model {self.model.name!r} at t={t:.6g}: augmented Lagrangian did not converge in "
                f"{p.iterations} iterations (last relative change {change:.3g}); raise 'iterations' or lower 'alpha'")
        self.lam_star = lam_star
        lam = lam_star + p.alpha * (A @ qdd - target)
        return Accelerations(qdd, lam, -A.T @ lam)
