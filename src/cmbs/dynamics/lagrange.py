"""Lagrange multipliers (index-1) and Baumgarte stabilisation (thesis §3.5.1-3.5.2).

Index-1 augmented system (García de Jalón & Bayo 1994, eq. 5.4)::

    [ M  Aᵀ ] [ q̈ ]   [ Q  ]
    [ A  0  ] [ λ  ] = [ γ* ],      γ* = γ                       (Lagrange)
                                    γ* = γ - 2ξω Φ̇ - ω² Φ        (Baumgarte 1972)

A rank-deficient A (redundant constraints or a singular configuration) makes the matrix
singular: the solver raises :class:`~cmbs.errors.SingularSystemError` naming the dependent
constraints, unless ``least_squares`` asks for the minimum-norm least-squares solution (LAPACK's
SVD-based gelsd, numpy's ``np.linalg.lstsq`` with its default cut-off).  Each option is one
compiled solve (:func:`_solve` on a :class:`LagrangeKernel`, :func:`_solve_least_squares` on a
:class:`LeastSquaresKernel`), the one the compiled integration loops run; a run compiles only
the one it uses.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, NamedTuple

import numpy as np

from cmbs.dynamics.base import NON_FINITE, OK, SINGULAR, Accelerations, StatelessSolver, check_parameters
from cmbs.dynamics.dense import all_finite
from cmbs.dynamics.field import unchanged
from cmbs.dynamics.kkt import assemble_kkt, band_kkt, banded, certify, full_system, gram_singular, packed_workspace, \
    schur_solve, unpack_workspace
from cmbs.errors import SingularSystemError
from cmbs.jit import njit
from cmbs.lazy import on_first_use
from cmbs.model.model import Model, Terms

linalg = on_first_use("scipy.linalg")


@dataclass(frozen=True)
class Lagrange:
    """Index-1 Lagrange multipliers.

    Parameters
    ----------
    least_squares
        Solve a singular system in the least-squares sense instead of raising.
    singular_tolerance
        The system counts as singular when σ_min/σ_max of A, with each row scaled by its norm at
        the model's initial configuration, falls below this value.  Near a singular
        configuration the multipliers and the accelerations lose about log10(1/σ_min²) digits;
        the default refuses to go on below 1e-4 (8 digits lost) and names the constraints.
    """

    name: ClassVar[str] = "lagrange"
    least_squares: bool = False
    singular_tolerance: float = 1e-4

    def __post_init__(self) -> None:
        check_parameters(self, singular_tolerance="non-negative", least_squares="flag")

    def bind(self, model: Model) -> "KKTSolver":
        return KKTSolver(model, self.least_squares, self.singular_tolerance, xi=0.0, omega=0.0)

    def compiled(self, solver: "KKTSolver", model: Model) -> "LagrangeKernel | LeastSquaresKernel":
        """The solve of the compiled loops: the bound solver's own."""
        return solver.kernel


@dataclass(frozen=True)
class Baumgarte:
    """Lagrange multipliers with Baumgarte's stabilisation Φ̈ + 2ξωΦ̇ + ω²Φ = 0.

    Defaults ξ = 1 (critical damping) and ω = 10 s⁻¹, the thesis's values.
    """

    name: ClassVar[str] = "baumgarte"
    xi: float = 1.0
    omega: float = 10.0
    least_squares: bool = False
    singular_tolerance: float = 1e-4

    def __post_init__(self) -> None:
        check_parameters(self, xi="non-negative", omega="non-negative", singular_tolerance="non-negative",
                         least_squares="flag")

    def bind(self, model: Model) -> "KKTSolver":
        return KKTSolver(model, self.least_squares, self.singular_tolerance, xi=self.xi, omega=self.omega)

    def compiled(self, solver: "KKTSolver", model: Model) -> "LagrangeKernel | LeastSquaresKernel":
        """The solve of the compiled loops: the bound solver's own."""
        return solver.kernel


