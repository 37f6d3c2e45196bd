"""Aghili's projection-operator formulation (Aghili 2005, §IV-V; THEORY §3.5).

With the SVD pseudo-inverse A⁺ (singular values below ``threshold``·σ_max discarded) and the
orthogonal projector onto null(A), P = I - A⁺A, the constrained dynamics split into

    P M q̈ = P Q                 (projected inverse dynamics: λ eliminated, P Aᵀ = 0)
    (I - P) q̈ = A⁺ γ            (the constraints at acceleration level)

and are combined into one regular system with a *constraint inertia matrix*:

    standard       M_c = M + P M - M P,                    M_c q̈ = P Q + M A⁺γ
    symmetric      M̄ = P M P + (I-P) M (I-P),              M̄ q̈ = P Q + (I - 2P) M A⁺γ
    parameterised  M_μ = P M + μ (I - P),                  M_μ q̈ = P Q + μ A⁺γ

Only the pseudo-inverse sees redundant constraints and singular configurations, so all three
pass them.  Constraint force f_c = -Aᵀλ = (I - P)(M q̈ - Q); λ = -(Aᵀ)⁺ f_c is unique when A has
full row rank and the minimum-norm multiplier otherwise.

Natural-coordinate models have massless angle/distance coordinates (M only semi-definite);
then M is replaced by M̂ = M + s(I - P) with s = trace(M)/n.  Since P(I - P) = 0, P M̂ = P M and
the solution is unchanged, while M_c and M̄ become regular.

One compiled solve, :func:`_solve` on a :class:`ProjectionKernel` made when the formulation is
bound, serves every inertia, the Python loop (:meth:`ProjectionSolver.accelerations`) and the
compiled loops alike.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, NamedTuple

import numpy as np

from cmbs.dynamics.base import OK, SINGULAR, Accelerations, StatelessSolver, check_parameters
from cmbs.dynamics.dependent_rows import KEPT_LOW, RESIDUAL, TRACE, dependent_rows, solve_dependent_rows
from cmbs.dynamics.field import unchanged
from cmbs.dynamics.kkt import band_kkt, banded, bounds_meeting, packed_workspace, schur_solve, solve_in_place, \
    unpack_workspace
from cmbs.errors import CmbsError, SingularSystemError
from cmbs.jit import njit
from cmbs.model.model import Model, Terms

#: The constraint inertia matrices; a :class:`ProjectionKernel` carries one by its index here.
INERTIAS = ("standard", "symmetric", "parameterised")
STANDARD, SYMMETRIC, PARAMETERISED = range(len(INERTIAS))


@dataclass(frozen=True)
class Projection:
    """Projection-operator formulation.

    Parameters
    ----------
    inertia
        ``"standard"``, ``"symmetric"`` or ``"parameterised"`` constraint inertia matrix.
    threshold
        Singular values of A, with its rows normalised by their norms at the initial
        configuration, below this are discarded by the pseudo-inverse.  Near a singular
        configuration this frees the constraint direction that is being lost, so the mechanism
        moves through on its momentum (Aghili 2005 §V-C); see docs/formulations.md for the
        trade-off between keeping the assembly branch and the energy error.
    mu
        Scalar of the parameterised variant (mass units); default trace(M)/n.
    """

    name: ClassVar[str] = "projection"
    inertia: str = "standard"
    threshold: float = 1e-9
    mu: float | None = None

    def __post_init__(self) -> None:
        check_parameters(self, threshold="non-negative", mu="optional-positive")
        if self.inertia not in INERTIAS:
            raise CmbsError(f"projection inertia must be one of {', '.join(INERTIAS)}, got {self.inertia!r}")

    def bind(self, model: Model) -> "ProjectionSolver":
        return ProjectionSolver(model, self)

    def compiled(self, solver: "ProjectionSolver", model: Model) -> "ProjectionKernel":
        """The solve of the compiled loops: the bound solver's own (every inertia)."""
        return solver.kernel


