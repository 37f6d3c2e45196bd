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

The whole solve is one compiled kernel, :func:`penalty_solve`, which :class:`PenaltySolver` calls
on work arrays allocated once per run, and the compiled loops through :class:`PenaltyKernel`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, NamedTuple

import numpy as np

from cmbs.dynamics.base import OK, Accelerations, StatelessSolver, check_parameters
from cmbs.dynamics.dense import (NOT_POSITIVE_DEFINITE, add_scaled_gram, all_finite, copy_vector, fill_nan, max_abs,
                                 multiply, multiply_transposed)
from cmbs.dynamics.field import unchanged
from cmbs.dynamics.kkt import DENSE, cholesky_in_place, solve_lower, solve_lower_transposed
from cmbs.errors import SingularSystemError
from cmbs.jit import njit
from cmbs.model.model import Model, Terms

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

    def compiled(self, solver: "PenaltySolver", model: Model) -> "PenaltyKernel":
        """The solve of the compiled loops, on the solver's own λ*, work arrays and worst
        residual (so that :meth:`PenaltySolver.run_note` reports a compiled run too)."""
        return PenaltyKernel(solver.alpha, solver.mu, solver.Omega, solver.iterations, solver.tolerance,
                             solver.lam_star, solver.factor, solver.vectors_n, solver.vectors_m, np.zeros(model.n),
                             solver.worst)


def scaled_alpha(model: Model) -> float:
    """ALPHA_SCALE · max diag M / max diag AᵀA at the model's q0 (1 without constraints)."""
    terms = model.evaluate(model.q0, np.zeros(model.n), 0.0)
    constraint_scale = float(np.max(np.sum(terms.A**2, axis=0), initial=0.0))
    mass_scale = float(np.max(np.diag(terms.M), initial=0.0))
    return ALPHA_SCALE * mass_scale / constraint_scale if constraint_scale > 0 and mass_scale > 0 else 1.0


class PenaltySolver(StatelessSolver):
    """The penalty of one run; it keeps λ* between evaluations and the largest relative
    constraint-acceleration residual met (``worst_residual`` at ``worst_time``).  Each evaluation
    is one call of the compiled :func:`penalty_solve` on work arrays allocated here."""

    def __init__(self, model: Model, parameters: Penalty):
        super().__init__(model)
        self.p = parameters
        self.alpha = float(parameters.alpha) if parameters.alpha is not None else scaled_alpha(model)
        # the kernel's argument types (an integer option would compile another specialisation)
        self.mu, self.Omega = float(parameters.mu), float(parameters.Omega)
        self.iterations, self.tolerance = int(parameters.iterations), float(parameters.tolerance)
        self.lam_star = np.zeros(model.m)
        #: the largest relative residual met and its time (shared with the compiled kernel)
        self.worst = np.zeros(2)
        self.factor = np.zeros((model.n, model.n))
        self.vectors_n = np.zeros((3, model.n))
        self.vectors_m = np.zeros((4, model.m))

    def accelerations(self, terms: Terms, q: np.ndarray, qd: np.ndarray, t: float) -> Accelerations:
        """The penalty's accelerations at one state.

        Raises :class:`~cmbs.errors.SingularSystemError` when M + αAᵀA is not positive definite;
        a non-finite term gives NaN accelerations (the integrator reports the non-finite state)."""
        m, n = terms.A.shape
        if (m, n) != (self.model.m, self.model.n):
            raise ValueError(f"terms of shape A {terms.A.shape} for model {self.model.name!r} "
                             f"(m = {self.model.m}, n = {self.model.n})")
        qdd, lam, force = np.empty(n), np.empty(m), np.empty(n)
        status, relative = penalty_solve(terms.M, terms.Q, terms.A, terms.gamma, terms.phi, terms.phi_t, qd,
                                         self.alpha, self.mu, self.Omega, self.iterations, self.tolerance,
                                         self.lam_star, self.factor, self.vectors_n, self.vectors_m, qdd, lam, force)
        if status == NOT_POSITIVE_DEFINITE:
            raise SingularSystemError(
                f"model {self.model.name!r} at t={t:.6g}: the penalty matrix M + alpha AᵀA "
                f"(alpha = {self.alpha:.3g}) is not positive definite: a motion that the constraints allow has no "
                "mass, or alpha is so large that M is lost to rounding")
        if relative > self.worst[0]:
            self.worst[0], self.worst[1] = relative, t
        return Accelerations(qdd, lam, force)

    @property
    def worst_residual(self) -> float:
        """The largest relative constraint-acceleration residual of the run so far."""
        return float(self.worst[0])

    @property
    def worst_time(self) -> float:
        """The time of :attr:`worst_residual`."""
        return float(self.worst[1])

    def run_note(self) -> str:
        """A warning when the constraint accelerations missed the exact ones by more than
        :data:`RESIDUAL_NOTE` (relative) during the run, else ""."""
        if self.worst_residual <= RESIDUAL_NOTE:
            return ""
        return (f"penalty: the constraint accelerations missed the exact ones by up to {self.worst_residual:.2g} "
                f"(relative, at t = {self.worst_time:.6g}): constraint forces and motion of soft constraints there "
                "(the plain penalty, iterations=0, or a small alpha; or a singular position, whose acceleration "
                "equations have no exact solution)")