class KKTSolver(StatelessSolver):
    """Solves the augmented (KKT) system with an optional Baumgarte right-hand side, or with
    ``least_squares`` its minimum-norm least-squares solution: one call of the compiled
    :func:`_solve` on the :class:`LagrangeKernel` made here, or :func:`_solve_least_squares` on a
    :class:`LeastSquaresKernel` (the compiled loops call the same)."""

    def __init__(self, model: Model, least_squares: bool, singular_tolerance: float, *, xi: float, omega: float):
        super().__init__(model)
        self.least_squares = least_squares
        self.singular_tolerance = singular_tolerance
        self.xi, self.omega = xi, omega
        norms = np.linalg.norm(model.jacobian(model.q0, 0.0), axis=1)
        self.row_scale = 1.0 / np.where(norms > 0, norms, 1.0)
        self.kernel = lagrange_kernel(self, model)

    def accelerations(self, terms: Terms, q: np.ndarray, qd: np.ndarray, t: float) -> Accelerations:
        """Accelerations, multipliers and f_c = -Aᵀλ at one state; raises
        :class:`~cmbs.errors.SingularSystemError` at a rank-deficient A (without
        ``least_squares``).  With ``least_squares``, non-finite terms give NaN accelerations (the
        integrator reports the non-finite state)."""
        qdd, lam = np.empty(self.model.n), np.empty(self.model.m)
        kernel = self.kernel
        status = type(kernel).solve(kernel, (terms.Q, terms.phi, terms.A, terms.gamma, terms.phi_t, terms.M), t, qd,
                                    qdd, lam)
        if status == SINGULAR:
            raise SingularSystemError(self._singular_message(terms, t))
        return Accelerations(qdd, lam, -terms.A.T @ lam)

    def _singular_message(self, terms: Terms, t: float) -> str:
        """Why :func:`_solve` found the system singular, naming the dependent constraints (the
        rank of the row-scaled A by SVD, the constraints by QR with column pivoting on Aᵀ); of
        full rank, within :data:`~cmbs.integrate.continuity.NEAR_SINGULAR` of rank loss, the
        constraint nearest to dependence (an adaptive step that shortens towards a singular
        position ends where the elimination fails, just outside the rank tolerance)."""
        A = terms.A
        scaled = A * self.row_scale[:, None]
        sigma = np.linalg.svd(scaled, compute_uv=False)
        cutoff = self.singular_tolerance * max(sigma[0], 1.0) if sigma.size else 0.0
        from cmbs.integrate.continuity import NEAR_SINGULAR

        rank = int(np.sum(sigma > cutoff))
        _, _, pivots = linalg.qr(scaled.T, pivoting=True, mode="economic")
        if rank == A.shape[0]:
            ratio = sigma[-1] / max(sigma[0], 1.0) if sigma.size else 1.0
            why = (f"near a singular configuration (σ_min/σ_max of the constraint Jacobian {ratio:.2g}; nearly "
                   f"dependent: {self.model.constraint_names[pivots[-1]]})" if ratio < NEAR_SINGULAR
                   else "(a motion the constraints allow has no mass)")
            return (f"model {self.model.name!r} at t={t:.6g}: the augmented system [M Aᵀ; A 0] is singular {why}. "
                    "Use formulation 'projection' or 'udwadia-kalaba', or least_squares=True")
        dependent = [self.model.constraint_names[k] for k in sorted(pivots[rank:])]
        return (f"model {self.model.name!r} at t={t:.6g}: the constraint Jacobian has rank {rank} < {A.shape[0]} "
                f"(redundant constraints or a singular configuration); dependent: {', '.join(dependent)}. "
                "Use formulation 'projection', 'udwadia-kalaba' or 'penalty', or least_squares=True")


