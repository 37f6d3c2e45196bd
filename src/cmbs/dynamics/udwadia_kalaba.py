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

The whole solve is one compiled kernel, :func:`_solve_with`, which :class:`UdwadiaKalabaSolver`
and the compiled loops call on the work arrays of one :class:`UdwadiaKalabaKernel` per run: where
A is certified regular (full row rank, no singular value discarded) the ideal equations are the
Lagrange multipliers' augmented system, solved as such (:func:`_regular`); elsewhere (redundant
constraints, singular positions, a non-ideal term) the SVDs above (:func:`udwadia_kalaba_solve`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, ClassVar, NamedTuple

import numpy as np

from cmbs.dynamics.base import OK, Accelerations, StatelessSolver, check_parameters
from cmbs.dynamics.dense import NOT_POSITIVE_DEFINITE, add_scaled_gram, all_finite, fill_nan, multiply, \
    multiply_transposed
from cmbs.dynamics.dependent_rows import KEPT_LOW, RESIDUAL, dependent_rows, solve_dependent_rows
from cmbs.dynamics.field import unchanged
from cmbs.dynamics.kkt import DENSE, band_kkt, banded, bounds_meeting, cholesky_in_place, packed_workspace, \
    schur_solve, solve_lower, solve_lower_transposed, unpack_workspace
from cmbs.dynamics.projection import PROJECTION_REGULAR, reference_row_scale, row_scaled_svd_agrees
from cmbs.errors import CmbsError, SingularSystemError
from cmbs.jit import njit
from cmbs.model.compiled import model_kernel
from cmbs.model.model import Model, Terms


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

    def compiled(self, solver: "UdwadiaKalabaSolver", model: Model) -> "UdwadiaKalabaKernel | None":
        """The solve of the compiled loops on the solver's factor and work arrays (None with a
        ``nonideal`` term: a Python callable)."""
        return None if self.nonideal is not None else solver.kernel


class UdwadiaKalabaSolver(StatelessSolver):
    """Udwadia-Kalaba for one run: each evaluation is one call of the compiled :func:`_solve_with`
    on the :class:`UdwadiaKalabaKernel` made here (the compiled loops call the same).  A constant,
    definite mass matrix is factored once, here."""

    def __init__(self, model: Model, parameters: UdwadiaKalaba):
        super().__init__(model)
        self.p = parameters
        M0 = model.mass_matrix(model.q0)
        self.scale = float(np.trace(M0)) / model.n
        self.mass_scale = np.sqrt(self.scale)  # B = A L⁻ᵀ: rows of A scaled by about 1/√m
        self.semi_definite = bool(np.linalg.eigvalsh(M0)[0] <= 1e-12 * max(np.abs(M0).max(), 1.0))
        self.row_scale = reference_row_scale(model)
        self.factor = np.array(M0, dtype=float)
        self.factored = False
        if model.constant_mass and not self.semi_definite:
            self.factored = cholesky_in_place(self.factor, DENSE)    # else factored at each evaluation
        self.augmentation = self.scale if self.semi_definite else 0.0
        self.threshold = float(parameters.threshold)    # the kernel's argument type
        self.work_matrix = np.zeros((model.m, model.n))
        self.vectors_n = np.zeros((3, model.n))
        self.vectors_m = np.zeros((2, model.m))
        self.no_nonideal = np.zeros(0)
        workspace = packed_workspace(model) if model_kernel(model) is not None else None
        kind = BandUdwadiaKalabaKernel if workspace is not None and banded(*workspace) else UdwadiaKalabaKernel
        self.kernel = kind(
            self.augmentation, self.factored, self.threshold, self.row_scale, float(self.mass_scale), self.factor,
            self.work_matrix, self.vectors_n, self.vectors_m, np.zeros(model.n), self.no_nonideal,
            workspace is not None, *(workspace or (np.zeros(0), np.zeros(0, dtype=np.int64), NO_WORKSPACE)),
            *dependent_rows(model, M0, self.factored and workspace is not None))

    def accelerations(self, terms: Terms, q: np.ndarray, qd: np.ndarray, t: float) -> Accelerations:
        """Udwadia-Kalaba's accelerations at one state.

        Raises :class:`~cmbs.errors.SingularSystemError` when the mass matrix (M + sAᵀA for a
        semi-definite M) is not positive definite, :class:`~cmbs.errors.CmbsError` when
        ``nonideal`` does not return n values; a non-finite term gives NaN accelerations (the
        integrator reports the non-finite state)."""
        m, n = terms.A.shape
        if (m, n) != (self.model.m, self.model.n):
            raise ValueError(f"terms of shape A {terms.A.shape} for model {self.model.name!r} "
                             f"(m = {self.model.m}, n = {self.model.n})")
        c = self.no_nonideal if self.p.nonideal is None else self._nonideal(t, q, qd)
        qdd, lam = np.empty(n), np.empty(m)
        kernel = self.kernel
        status = type(kernel).solve_with(kernel, terms.M, terms.Q, terms.A, terms.gamma, c, qdd, lam)
        force = self.kernel.force.copy()
        if status == NOT_POSITIVE_DEFINITE:
            matrix = f"M + s AᵀA (s = {self.scale:.3g})" if self.semi_definite else "the mass matrix M"
            raise SingularSystemError(f"model {self.model.name!r} at t={t:.6g}: {matrix} is not positive definite "
                                      "(Udwadia-Kalaba needs a mass matrix that is positive definite on the motions "
                                      "the constraints allow)")
        return Accelerations(qdd, lam, force)

    def _nonideal(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """c = nonideal(t, q, q̇) as n floats (CmbsError naming its shape otherwise)."""
        c = np.asarray(self.p.nonideal(t, q, qd), dtype=float)
        if c.shape != (self.model.n,):
            raise CmbsError(f"udwadia-kalaba: nonideal(t, q, qd) must return {self.model.n} values (one per "
                            f"coordinate of model {self.model.name!r}), got shape {c.shape}")
        return c


@njit(cache=True)
def udwadia_kalaba_solve(M: np.ndarray, Q: np.ndarray, A: np.ndarray, gamma: np.ndarray, c: np.ndarray,
                         augmentation: float, factored: bool, threshold: float, row_scale: np.ndarray,
                         mass_scale: float, factor: np.ndarray, work_matrix: np.ndarray, vectors_n: np.ndarray,
                         vectors_m: np.ndarray, qdd: np.ndarray, lam: np.ndarray, force: np.ndarray) -> int:
    """Udwadia-Kalaba's q̈, λ and constraint force Q_c = M q̈ - Q (module docstring) at one state,
    written into ``qdd`` (n,), ``lam`` (m,) and ``force`` (n,).  Returns the status:
    :data:`~cmbs.dynamics.base.OK`, ``NOT_POSITIVE_DEFINITE`` (outputs not written) or
    ``NON_FINITE`` (outputs NaN).

    ``c`` is the non-ideal vector (n,), or empty for none.  ``augmentation`` s > 0 factors
    M̂ = M + sAᵀA with Q̂ = Q + sAᵀγ (semi-definite M), 0 factors M itself, unless ``factored``:
    ``factor`` then already holds the Cholesky factor L of the constant M.  B = A L⁻ᵀ; its
    pseudo-inverse is that of :func:`cmbs.dynamics.projection.pseudo_inverse` with rows scaled
    by D = diag(``row_scale`` · ``mass_scale``) (SVD of D B, singular values ≤ ``threshold``
    discarded, B⁺ = (D B)⁺ D), and λ = -(Aᵀ)⁺ Q_c with A's rows scaled by ``row_scale``.

    Work arrays: ``factor`` (n, n), ``work_matrix`` (m, n), ``vectors_n`` (3, n), ``vectors_m``
    (2, m).
    """
    m, n = A.shape
    a, scaled_force, extra = vectors_n[0], vectors_n[1], vectors_n[2]
    residual, coefficients = vectors_m[0], vectors_m[1]
    for j in range(n):
        a[j] = Q[j]
    if augmentation > 0.0:                                  # M̂ = M + sAᵀA, Q̂ = Q + sAᵀγ
        add_scaled_gram(M, A, augmentation, factor)
        multiply_transposed(A, gamma, scaled_force)
        for j in range(n):
            a[j] += augmentation * scaled_force[j]
    elif not factored:
        for i in range(n):
            for j in range(n):
                factor[i, j] = M[i, j]
    if not (factored or cholesky_in_place(factor, DENSE)):
        if all_finite(M) and all_finite(A) and (augmentation == 0.0 or all_finite(gamma)):
            return NOT_POSITIVE_DEFINITE
        return fill_nan(qdd, lam, force)
    solve_lower(factor, DENSE, a)                           # a = M̂⁻¹ Q̂
    solve_lower_transposed(factor, DENSE, a)
    multiply(A, a, residual)
    for i in range(m):
        residual[i] = gamma[i] - residual[i]                # γ - A a
    scaled_B = work_matrix
    for i in range(m):                                      # row i of D B = d_i (L⁻¹ A[i])ᵀ
        row = scaled_B[i]
        for j in range(n):
            row[j] = A[i, j]
        solve_lower(factor, DENSE, row)
        row *= row_scale[i] * mass_scale
    if not (all_finite(a) and all_finite(scaled_B) and all_finite(residual) and all_finite(c)):
        return fill_nan(qdd, lam, force)
    scaled_force[:] = 0.0
    if m:
        U, sigma, Vt = np.linalg.svd(scaled_B, full_matrices=False)
        rank = _rank(sigma, threshold)
        for i in range(m):
            residual[i] *= row_scale[i] * mass_scale        # D (γ - A a)
        _apply_pseudo_inverse(U, sigma, Vt, rank, residual, coefficients, scaled_force)    # B⁺ (γ - A a)
    if c.size:                                              # + (I - B⁺B) L⁻¹ c
        for j in range(n):
            extra[j] = c[j]
        solve_lower(factor, DENSE, extra)
        if m:
            _remove_range(Vt, rank, extra)
        scaled_force += extra
    solve_lower_transposed(factor, DENSE, scaled_force)     # L⁻ᵀ (...)
    for j in range(n):
        qdd[j] = a[j] + scaled_force[j]
    multiply(M, qdd, force)
    force -= Q                                              # Q_c = M q̈ - Q (ideal + non-ideal)
    if m:
        for i in range(m):
            for j in range(n):
                scaled_B[i, j] = A[i, j] * row_scale[i]
        U, sigma, Vt = np.linalg.svd(scaled_B, full_matrices=False)
        _apply_transposed_pseudo_inverse(U, sigma, Vt, _rank(sigma, threshold), force, coefficients, lam)
        for i in range(m):
            lam[i] *= -row_scale[i]                         # λ = -(Aᵀ)⁺ Q_c = -D (D A)ᵀ⁺ Q_c
    if not (all_finite(qdd) and all_finite(lam) and all_finite(force)):
        return fill_nan(qdd, lam, force)
    return OK


@njit(cache=True)
def _rank(sigma: np.ndarray, threshold: float) -> int:
    """How many singular values are above ``threshold`` (they come in decreasing order)."""
    rank = 0
    while rank < sigma.size and sigma[rank] > threshold:
        rank += 1
    return rank


@njit(cache=True)
def _apply_pseudo_inverse(U: np.ndarray, sigma: np.ndarray, Vt: np.ndarray, rank: int, x: np.ndarray,
                          coefficients: np.ndarray, out: np.ndarray) -> None:
    """out ← V Σ⁻¹ Uᵀ x over the first ``rank`` singular triplets (X⁺ x for X = U Σ Vᵀ)."""
    for k in range(rank):
        total = 0.0
        for i in range(U.shape[0]):
            total += U[i, k] * x[i]
        coefficients[k] = total / sigma[k]
    out[:] = 0.0
    for k in range(rank):
        for j in range(Vt.shape[1]):
            out[j] += Vt[k, j] * coefficients[k]


@njit(cache=True)
def _apply_transposed_pseudo_inverse(U: np.ndarray, sigma: np.ndarray, Vt: np.ndarray, rank: int, x: np.ndarray,
                                     coefficients: np.ndarray, out: np.ndarray) -> None:
    """out ← U Σ⁻¹ Vᵀ x over the first ``rank`` singular triplets ((X⁺)ᵀ x for X = U Σ Vᵀ)."""
    for k in range(rank):
        total = 0.0
        for j in range(Vt.shape[1]):
            total += Vt[k, j] * x[j]
        coefficients[k] = total / sigma[k]
    out[:] = 0.0
    for k in range(rank):
        for i in range(U.shape[0]):
            out[i] += U[i, k] * coefficients[k]


@njit(cache=True)
def _remove_range(Vt: np.ndarray, rank: int, x: np.ndarray) -> None:
    """x ← (I - V Vᵀ) x over the first ``rank`` right singular vectors (I - X⁺X for X = U Σ Vᵀ)."""
    for k in range(rank):
        projection = 0.0
        for j in range(x.size):
            projection += Vt[k, j] * x[j]
        for j in range(x.size):
            x[j] -= projection * Vt[k, j]


class UdwadiaKalabaKernel(NamedTuple):
    """Udwadia-Kalaba as its solver and the compiled loops (:mod:`cmbs.dynamics.field`) take it:
    the arguments and work arrays of :func:`udwadia_kalaba_solve`, the constraint force it
    writes, and (``regular_path``, for models with a compiled kernel) the packed
    :func:`cmbs.dynamics.kkt.schur_workspace` of :func:`_regular`; what the path of dependent
    rows needs (:func:`cmbs.dynamics.dependent_rows.dependent_rows`)."""

    augmentation: float
    factored: bool
    threshold: float
    row_scale: np.ndarray
    mass_scale: float
    factor: np.ndarray
    work_matrix: np.ndarray
    vectors_n: np.ndarray
    vectors_m: np.ndarray
    force: np.ndarray
    no_nonideal: np.ndarray
    regular_path: bool
    floats: np.ndarray
    integers: np.ndarray
    layout: np.ndarray
    mass_low: float
    dependent_floats: np.ndarray
    dependent_order: np.ndarray
    last_path: np.ndarray


class BandUdwadiaKalabaKernel(UdwadiaKalabaKernel):
    """An :class:`UdwadiaKalabaKernel` whose workspace solves regular systems by band LU (large
    natural models, :func:`cmbs.dynamics.kkt.banded`)."""

    __slots__ = ()


#: The layout of an empty workspace (a model without a compiled kernel has no regular path).
NO_WORKSPACE = np.zeros((29, 5), dtype=np.int64)


@njit(cache=True, inline="always")
def _solve_with(kernel, M, Q, A, gamma, c, qdd, lam):
    """Udwadia-Kalaba's q̈, λ and constraint force (into ``kernel.force``) with the non-ideal
    vector ``c`` (empty for none): the Schur complement where :func:`_regular` proves it applies,
    the Schur complement of the independent rows where :func:`_by_dependent_rows` proves that
    (tried first after an evaluation that took it), else :func:`udwadia_kalaba_solve`.  Returns
    OK, NOT_POSITIVE_DEFINITE or NON_FINITE."""
    last_path = kernel.last_path
    dependent_first = last_path[0] == 1
    if dependent_first and _by_dependent_rows(kernel, M, Q, A, gamma, c, qdd, lam):
        return OK
    proven, schur = _regular(kernel, M, A, c)
    if proven and schur_solve(M, Q, A, gamma, schur, qdd, lam) and _regular_force(kernel, M, Q, qdd, lam):
        last_path[0] = 0
        return OK
    if not dependent_first and _by_dependent_rows(kernel, M, Q, A, gamma, c, qdd, lam):
        last_path[0] = 1
        return OK
    return _by_svds(kernel, M, Q, A, gamma, c, qdd, lam)


@njit(cache=True, inline="always")
def _by_dependent_rows(kernel, M, Q, A, gamma, c, qdd, lam):
    """Udwadia-Kalaba's ideal solution where rows of A depend on the others (redundant
    constraints): the augmented system of the independent rows
    (:func:`cmbs.dynamics.dependent_rows.solve_dependent_rows`), whose q̈ Gauss's principle gives
    when both pseudo-inverses discard exactly the dependent rows' singular values.  With
    λ_min(M) = μ, D = mass_scale·S and B = A L⁻ᵀ (L Lᵀ = M), the certificate proves it: the
    discarded singular values of DB are at most mass_scale·ρ/√μ (Eckart-Young with
    ‖L⁻¹‖₂ = 1/√μ), the kept ones at least mass_scale (σ_min(A'_I)²/μ)^{1/2}, as DB DBᵀ =
    mass_scale² A' M⁻¹ A'ᵀ; for the λ pseudo-inverse of the row-scaled A the projection's test
    (:func:`cmbs.dynamics.projection._by_dependent_rows`).  Needs a constant, definite M and no
    non-ideal term; returns False otherwise."""
    if c.size != 0 or kernel.mass_low <= 0.0:
        return False
    schur = unpack_workspace(kernel.floats, kernel.integers, kernel.layout)
    if schur[1] != 1:
        return False
    certificate = solve_dependent_rows(kernel.mass_low, kernel.dependent_floats, kernel.dependent_order, schur[0], Q,
                                       A, gamma, kernel.row_scale, schur[2], schur[5], schur[6], qdd, lam)
    if certificate.shape[0] == 0:
        return False
    threshold, low, residual = kernel.threshold, certificate[KEPT_LOW], certificate[RESIDUAL]
    weight = kernel.mass_scale * kernel.mass_scale / kernel.mass_low
    return (row_scaled_svd_agrees(certificate, threshold)
            and weight * low > threshold * threshold and weight * residual <= threshold * threshold
            and _regular_force(kernel, M, Q, qdd, lam))


@njit(cache=True, inline="always")
def _solve_with_band(kernel, M, Q, A, gamma, c, qdd, lam):
    """:func:`_solve_with` of a :class:`BandUdwadiaKalabaKernel`: band LU where :func:`_regular`
    proves it applies."""
    proven, schur = _regular(kernel, M, A, c)
    if proven and band_kkt(Q, A, gamma, schur, qdd, lam) and _regular_force(kernel, M, Q, qdd, lam):
        return OK
    return _by_svds(kernel, M, Q, A, gamma, c, qdd, lam)


@njit(cache=True, inline="always")
def _by_svds(kernel, M, Q, A, gamma, c, qdd, lam):
    """:func:`udwadia_kalaba_solve` with the kernel's settings and work arrays."""
    return udwadia_kalaba_solve(M, Q, A, gamma, c, kernel.augmentation, kernel.factored, kernel.threshold,
                                kernel.row_scale, kernel.mass_scale, kernel.factor, kernel.work_matrix,
                                kernel.vectors_n, kernel.vectors_m, qdd, lam, kernel.force)


@njit(cache=True, inline="always")
def _regular(kernel, M, A, c):
    """(proven, workspace): whether Udwadia-Kalaba's ideal solution, nothing discarded, is the
    augmented system's (False: the caller takes the SVDs), and the workspace's views.

    When A has full row rank and the pseudo-inverses discard no singular value, Gauss's principle
    gives q̈ = a + M̂⁻¹Aᵀ(AM̂⁻¹Aᵀ)⁻¹(γ - Aa): the solution of [M Aᵀ; A 0][q̈; λ] = [Q; γ] (with M̂
    = M + sAᵀA, Q̂ = Q + sAᵀγ the same, since Aq̈ = γ), and λ = -(Aᵀ)⁺(Mq̈ - Q) is that system's
    unique multiplier.  The Gram bounds of :func:`~cmbs.dynamics.kkt.bounds_meeting` prove it:
    σ_min(SA)² ≥ low ≥ (1e-4)² max(σ_max², 1) and low > threshold² (the λ pseudo-inverse of the
    row-scaled A keeps everything), and for B = AL⁻ᵀ scaled by D = mass_scale·S,
    σ_min(DB)² ≥ mass_scale² low / λ_max(M̂) ≥ mass_scale² low / trace M̂ > threshold² (the q̈
    pseudo-inverse keeps everything).  The caller solves it as the projection's regular path
    (:func:`cmbs.dynamics.projection._by_schur`): the Schur complement, or band LU for a
    :class:`BandUdwadiaKalabaKernel`."""
    schur = unpack_workspace(kernel.floats, kernel.integers, kernel.layout)
    m, n = A.shape
    if c.size != 0 or not kernel.regular_path or m == 0 or m > n:
        return False, schur
    low, high = bounds_meeting(A, kernel.row_scale, PROJECTION_REGULAR, kernel.threshold, schur[27], schur[28],
                               schur[7], schur[8], schur[13], schur[14], schur[15])
    threshold = kernel.threshold
    if low < PROJECTION_REGULAR * PROJECTION_REGULAR * max(high, 1.0) or low <= threshold * threshold:
        return False, schur
    trace = 0.0
    for j in range(n):
        trace += M[j, j]
        for i in range(m):
            trace += kernel.augmentation * A[i, j] * A[i, j]
    return kernel.mass_scale * kernel.mass_scale * low > threshold * threshold * trace, schur


@njit(cache=True, inline="always")
def _regular_force(kernel, M, Q, qdd, lam):
    """The constraint force Q_c = M q̈ - Q of the augmented system's solution into ``kernel.force``;
    whether q̈ and λ are finite."""
    force = kernel.force
    multiply(M, qdd, force)
    force -= Q
    return all_finite(qdd) and all_finite(lam)


@njit(cache=True, inline="always")
def _kernel_solve(kernel, terms, t, qd, qdd, lam):
    """:func:`_solve_with` at the terms (Q, Φ, A, γ, Φ_t, M) without a non-ideal term; status OK,
    SINGULAR (the mass matrix to factor is not positive definite) or NON_FINITE."""
    Q, phi, A, gamma, phi_t, M = terms
    return _solve_with(kernel, M, Q, A, gamma, kernel.no_nonideal, qdd, lam)


@njit(cache=True, inline="always")
def _kernel_solve_band(kernel, terms, t, qd, qdd, lam):
    """:func:`_kernel_solve` of a :class:`BandUdwadiaKalabaKernel`."""
    Q, phi, A, gamma, phi_t, M = terms
    return _solve_with_band(kernel, M, Q, A, gamma, kernel.no_nonideal, qdd, lam)


UdwadiaKalabaKernel.solve = staticmethod(_kernel_solve)
UdwadiaKalabaKernel.stage_state = UdwadiaKalabaKernel.after_step = staticmethod(unchanged)
UdwadiaKalabaKernel.solve_with = staticmethod(_solve_with)
BandUdwadiaKalabaKernel.solve = staticmethod(_kernel_solve_band)
BandUdwadiaKalabaKernel.solve_with = staticmethod(_solve_with_band)