@njit(cache=True)
def penalty_solve(M: np.ndarray, Q: np.ndarray, A: np.ndarray, gamma: np.ndarray, phi: np.ndarray,
                  phi_t: np.ndarray, qd: np.ndarray, alpha: float, mu: float, Omega: float, iterations: int,
                  tolerance: float, lam_star: np.ndarray, factor: np.ndarray, vectors_n: np.ndarray,
                  vectors_m: np.ndarray, qdd: np.ndarray, lam: np.ndarray, force: np.ndarray) -> tuple[int, float]:
    """The penalty's q̈, λ and constraint force -Aᵀλ at one state, written into ``qdd`` (n,),
    ``lam`` (m,) and ``force`` (n,); the augmented Lagrangian's λ* (m,) is updated in place (set to
    zero when ``iterations`` is 0).  Returns (status, relative residual): status
    :data:`~cmbs.dynamics.base.OK`, ``NOT_POSITIVE_DEFINITE`` (M + αAᵀA; outputs not written) or
    ``NON_FINITE`` (outputs NaN); the residual of the kept iterate as the module docstring
    defines it.

    Work arrays: ``factor`` (n, n) for the Cholesky factor of M + αAᵀA; ``vectors_n`` (3, n) and
    ``vectors_m`` (4, m).

    The iteration (module docstring): q̈ₖ = (M + αAᵀA)⁻¹ (b - Aᵀλ*ₖ), b = Q + αAᵀ target,
    target = γ - 2μΩΦ̇ - Ω²Φ; rₖ = A q̈ₖ - target; λ*ₖ₊₁ = λ*ₖ + α rₖ while the relative residual is
    above ``tolerance`` and each step at least halves it; λ = λ* + α r of the kept iterate.
    """
    base, rhs, trial = vectors_n[0], vectors_n[1], vectors_n[2]
    target, residual, trial_residual, trial_lam_star = vectors_m[0], vectors_m[1], vectors_m[2], vectors_m[3]
    multiply(A, qd, target)                                   # Φ̇ - Φ_t = A q̇
    for i in range(target.size):
        target[i] = gamma[i] - 2.0 * mu * Omega * (target[i] + phi_t[i]) - Omega**2 * phi[i]
    add_scaled_gram(M, A, alpha, factor)
    if not cholesky_in_place(factor, DENSE):
        if all_finite(M) and all_finite(A) and np.isfinite(alpha):
            return NOT_POSITIVE_DEFINITE, np.nan
        return fill_nan(qdd, lam, force), np.nan
    multiply_transposed(A, target, base)
    for j in range(base.size):
        base[j] = Q[j] + alpha * base[j]
    if iterations == 0:
        lam_star[:] = 0.0
    size_A = max_abs(A)
    relative = _solve_and_measure(factor, base, A, lam_star, target, size_A, rhs, qdd, residual)
    if not np.isfinite(relative):
        return fill_nan(qdd, lam, force), np.nan
    for _ in range(iterations):
        if relative < tolerance:
            break
        for i in range(trial_lam_star.size):
            trial_lam_star[i] = lam_star[i] + alpha * residual[i]
        trial_relative = _solve_and_measure(factor, base, A, trial_lam_star, target, size_A, rhs, trial,
                                            trial_residual)
        if trial_relative > 0.5 * relative:     # no longer contracting: the best this state allows
            break
        copy_vector(trial_lam_star, lam_star)
        copy_vector(trial, qdd)
        copy_vector(trial_residual, residual)
        relative = trial_relative
    for i in range(lam.size):
        lam[i] = lam_star[i] + alpha * residual[i]
    multiply_transposed(A, lam, force)
    force *= -1.0
    if not (all_finite(qdd) and all_finite(lam) and np.isfinite(relative)):
        return fill_nan(qdd, lam, force), np.nan
    return OK, relative