class LagrangeKernel(NamedTuple):
    """Lagrange's or Baumgarte's equations as the compiled loops take them (ξ = ω = 0: Lagrange):
    the singularity tolerance on σ_min/σ_max of the row-scaled A, the row scale, the packed
    :func:`cmbs.dynamics.kkt.schur_workspace` and the augmented system's work arrays."""

    xi: float
    omega: float
    tolerance: float
    row_scale: np.ndarray
    floats: np.ndarray
    integers: np.ndarray
    layout: np.ndarray
    K: np.ndarray
    rhs: np.ndarray


class BandLagrangeKernel(LagrangeKernel):
    """A :class:`LagrangeKernel` whose workspace solves regular systems by band LU (large natural
    models, :func:`cmbs.dynamics.kkt.banded`)."""

    __slots__ = ()


class LeastSquaresKernel(NamedTuple):
    """Lagrange's or Baumgarte's equations solved in the least-squares sense
    (:func:`_solve_least_squares`): ξ, ω and the augmented system's work arrays."""

    xi: float
    omega: float
    K: np.ndarray
    rhs: np.ndarray


def lagrange_kernel(solver: KKTSolver, model: Model) -> LagrangeKernel | LeastSquaresKernel:
    """The kernel of a bound solver (:class:`LeastSquaresKernel` with ``least_squares``), with work
    arrays of its own."""
    n, m = model.n, model.m
    xi, omega = float(solver.xi), float(solver.omega)
    if solver.least_squares:
        return LeastSquaresKernel(xi, omega, np.empty((n + m, n + m)), np.empty(n + m))
    workspace = packed_workspace(model)
    kind = BandLagrangeKernel if banded(*workspace) else LagrangeKernel
    return kind(xi, omega, float(solver.singular_tolerance), np.ascontiguousarray(solver.row_scale, dtype=float),
                *workspace, np.empty((n + m, n + m)), np.empty(n + m))


@njit(cache=True)
def _solve(kernel, terms, t, qd, qdd, lam):
    """q̈, λ of [M Aᵀ; A 0][q̈; λ] = [Q; c], c = γ (Lagrange) or γ - 2ξωΦ̇ - ω²Φ with
    Φ̇ = Aq̇ + Φ_t (Baumgarte), at the terms (Q, Φ, A, γ, Φ_t, M).

    SINGULAR when σ_min/σ_max of the row-scaled A is below the tolerance
    (:func:`~cmbs.dynamics.kkt.certify`, then the Gram matrix's eigenvalues where its bounds are
    inconclusive); :meth:`KKTSolver._singular_message` names the constraints.  Band LU for large
    natural models (a :class:`BandLagrangeKernel`), the Schur complement when A is certified
    regular and M's block positive definite; else, or where band LU meets an exactly zero pivot,
    the full system by Gaussian elimination with partial pivoting.
    """
    Q, phi, A, gamma, phi_t, M = terms
    schur, certified, singular = _checked(kernel, terms, qd)
    if singular:
        return SINGULAR
    c = kernel.rhs[Q.shape[0]:]
    solved = (certified and schur_solve(M, Q, A, c, schur, qdd, lam)) or \
        full_system(M, Q, A, kernel.K, kernel.rhs, qdd, lam)
    return OK if solved else SINGULAR


@njit(cache=True)
def _solve_band(kernel, terms, t, qd, qdd, lam):
    """:func:`_solve` of a :class:`BandLagrangeKernel`: band LU of the augmented system where A
    is not singular (pivoting: A need not be certified)."""
    Q, phi, A, gamma, phi_t, M = terms
    schur, certified, singular = _checked(kernel, terms, qd)
    if singular:
        return SINGULAR
    c = kernel.rhs[Q.shape[0]:]
    solved = band_kkt(Q, A, c, schur, qdd, lam) or full_system(M, Q, A, kernel.K, kernel.rhs, qdd, lam)
    return OK if solved else SINGULAR


