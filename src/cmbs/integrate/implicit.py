"""Implicit one-step schemes for second-order systems, solved by Newton's method.

Index-3 DAE (Arnold & Brüls 2007, "Convergence of the generalized-α scheme for constrained
mechanical systems"): unknowns a_{n+1} (accelerations) and λ_{n+1}, with an auxiliary
acceleration x (x = a unless α_m, α_f ≠ 0)::

    (1 - α_m) x_{n+1} + α_m x_n = (1 - α_f) a_{n+1} + α_f a_n
    q_{n+1} = q_n + h v_n + h² (b₀ x_n + b₁ x_{n+1})
    v_{n+1} = v_n + h (g₀ x_n + g₁ x_{n+1})
    M(q_{n+1}) a_{n+1} + A(q_{n+1})ᵀ λ_{n+1} = Q(q_{n+1}, v_{n+1}, t_{n+1}),     Φ(q_{n+1}, t_{n+1}) = 0

Schemes (coefficients ``b₀, b₁, g₀, g₁, α_m, α_f``):

- backward Euler: v_{n+1} = v_n + h a_{n+1}, q_{n+1} = q_n + h v_{n+1}  → (0, 1, 0, 1, 0, 0), order 1;
- trapezoidal rule (Newmark, average acceleration): (¼, ¼, ½, ½, 0, 0), order 2;
- generalized-α with spectral radius ρ∞ (Chung & Hulbert 1993): α_m = (2ρ∞-1)/(ρ∞+1),
  α_f = ρ∞/(ρ∞+1), γ = ½ + α_f - α_m, β = ¼(γ + ½)², (½-β, β, 1-γ, γ, α_m, α_f), order 2.

Newton iteration matrix (with b' = b₁(1-α_f)/(1-α_m), g' = g₁(1-α_f)/(1-α_m), the derivatives
of q_{n+1} and v_{n+1} with respect to a_{n+1} divided by h² and h)::

    [ M + h g' C_t + h² b' K_t    Aᵀ ] [Δa]     [ r_dyn ]
    [ h² b' A                      0 ] [Δλ] = - [ Φ     ]

C_t = -∂Q/∂v and K_t = -∂Q/∂q are supplied by the caller (finite differences or zero).  The
constraint row is divided by h² b' to keep the matrix well scaled as h → 0.  This module knows
nothing about mechanics: the caller gives the residual and the matrices.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from cmbs.integrate.explicit import Integration


@dataclass(frozen=True)
class Scheme:
    """Coefficients of a one-step scheme (see the module docstring)."""

    name: str
    b0: float
    b1: float
    g0: float
    g1: float
    alpha_m: float = 0.0
    alpha_f: float = 0.0
    order: int = 2

    @property
    def b_eff(self) -> float:
        return self.b1 * (1.0 - self.alpha_f) / (1.0 - self.alpha_m)

    @property
    def g_eff(self) -> float:
        return self.g1 * (1.0 - self.alpha_f) / (1.0 - self.alpha_m)


BACKWARD_EULER = Scheme("backward-euler", 0.0, 1.0, 0.0, 1.0, order=1)
TRAPEZOIDAL = Scheme("trapezoidal", 0.25, 0.25, 0.5, 0.5)


def generalized_alpha(rho_infinity: float = 0.9) -> Scheme:
    """Chung & Hulbert's generalized-α with high-frequency spectral radius ρ∞ ∈ [0, 1]."""
    if not 0.0 <= rho_infinity <= 1.0:
        raise ValueError(f"spectral radius must be in [0, 1], got {rho_infinity}")
    alpha_m = (2.0 * rho_infinity - 1.0) / (rho_infinity + 1.0)
    alpha_f = rho_infinity / (rho_infinity + 1.0)
    gamma = 0.5 + alpha_f - alpha_m
    beta = 0.25 * (gamma + 0.5) ** 2
    return Scheme(f"generalized-alpha({rho_infinity:g})", 0.5 - beta, beta, 1.0 - gamma, gamma, alpha_m, alpha_f)


