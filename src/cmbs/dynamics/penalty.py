"""Penalty formulation and its augmented-Lagrangian iteration (thesis §3.5.3; Bayo, García de
Jalón & Serna 1988; Bayo & Ledesma 1996).

The constraints act as stiff springs with multipliers λ = α(Φ̈ + 2μΩΦ̇ + Ω²Φ), Φ̈ = A q̈ - γ::

    (M + Aᵀ α A) q̈ = Q + Aᵀ α (γ - 2μΩ Φ̇ - Ω² Φ).

It copes with redundant constraints and singular positions (M + AᵀαA stays invertible while M is
positive definite on the null space of A).  The plain penalty (``iterations=0``) leaves an error
λ/α in the constraint accelerations; the augmented Lagrangian removes it: starting from the
previous evaluation's λ*,

    (M + AᵀαA) q̈_k = Q - Aᵀλ*_k + Aᵀα(γ - 2μΩΦ̇ - Ω²Φ),
    λ*_{k+1} = λ*_k + α r_k,      r_k = A q̈_k - γ + 2μΩΦ̇ + Ω²Φ,

until the constraint-acceleration residual r_k is below ``tolerance`` relative to
‖A‖ ‖q̈‖ + ‖γ - 2μΩΦ̇ - Ω²Φ‖ (max norms), or until an iteration no longer halves it.  That
residual is what the iteration drives to zero, and rounding leaves it near machine precision
whatever the conditioning of M + αAᵀA, so the test is attainable; the change of q̈ between
iterations is not (it stalls at cond · ε).  At a singular position the acceleration equations
A q̈ = γ - 2μΩΦ̇ - Ω²Φ may have no solution (the drift terms leave range(A)): the residual then
stops shrinking above the tolerance, the iterate with the smallest residual is kept, and the
run's note reports the largest residual when it passed :data:`RESIDUAL_NOTE`.  The converged q̈
is Baumgarte's with ξω = μΩ, ω² = Ω².

The default α is scaled to the model (:data:`ALPHA_SCALE` · max diag M / max diag AᵀA at q0):
α = 1e7 in SI units suits kilogram-and-metre mechanisms, but on a mechanism of grams and
centimetres it makes M + αAᵀA so ill-conditioned (cond ≈ 4e10 on Andrews' squeezer) that q̈
loses six digits to rounding.  The scaled α keeps cond(M + αAᵀA) near 1e6 on the library models
and the iteration converges in two to four steps.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from cmbs.dynamics.base import Accelerations, StatelessSolver, check_parameters, constraint_velocity
from cmbs.lazy import on_first_use
from cmbs.model.model import Model, Terms

linalg = on_first_use("scipy.linalg")

#: α = ALPHA_SCALE · max diag M / max diag AᵀA (at q0) when no α is given.
ALPHA_SCALE = 1e4
#: A run whose relative constraint-acceleration residual (the plain penalty's λ/α) exceeds this
#: gets a note: its constraint forces and motion are those of soft constraints.
RESIDUAL_NOTE = 1e-6


@dataclass(frozen=True)
class Penalty:
    """Penalty method: α (default None: scaled to the model, see the module docstring), μ (1),
    Ω (10 s⁻¹); up to ``iterations`` (20) augmented-Lagrangian updates of λ* per evaluation,
    until the relative constraint-acceleration residual is below ``tolerance`` (1e-12) or an
    iteration no longer halves it; ``iterations=0`` is the plain penalty."""

    name: ClassVar[str] = "penalty"
    alpha: float | None = None
    mu: float = 1.0
    Omega: float = 10.0
    iterations: int = 20
    tolerance: float = 1e-12

    def __post_init__(self) -> None:
        check_parameters(self, alpha="optional-positive", mu="non-negative", Omega="non-negative", iterations="count",
                         tolerance="positive")

    def bind(self, model: Model) -> "PenaltySolver":
        return PenaltySolver(model, self)


def scaled_alpha(model: Model) -> float:
    """ALPHA_SCALE · max diag M / max diag AᵀA at the model's q0 (1 without constraints)."""
    terms = model.evaluate(model.q0, np.zeros(model.n), 0.0)
    constraint_scale = float(np.max(np.sum(terms.A**2, axis=0), initial=0.0))
    mass_scale = float(np.max(np.diag(terms.M), initial=0.0))
    return ALPHA_SCALE * mass_scale / constraint_scale if constraint_scale > 0 and mass_scale > 0 else 1.0


class PenaltySolver(StatelessSolver):
    """The penalty of one run; it keeps λ* between evaluations and the largest relative
    constraint-acceleration residual met (``worst_residual`` at ``worst_time``)."""

    def __init__(self, model: Model, parameters: Penalty):
        super().__init__(model)
        self.p = parameters
        self.alpha = parameters.alpha if parameters.alpha is not None else scaled_alpha(model)
        self.lam_star = np.zeros(model.m)
        self.worst_residual, self.worst_time = 0.0, 0.0

    def accelerations(self, terms: Terms, q: np.ndarray, qd: np.ndarray, t: float) -> Accelerations:
        p, A, alpha = self.p, terms.A, self.alpha
        target = terms.gamma - 2.0 * p.mu * p.Omega * constraint_velocity(terms, qd) - p.Omega**2 * terms.phi
        factor = linalg.cho_factor(terms.M + alpha * (A.T @ A), check_finite=False)
        base = terms.Q + alpha * (A.T @ target)
        lam_star = self.lam_star if p.iterations else np.zeros(self.model.m)
        qdd = linalg.cho_solve(factor, base - A.T @ lam_star, check_finite=False)
        residual = A @ qdd - target
        relative = _relative(residual, A, qdd, target)
        for _ in range(p.iterations):
            if relative < p.tolerance:
                break
            trial_lam_star = lam_star + alpha * residual
            trial = linalg.cho_solve(factor, base - A.T @ trial_lam_star, check_finite=False)
            trial_residual = A @ trial - target
            trial_relative = _relative(trial_residual, A, trial, target)
            if trial_relative > 0.5 * relative:     # no longer contracting: the best this state allows
                break
            lam_star, qdd, residual, relative = trial_lam_star, trial, trial_residual, trial_relative
        self.lam_star = lam_star
        if relative > self.worst_residual:
            self.worst_residual, self.worst_time = relative, t
        lam = lam_star + alpha * residual
        return Accelerations(qdd, lam, -A.T @ lam)

    def run_note(self) -> str:
        """A warning when the constraint accelerations missed the exact ones by more than
        :data:`RESIDUAL_NOTE` (relative) during the run, else ""."""
        if self.worst_residual <= RESIDUAL_NOTE:
            return ""
        return (f"penalty: the constraint accelerations missed the exact ones by up to {self.worst_residual:.2g} "
                f"(relative, at t = {self.worst_time:.6g}): constraint forces and motion of soft constraints there "
                "(the plain penalty, iterations=0, or a small alpha; or a singular position, whose acceleration "
                "equations have no exact solution)")


def _relative(residual: np.ndarray, A: np.ndarray, qdd: np.ndarray, target: np.ndarray) -> float:
    """max |r| / (max|A| max|q̈| + max|target|): the residual relative to the terms it is made of."""
    scale = np.max(np.abs(A), initial=0.0) * np.max(np.abs(qdd), initial=0.0) + np.max(np.abs(target), initial=0.0)
    size = np.max(np.abs(residual), initial=0.0)
    return float(size / scale) if scale > 0 else float(size > 0)