@njit(cache=True, inline="always")
def _checked(kernel, terms, qd):
    """(workspace, certified, singular) for :func:`_solve`: the workspace's views, whether the
    bounds certify A regular, and whether σ_min/σ_max of the row-scaled A is below the tolerance;
    where it is not, c into ``kernel.rhs[n:]``.  The regular system's solve is the caller's (a
    call between would pass the workspace's views at every evaluation: 20 % of a four-bar's RK4
    run)."""
    Q, phi, A, gamma, phi_t, M = terms
    schur = unpack_workspace(kernel.floats, kernel.integers, kernel.layout)
    singular, certified, decided = certify(A, kernel.row_scale, kernel.tolerance, schur[27], schur[28], schur[7],
                                           schur[8], schur[13], schur[14], schur[15])
    if not decided:
        singular = gram_singular(schur[7], kernel.tolerance)
    if not singular:
        _constraint_rhs(kernel, phi, A, gamma, phi_t, qd)
    return schur, certified, singular


@njit(cache=True)
def _solve_least_squares(kernel, terms, t, qd, qdd, lam):
    """:func:`_solve`'s system solved in the least-squares sense: the minimum-norm solution
    (:func:`_minimum_norm`), for any rank of A; OK, or NON_FINITE for non-finite terms."""
    Q, phi, A, gamma, phi_t, M = terms
    _constraint_rhs(kernel, phi, A, gamma, phi_t, qd)
    return _minimum_norm(M, Q, A, kernel.K, kernel.rhs, qdd, lam)


@njit(cache=True, inline="always")
def _constraint_rhs(kernel, phi, A, gamma, phi_t, qd):
    """c into ``kernel.rhs[n:]``: γ, or with Baumgarte's ω ≠ 0 γ - 2ξωΦ̇ - ω²Φ, Φ̇ = Aq̇ + Φ_t."""
    n = qd.shape[0]
    rhs = kernel.rhs
    xi, omega = kernel.xi, kernel.omega
    for r in range(gamma.shape[0]):
        value = gamma[r]
        if omega != 0.0:
            rate = phi_t[r]
            for j in range(n):
                rate += A[r, j] * qd[j]
            value -= 2.0 * xi * omega * rate + omega * omega * phi[r]
        rhs[n + r] = value


#: The machine epsilon of float64, for numpy's default cut-off of ``np.linalg.lstsq``.
EPSILON = float(np.finfo(np.float64).eps)


@njit(cache=True)
def _minimum_norm(M, Q, A, K, rhs, qdd, lam):
    """q̈, λ as the minimum-norm least-squares solution of [M Aᵀ; A 0][q̈; λ] = [Q; c] (c given in
    ``rhs[n:]``; K and ``rhs[:n]`` written here), for any rank of A: LAPACK's gelsd (the SVD of
    K) through ``np.linalg.lstsq`` with numpy's default ``rcond=None``, i.e. singular values up to
    ε·max(rows, columns)·σ_max = ε·(n + m)·σ_max count as zero (numba passes ``rcond`` to gelsd as
    it is, numpy computes this value from None: the same call).  Returns OK, or NON_FINITE with
    NaN outputs when K or the right-hand side is not finite (gelsd would refuse them)."""
    n, m = qdd.shape[0], lam.shape[0]
    assemble_kkt(M, Q, A, K, rhs)
    if not (all_finite(K) and all_finite(rhs)):
        qdd[:] = np.nan
        lam[:] = np.nan
        return NON_FINITE
    solution = np.linalg.lstsq(K, rhs, EPSILON * (n + m))[0]
    for i in range(n):
        qdd[i] = solution[i]
    for r in range(m):
        lam[r] = solution[n + r]
    return OK


LagrangeKernel.solve = staticmethod(_solve)
LagrangeKernel.stage_state = LagrangeKernel.after_step = staticmethod(unchanged)
BandLagrangeKernel.solve = staticmethod(_solve_band)
LeastSquaresKernel.solve = staticmethod(_solve_least_squares)
LeastSquaresKernel.stage_state = LeastSquaresKernel.after_step = staticmethod(unchanged)