@njit(cache=True)
def _solve_and_measure(factor: np.ndarray, base: np.ndarray, A: np.ndarray, lam_star: np.ndarray,
                       target: np.ndarray, size_A: float, rhs: np.ndarray, qdd: np.ndarray,
                       residual: np.ndarray) -> float:
    """q̈ = (L Lᵀ)⁻¹ (base - Aᵀλ*) into ``qdd`` and r = A q̈ - target into ``residual``; returns
    the relative residual max|r| / (max|A| max|q̈| + max|target|) (``size_A`` = max|A|), or
    whether r ≠ 0 when that scale is zero."""
    multiply_transposed(A, lam_star, rhs)
    for j in range(qdd.size):
        qdd[j] = base[j] - rhs[j]
    solve_lower(factor, DENSE, qdd)
    solve_lower_transposed(factor, DENSE, qdd)
    multiply(A, qdd, residual)
    residual -= target
    scale = size_A * max_abs(qdd) + max_abs(target)
    size = max_abs(residual)
    if scale > 0.0:
        return size / scale
    return 1.0 if size > 0.0 else 0.0


class PenaltyKernel(NamedTuple):
    """The penalty as the compiled loops take it (:mod:`cmbs.dynamics.field`): its parameters,
    λ*, the work arrays of :func:`penalty_solve`, a constraint-force vector and the largest
    relative residual met with its time."""

    alpha: float
    mu: float
    Omega: float
    iterations: int
    tolerance: float
    lam_star: np.ndarray
    factor: np.ndarray
    vectors_n: np.ndarray
    vectors_m: np.ndarray
    force: np.ndarray
    worst: np.ndarray


@njit(cache=True, inline="always")
def _kernel_solve(kernel, terms, t, qd, qdd, lam):
    """:func:`penalty_solve` at the terms (Q, Φ, A, γ, Φ_t, M); status OK, SINGULAR (M + αAᵀA
    not positive definite) or NON_FINITE; the largest residual is kept with its time."""
    Q, phi, A, gamma, phi_t, M = terms
    status, relative = penalty_solve(M, Q, A, gamma, phi, phi_t, qd, kernel.alpha, kernel.mu, kernel.Omega,
                                     kernel.iterations, kernel.tolerance, kernel.lam_star, kernel.factor,
                                     kernel.vectors_n, kernel.vectors_m, qdd, lam, kernel.force)
    if status == OK and relative > kernel.worst[0]:
        kernel.worst[0] = relative
        kernel.worst[1] = t
    return status


PenaltyKernel.solve = staticmethod(_kernel_solve)
PenaltyKernel.stage_state = PenaltyKernel.after_step = staticmethod(unchanged)