# residual(t, q, v, a, λ) -> (r_dyn (n,), phi (m,), M (n,n), A (m,n), C_t (n,n), K_t (n,n))
Residual = Callable[[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                    tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]


def integrate_index3(residual: Residual, q0: np.ndarray, v0: np.ndarray, a0: np.ndarray, lam0: np.ndarray,
                     t_out: np.ndarray, *, scheme: Scheme, step: float, tolerance: float = 1e-10,
                     max_iterations: int = 25, progress: Callable[[float], None] | None = None,
                     stop_on: tuple[type[Exception], ...] = (), keep_every: int = 1) -> Integration:
    """Fixed-step integration of the index-3 DAE; output at ``t_out`` (each a multiple of the step
    or hit exactly by shortening the last step before it), of which only ``t_out[::keep_every]``
    are stored (``keep_every`` must divide the number of intervals, so that the last is kept).

    Returns an :class:`~cmbs.integrate.explicit.Integration` whose ``y`` holds (q, v) and ``dy``
    (v, a); ``counters`` include the Newton iterations.  Newton stops when the scaled correction
    max|Δa| h² b' + max|Δλ| h² b' / (1 + max|λ|) is below ``tolerance`` relative to (1 + max|q|).
    """
    n, m = q0.size, lam0.size
    q, v, a, lam = (np.array(x, dtype=float) for x in (q0, v0, a0, lam0))
    x = a.copy()
    if keep_every < 1 or (t_out.size - 1) % keep_every:
        raise ValueError(f"keep_every={keep_every} does not divide the {t_out.size - 1} output intervals")
    kept = t_out[::keep_every]
    out_y = np.zeros((kept.size, 2 * n))
    out_dy = np.zeros((kept.size, 2 * n))
    out_y[0], out_dy[0] = np.concatenate([q, v]), np.concatenate([v, a])
    counters = {"steps": 0, "newton_iterations": 0, "evaluations": 0}
    t = float(t_out[0])
    next_out = 1

    def fail(message: str) -> Integration:
        stored = -(-next_out // keep_every)          # the kept instants before t_out[next_out]
        return Integration(kept[:stored], out_y[:stored], out_dy[:stored], "failed", message, counters)

    s = scheme
    while next_out < t_out.size:
        h = min(step, t_out[next_out] - t)
        if h <= 1e-14 * max(1.0, abs(t)):
            next_out += 1
            continue
        t_new = t + h
        a_new, lam_new = a.copy(), lam.copy()
        converged = False
        for iteration in range(max_iterations):
            x_new = ((1.0 - s.alpha_f) * a_new + s.alpha_f * a - s.alpha_m * x) / (1.0 - s.alpha_m)
            q_new = q + h * v + h * h * (s.b0 * x + s.b1 * x_new)
            v_new = v + h * (s.g0 * x + s.g1 * x_new)
            try:
                r_dyn, phi, M, A, C_t, K_t = residual(t_new, q_new, v_new, a_new, lam_new)
            except stop_on as error:
                return fail(str(error))
            counters["evaluations"] += 1
            scale = h * h * s.b_eff
            matrix = np.zeros((n + m, n + m))
            matrix[:n, :n] = M + h * s.g_eff * C_t + scale * K_t
            matrix[:n, n:] = A.T
            matrix[n:, :n] = A
            rhs = -np.concatenate([r_dyn, phi / scale])
            try:
                delta = np.linalg.solve(matrix, rhs)
            except np.linalg.LinAlgError:
                return fail(f"singular Newton matrix at t={t_new:.6g} (redundant constraints or a singular "
                            "configuration)")
            a_new += delta[:n]
            lam_new += delta[n:]
            counters["newton_iterations"] += 1
            change = scale * np.max(np.abs(delta[:n]), initial=0.0)
            if not np.all(np.isfinite(delta)):
                return fail(f"Newton iteration diverged at t={t_new:.6g}")
            if change < tolerance * (1.0 + np.max(np.abs(q_new))) and iteration > 0:
                converged = True
                break
        if not converged:
            return fail(f"Newton iteration did not converge in {max_iterations} iterations at t={t_new:.6g} "
                        f"(last correction {change:.3g}); reduce the step")
        x_new = ((1.0 - s.alpha_f) * a_new + s.alpha_f * a - s.alpha_m * x) / (1.0 - s.alpha_m)
        q = q + h * v + h * h * (s.b0 * x + s.b1 * x_new)
        v = v + h * (s.g0 * x + s.g1 * x_new)
        a, lam, x, t = a_new, lam_new, x_new, t_new
        counters["steps"] += 1
        if progress is not None:
            progress(t)
        if abs(t - t_out[next_out]) <= 1e-12 * max(1.0, abs(t)):
            if next_out % keep_every == 0:
                row = next_out // keep_every
                out_y[row], out_dy[row] = np.concatenate([q, v]), np.concatenate([v, a])
            next_out += 1
    return Integration(kept, out_y, out_dy, "success", "", counters)