def pseudo_inverse(A: np.ndarray, threshold: float, row_scale: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """A⁺ (n, m) and P = I - A⁺A (n, n) by SVD.

    Without ``row_scale`` singular values below ``threshold``·σ_max are discarded.  With it,
    the SVD is taken of D A, D = diag(row_scale) (rows normalised once, e.g. by their norms at
    the initial configuration), singular values below ``threshold`` are discarded, and
    A⁺ = (D A)⁺ D, which is the Moore-Penrose inverse of A when nothing is discarded.
    """
    n = A.shape[1]
    if A.shape[0] == 0:
        return np.zeros((n, 0)), np.eye(n)
    scaled = A if row_scale is None else A * row_scale[:, None]
    U, sigma, Vt = np.linalg.svd(scaled, full_matrices=False)
    cutoff = threshold * max(sigma[0], 1e-300) if row_scale is None else threshold
    rank = int(np.sum(sigma > cutoff))
    V = Vt[:rank].T
    pinv = (V / sigma[:rank]) @ U[:, :rank].T
    if row_scale is not None:
        pinv = pinv * row_scale[None, :]
    return pinv, np.eye(n) - V @ V.T


def reference_row_scale(model: Model) -> np.ndarray:
    """1 / (norm of each row of A at the model's initial configuration), 1 for zero rows."""
    norms = np.linalg.norm(model.jacobian(model.q0, 0.0), axis=1)
    return 1.0 / np.where(norms > 0, norms, 1.0)


class ProjectionSolver(StatelessSolver):
    """The projection for one run: each evaluation is one call of the compiled :func:`_solve` on
    the :class:`ProjectionKernel` made here (the compiled loops call the same).  M counts as
    semi-definite (and is replaced by M̂) when its smallest eigenvalue at q0 is at most 1e-12 of
    its largest entry; s = trace(M)/n at q0."""

    def __init__(self, model: Model, parameters: Projection):
        super().__init__(model)
        self.p = parameters
        M0 = model.mass_matrix(model.q0)
        self.semi_definite = bool(np.linalg.eigvalsh(M0)[0] <= 1e-12 * max(np.abs(M0).max(), 1.0))
        self.scale = float(np.trace(M0)) / model.n
        self.row_scale = reference_row_scale(model)
        workspace = packed_workspace(model)
        kind = BandProjectionKernel if banded(*workspace) else ProjectionKernel
        mu = self.scale if parameters.mu is None else parameters.mu
        self.kernel = kind(INERTIAS.index(parameters.inertia), float(mu), float(parameters.threshold), self.scale,
                           self.semi_definite, np.ascontiguousarray(self.row_scale, dtype=float), *workspace,
                           *dependent_rows(model, M0, not self.semi_definite))

    def accelerations(self, terms: Terms, q: np.ndarray, qd: np.ndarray, t: float) -> Accelerations:
        """Accelerations, multipliers and f_c = -Aᵀλ at one state; raises
        :class:`~cmbs.errors.SingularSystemError` when the constraint inertia matrix is singular."""
        qdd, lam = np.empty(self.model.n), np.empty(self.model.m)
        status = _solve(self.kernel, (terms.Q, terms.phi, terms.A, terms.gamma, terms.phi_t, terms.M), t, qd, qdd, lam)
        if status != OK:
            raise SingularSystemError(self._singular_message(t))
        return Accelerations(qdd, lam, -terms.A.T @ lam)

    def _singular_message(self, t: float) -> str:
        """Why :func:`_solve` found the constraint inertia matrix singular: M x = 0 for a motion x
        the constraints allow, or an M that is not what q0 showed (M̂ is decided there)."""
        if self.semi_definite:
            other = f"or M is not positive semi-definite (M + s(I - P) used, s = {self.scale:.3g})"
        else:
            other = "or M, positive definite at q0 and therefore used as it is, has lost rank or definiteness"
        return (f"model {self.model.name!r} at t={t:.6g}: the projection's {self.p.inertia} constraint inertia matrix "
                f"is singular: a motion the constraints allow carries no mass (M x = 0 for some x != 0 with A x = 0), "
                f"{other}")


class ProjectionKernel(NamedTuple):
    """The projection as :func:`_solve` takes it: the constraint inertia (an index into
    INERTIAS) and μ of the parameterised one, the SVD threshold, the mass-regularisation scale s
    and whether M is semi-definite, the row scale and the packed
    :func:`cmbs.dynamics.kkt.schur_workspace`; and what the path of dependent rows needs
    (:func:`cmbs.dynamics.dependent_rows.dependent_rows`)."""

    inertia: int
    mu: float
    threshold: float
    scale: float
    semi_definite: bool
    row_scale: np.ndarray
    floats: np.ndarray
    integers: np.ndarray
    layout: np.ndarray
    mass_low: float
    dependent_floats: np.ndarray
    dependent_order: np.ndarray
    last_path: np.ndarray


class BandProjectionKernel(ProjectionKernel):
    """A :class:`ProjectionKernel` whose workspace solves regular systems by band LU (large natural
    models, :func:`cmbs.dynamics.kkt.banded`)."""

    __slots__ = ()


@njit(cache=True)
def _solve(kernel, terms, t, qd, qdd, lam):
    """Aghili's projection with the kernel's constraint inertia at the terms (Q, Φ, A, γ, Φ_t, M):
    by the augmented system where A is certified regular (:func:`_by_schur`, the same solution
    there for every inertia), by the augmented system without the dependent rows where they are
    certified to be what the SVD discards (:func:`_by_dependent_rows`; tried first after an
    evaluation that took it), else by the SVD (:func:`_by_svd`); SINGULAR only when the
    constraint inertia matrix is exactly singular."""
    Q, phi, A, gamma, phi_t, M = terms
    schur = unpack_workspace(kernel.floats, kernel.integers, kernel.layout)
    dependent_first = kernel.last_path[0] == 1
    if dependent_first and _by_dependent_rows(kernel, Q, A, gamma, schur, qdd, lam):
        return OK
    if _by_schur(kernel, M, Q, A, gamma, schur, qdd, lam):
        kernel.last_path[0] = 0
        return OK
    if not dependent_first and _by_dependent_rows(kernel, Q, A, gamma, schur, qdd, lam):
        kernel.last_path[0] = 1
        return OK
    return _svd_status(kernel, M, Q, A, gamma, qdd, lam)


@njit(cache=True, inline="always")
def _by_dependent_rows(kernel, Q, A, gamma, schur, qdd, lam):
    """Aghili's projection solution where rows of A depend on the others (redundant
    constraints), by the augmented system of the independent rows
    (:func:`cmbs.dynamics.dependent_rows.solve_dependent_rows`), for each of the three inertias
    as in :func:`_by_schur`.  Taken only where its certificate shows that the SVD of the
    row-scaled A discards exactly the dependent rows' singular values: those are at most ρ ≤
    ``threshold``, and the kept ones at least σ_min(A'_I) ≥ PROJECTION_REGULAR·max(σ_max, 1)
    and above ``threshold``; the solutions then differ by about ρ/σ_min(A'_I).  Needs M⁻¹
    (constant M, no massless coordinates: ``kernel.mass_low`` > 0); returns False otherwise."""
    if kernel.mass_low <= 0.0 or schur[1] != 1:
        return False
    certificate = solve_dependent_rows(kernel.mass_low, kernel.dependent_floats, kernel.dependent_order, schur[0], Q,
                                       A, gamma, kernel.row_scale, schur[2], schur[5], schur[6], qdd, lam)
    if certificate.shape[0] == 0:
        return False
    return row_scaled_svd_agrees(certificate, kernel.threshold)


@njit(cache=True, inline="always")
def row_scaled_svd_agrees(certificate, threshold):
    """Whether the SVD of the row-scaled A, singular values up to ``threshold`` discarded, keeps
    exactly the rows :func:`cmbs.dynamics.dependent_rows.solve_dependent_rows` kept (its
    ``certificate``): the left-out singular values are at most ρ ≤ ``threshold``, the kept ones
    at least σ_min(A'_I) > ``threshold`` and ≥ PROJECTION_REGULAR·max(σ_max, 1) (for accuracy).
    The projection's test, and Udwadia-Kalaba's for its multipliers."""
    low = certificate[KEPT_LOW]
    return (low >= PROJECTION_REGULAR * PROJECTION_REGULAR * max(certificate[TRACE], 1.0)
            and low > threshold * threshold and certificate[RESIDUAL] <= threshold * threshold)


@njit(cache=True)
def _solve_band(kernel, terms, t, qd, qdd, lam):
    """:func:`_solve` of a :class:`BandProjectionKernel`: band LU of the augmented system where A
    is certified regular, else the SVD."""
    Q, phi, A, gamma, phi_t, M = terms
    schur = unpack_workspace(kernel.floats, kernel.integers, kernel.layout)
    if _certified_regular(kernel, A, schur) and band_kkt(Q, A, gamma, schur, qdd, lam):
        return OK
    return _svd_status(kernel, M, Q, A, gamma, qdd, lam)


@njit(cache=True, inline="always")
def _svd_status(kernel, M, Q, A, gamma, qdd, lam):
    """:func:`_by_svd` with the kernel's settings: OK, or SINGULAR when the constraint inertia
    matrix is exactly singular."""
    if _by_svd(M, Q, A, gamma, kernel.row_scale, kernel.threshold, kernel.inertia, kernel.mu, kernel.scale,
               kernel.semi_definite, qdd, lam):
        return OK
    return SINGULAR


#: The projection formulation takes the Schur-complement path when the row-scaled A is certified
#: to have σ_min >= this (times max(σ_max, 1)) and above the formulation's SVD threshold.
PROJECTION_REGULAR = 1e-4


@njit(cache=True, inline="always")
def _by_schur(kernel, M, Q, A, gamma, schur, qdd, lam):
    """Aghili's projection solution at a regular configuration, for each of the three inertias,
    by the augmented system [M Aᵀ; A 0][q̈; λ] = [Q; γ].

    When A has full row rank and no singular value of the row-scaled DA falls below the SVD
    ``threshold``, the pseudo-inverse discards nothing: A⁺ = Aᵀ(AAᵀ)⁻¹ and P = I - A⁺A.  Let q̈
    solve the augmented system.  Then P M q̈ = P Q (P Aᵀ = 0) and (I - P) q̈ = A⁺A q̈ = A⁺γ, so
    with w = A⁺γ and P M̂ = P M (Aghili 2005, §IV: the two projections of the equation):

    - standard: M_c = P M + M̂ (I - P), so M_c q̈ = P M q̈ + M̂ w = P Q + M̂ A⁺γ;
    - symmetric: M̄ q̈ = P M̂ (q̈ - w) + (I - P) M̂ w = P Q + (I - 2P) M̂ A⁺γ;
    - parameterised: M_μ q̈ = P M q̈ + μ w = P Q + μ A⁺γ.

    q̈ solves each system, and it is the only solution: the path succeeds only when the
    augmented matrix is regular, i.e. no motion x ≠ 0 with A x = 0 has M x = 0 (M being
    positive semi-definite), and each constraint inertia matrix is then regular.  For M_c x = 0
    or M̄ x = 0, the (I - P) part gives (I - P) M̂ (I - P) x = 0, so (I - P) x = 0, as
    (I - P) M̂ (I - P) is definite on range(Aᵀ): M is positive definite where this path factors
    it by Cholesky (a joint-coordinate or user model's M), and M̂ = M + s(I - P) is used where M
    has massless coordinates (a natural model's constant M, whose massive block the workspace
    found definite: M's smallest eigenvalue is 0 at q0); for M_μ x = 0 it gives
    μ (I - P) x = 0.  Then x = P x ∈ null(A) and the P part gives P M P x = 0, so xᵀ M x = 0 and
    M x = 0: x = 0.  The multipliers are the same too: f_c = (I - P)(M q̈ - Q) = -Aᵀλ and
    λ = -(Aᵀ)⁺ f_c.

    Taken only when the Gram-matrix bounds of :func:`~cmbs.dynamics.kkt.bounds` certify σ_min(DA) >=
    PROJECTION_REGULAR·max(σ_max, 1) and σ_min > ``threshold``; returns False otherwise (near
    singular positions, redundant constraints), and the caller takes the SVD path.  Solved by
    the Schur complement (a :class:`BandProjectionKernel` solves by band LU,
    :func:`_solve_band`)."""
    return _certified_regular(kernel, A, schur) and schur_solve(M, Q, A, gamma, schur, qdd, lam)


@njit(cache=True, inline="always")
def _certified_regular(kernel, A, schur):
    """Whether the Gram bounds certify the row-scaled A regular enough for the augmented system
    (:func:`_by_schur`)."""
    m = A.shape[0]
    if m == 0 or m > A.shape[1]:
        return False
    row_scale, threshold = kernel.row_scale, kernel.threshold
    low, high = bounds_meeting(A, row_scale, PROJECTION_REGULAR, threshold, schur[27], schur[28], schur[7], schur[8],
                                schur[13], schur[14], schur[15])
    return not (low < PROJECTION_REGULAR * PROJECTION_REGULAR * max(high, 1.0) or low <= threshold * threshold)


@njit(cache=True)
def _by_svd(M, Q, A, gamma, row_scale, threshold, inertia, mu, scale, semi_definite, qdd, lam):
    """Aghili's projection solution with the constraint inertia ``inertia`` (STANDARD, SYMMETRIC
    or PARAMETERISED, scalar ``mu``) and the SVD pseudo-inverse of the row-scaled A, singular
    values up to ``threshold`` discarded (any rank of A); M̂ = M + s(I - P) when
    ``semi_definite`` flags a semi-definite M (s = ``scale``).  Returns False when the
    constraint inertia matrix is exactly singular."""
    n = M.shape[0]
    m = A.shape[0]
    pinv = np.zeros((n, m))
    P = np.eye(n)
    if m > 0:
        scaled = A * row_scale.reshape((m, 1))
        U, sigma, Vt = np.linalg.svd(scaled, full_matrices=False)
        for k in range(sigma.shape[0]):
            if sigma[k] > threshold:            # P -= v vᵀ, A⁺ += (v/σ)(u ∘ row_scale)ᵀ, element by element
                for i in range(n):
                    for j in range(n):
                        P[i, j] -= Vt[k, i] * Vt[k, j]
                    for j in range(m):
                        pinv[i, j] += (Vt[k, i] / sigma[k]) * (U[j, k] * row_scale[j])
    I_P = np.eye(n) - P
    M_hat = M + scale * I_P if semi_definite else M.copy()
    constrained = pinv @ gamma                      # A⁺γ
    if inertia == STANDARD:
        matrix = M_hat + P @ M - M_hat @ P
        solution = P @ Q + M_hat @ constrained
    elif inertia == SYMMETRIC:
        matrix = P @ M_hat @ P + I_P @ M_hat @ I_P
        solution = P @ Q + (np.eye(n) - 2.0 * P) @ (M_hat @ constrained)
    else:
        matrix = P @ M + mu * I_P
        solution = P @ Q + mu * constrained
    if not solve_in_place(matrix, solution):
        return False
    for i in range(n):
        qdd[i] = solution[i]
    force = I_P @ (M @ qdd - Q)
    multipliers = pinv.T @ force
    for r in range(m):
        lam[r] = -multipliers[r]
    return True


ProjectionKernel.solve = staticmethod(_solve)
ProjectionKernel.stage_state = ProjectionKernel.after_step = staticmethod(unchanged)
BandProjectionKernel.solve = staticmethod(_solve_band)
