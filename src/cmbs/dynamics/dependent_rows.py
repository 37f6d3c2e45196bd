"""The constrained equations of motion when rows of the constraint Jacobian depend on the others
(redundant constraints, e.g. Bricard's mechanism), solved without an SVD and certified against
the SVD pseudo-inverse that the projection and Udwadia-Kalaba define them by.

For a constant, positive definite M (natural coordinates without massless coordinates) and the
rows scaled once, A' = D A, γ' = D γ, λ = D μ (D = diag(row_scale)):

1. X = A' M⁻¹ (row r: M⁻¹a'_r), y = M⁻¹Q, the Schur complement S = A' M⁻¹ A'ᵀ, z = A' y - γ'.
2. Cholesky factorisation of S with diagonal pivoting (Higham, *Accuracy and Stability of
   Numerical Algorithms*, 2nd ed., 2002, §10.3; LAPACK ``dpstrf``): each step takes the row of
   the largest remaining diagonal and the factorisation stops, at rank r, when the remaining
   diagonals sum to at most ``STOP`` times the largest diagonal of S.  The first r pivots I are
   kept; the others, R, are the dependent rows.
3. μ_I = S_II⁻¹ z_I and q̈ = y - X_Iᵀ μ_I: M q̈ + A'_Iᵀ μ_I = Q and A'_I q̈ = γ'_I.
4. The dependent rows in terms of the kept ones, a'_k ≈ Σ_j C_kj a'_j with C = S_RI S_II⁻¹
   = L_RI L_II⁻¹ (a triangular solve per dependent row), and the minimum-norm multipliers, as
   the pseudo-inverse (A'ᵀ)⁺ gives them:
   every μ with A'ᵀμ = A'_Iᵀμ_I is μ_basic + N v, N = [-Cᵀ; I], and the shortest one has
   v = (I + C Cᵀ)⁻¹ C μ_I (μ_I then less Cᵀv).

Certificate (what the caller compares with its SVD threshold):

- ρ = ‖A'_R - C A'_I‖_F bounds the singular values that the SVD would find below the r-th:
  (σ²_{r+1} + … + σ²_m)^{1/2} ≤ ρ (Eckart-Young: rows I with C A'_I for rows R are a rank-r
  matrix).  ρ is computed from the rows themselves, so it resolves singular values down to the
  rounding level of A, not of its square.
- σ_r(A')² ≥ σ_min(A'_I)² ≥ λ_min(M) / trace(S_II⁻¹) (removing rows does not raise singular
  values; S_II ≼ A'_I A'_Iᵀ / λ_min(M)), with trace(S_II⁻¹) = ‖L_II⁻¹‖_F²; from one evaluation
  to the next, while the same rows are kept and A'_I has moved little, the bound of the last
  one less the move (Weyl's inequality, :func:`_kept_low`);
- σ_max(A')² ≤ trace(A'A'ᵀ).

When ρ is at most the threshold and σ_r above it, the SVD keeps exactly the r largest singular
values, and its solution differs from this one only by the angle between the row space of A'_I
and the SVD's leading right singular vectors, at most about ρ / σ_r (Wedin's theorem).
"""

from __future__ import annotations

import math

import numpy as np

from cmbs.dynamics.kkt import DENSE, solve_lower, solve_lower_transposed
from cmbs.jit import njit
from cmbs.model.model import Model

#: The pivoted factorisation stops when the remaining diagonals of S sum to at most this times
#: S's largest diagonal: above the rounding of a dependent row (about m·ε), below any row the
#: certificate could keep (σ_r ≥ 1e-4 σ_max squares to 1e-8).
STOP = 1e-12

#: Indices of :func:`solve_dependent_rows`'s certificate: (σ_min(A'_I)² lower bound,
#: trace(A'A'ᵀ), ρ², rank r).
KEPT_LOW, TRACE, RESIDUAL, RANK = range(4)


def dependent_rows(model: Model, M0: np.ndarray, definite: bool) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """What :func:`solve_dependent_rows` needs besides the terms, for ``model`` whose mass matrix at
    q0 is ``M0`` (``definite``: positive definite, no massless coordinates): λ_min(M) (0 when M is
    not constant and definite: the path is not taken), the work floats (the reference of the
    bound's reuse: valid, √bound, its row count, the kept rows (m) and their A' (m × n); then S,
    L⁻¹ and C, each m × m, y (n), z (m), a residual row (n) and the certificate (4); a caller may
    pass fewer rows, e.g. the holonomic ones), the pivot order (m), and the
    path of a formulation's last evaluation (1: dependent rows, which it then tries first).  A
    formulation's kernel carries the four as fields (numba's parallel loops take no tuple nested
    in a kernel's)."""
    m, n = model.m, model.n
    mass_low = float(np.linalg.eigvalsh(M0)[0]) if model.constant_mass and definite and m else 0.0
    return mass_low, *dependent_rows_arrays(m, n)


def dependent_rows_arrays(m: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The work floats, pivot order and last path of :func:`dependent_rows` for m rows, n coordinates."""
    return (np.zeros(3 + m + m * n + 3 * m * m + 2 * n + m + 4), np.zeros(m, dtype=np.int64),
            np.zeros(1, dtype=np.int64))


@njit(cache=True)
def solve_dependent_rows(mass_low, floats, order, inverse_mass, Q, A, gamma, row_scale, X, columns, counts, qdd,
                         lam):
    """q̈ and the minimum-norm λ of [M Aᵀ; A 0][q̈; λ] = [Q; γ] by the pivoted Schur complement
    of the module docstring, with λ_min(M) (``mass_low``) and M⁻¹ (``inverse_mass``) given.

    ``floats`` and ``order`` (:func:`dependent_rows_arrays`), ``X`` (m, n), ``columns`` (m, n)
    and ``counts`` (m,) are work arrays.  Returns the certificate (a view into ``floats``:
    σ_min(A'_I)² lower bound, trace(A'A'ᵀ), ρ², r), or an empty view when a pivot is not
    positive or a result is not finite (nothing is certified then)."""
    m, n = A.shape
    reference = floats[:3 + m + m * n]      # first: its valid flag and row count stay put for any m
    base = 3 + m + m * n
    S = floats[base:base + m * m].reshape((m, m))
    T = floats[base + m * m:base + 2 * m * m].reshape((m, m))
    C = floats[base + 2 * m * m:base + 3 * m * m].reshape((m, m))
    y = floats[base + 3 * m * m:base + 3 * m * m + n]
    z = floats[base + 3 * m * m + n:base + 3 * m * m + n + m]
    residual = floats[base + 3 * m * m + n + m:base + 3 * m * m + 2 * n + m]
    certificate = floats[base + 3 * m * m + 2 * n + m:base + 3 * m * m + 2 * n + m + 4]
    trace_gram = 0.0
    for r in range(m):                      # A's row non-zeros; X = A' M⁻¹
        count = 0
        for j in range(n):
            value = A[r, j]
            if value != 0.0:
                columns[r, count] = j
                count += 1
                trace_gram += value * value * row_scale[r] * row_scale[r]
        counts[r] = count
        for i in range(n):                  # row r of X = Σ_t A[r, c_t] M⁻¹[c_t, :] (M⁻¹ symmetric)
            X[r, i] = 0.0
        for t in range(count):
            value = A[r, columns[r, t]]
            for i in range(n):
                X[r, i] += inverse_mass[columns[r, t], i] * value
        for i in range(n):
            X[r, i] *= row_scale[r]
    for i in range(n):
        total = 0.0
        for j in range(n):
            total += inverse_mass[i, j] * Q[j]
        y[i] = total
    largest = 0.0
    for a in range(m):                      # S (its upper triangle) and z
        order[a] = a
        total = -gamma[a]
        for t in range(counts[a]):
            total += A[a, columns[a, t]] * y[columns[a, t]]
        z[a] = total * row_scale[a]
        for b in range(a + 1):
            value = 0.0
            for t in range(counts[a]):
                value += A[a, columns[a, t]] * X[b, columns[a, t]]
            S[b, a] = value * row_scale[a]
        largest = max(largest, S[a, a])
    rank = _pivoted_cholesky(S, z, order, STOP * largest)
    if rank <= 0:                           # not semi-definite, or no row to keep: nothing certified
        return certificate[:0]
    _solve_kept(S, rank, z)
    kept_low = _kept_low(mass_low, S, rank, T, A, row_scale, order, reference)
    dependent = m - rank
    kept = S[:rank, :rank]
    for k in range(dependent):              # C_k = L_II⁻ᵀ l_k (l_k: row rank + k of L)
        row = C[k, :rank]
        for j in range(rank):
            row[j] = S[rank + k, j]
        solve_lower_transposed(kept, DENSE, row)
    residual_squared = _dependency_residual(A, row_scale, columns, counts, order, C, rank, residual)
    for i in range(n):                      # q̈ from the basic multipliers: A'_I q̈ = γ'_I exactly
        total = y[i]
        for k in range(rank):
            total -= X[order[k], i] * z[k]
        qdd[i] = total
    _minimum_norm(C, rank, dependent, z, T)
    for k in range(m):
        lam[order[k]] = z[k] * row_scale[order[k]]
    for i in range(n):
        if not math.isfinite(qdd[i]):
            return certificate[:0]
    certificate[KEPT_LOW] = kept_low
    certificate[TRACE] = trace_gram
    certificate[RESIDUAL] = residual_squared
    certificate[RANK] = rank
    return certificate


#: The lower bound on σ_min(A'_I)² is reused while A'_I has moved by at most this fraction of the
#: bound's square root (Frobenius norm): the reused bound then loses at most 19 %.
REUSE = 0.1


@njit(cache=True)
def _kept_low(mass_low, L, rank, T, A, row_scale, order, reference):
    """A lower bound on σ_min(A'_I)² for the kept rows I = order[:rank]: λ_min(M) / trace(S_II⁻¹)
    (module docstring; trace(S_II⁻¹) = ‖L_II⁻¹‖_F², L⁻¹ left in ``T``), or, when the rows kept are
    those of the bound last computed for as many rows (``reference``: valid, its √bound b₀, its
    row count, the rows kept (1.0), their A'₀ (m × n)) and δ = ‖A'_I - A'₀_I‖_F ≤ REUSE·b₀, the bound (b₀ - δ)², by Weyl's
    inequality for singular values, σ_min(A'_I) ≥ σ_min(A'₀_I) - ‖A'_I - A'₀_I‖₂ (Golub & Van
    Loan, Cor. 8.6.2): a step moves A little, so most evaluations skip L⁻¹.  A fresh bound
    becomes the reference."""
    m, n = A.shape
    kept_rows = reference[3:3 + m]
    A0 = reference[3 + m:3 + m + m * n].reshape((m, n))
    if reference[0] == 1.0 and reference[2] == m:
        same = True
        count = 0
        for r in range(m):
            count += kept_rows[r] == 1.0
        if count != rank:
            same = False
        for k in range(rank):
            if kept_rows[order[k]] != 1.0:
                same = False
        if same:
            total = 0.0
            for k in range(rank):
                r = order[k]
                for j in range(n):
                    difference = (A[r, j] - A0[r, j]) * row_scale[r]
                    total += difference * difference
            delta = math.sqrt(total)
            if delta <= REUSE * reference[1]:
                return (reference[1] - delta) ** 2
    low = mass_low / _inverse_frobenius_squared(L, rank, T)
    reference[0], reference[1], reference[2] = 1.0, math.sqrt(low), m
    for r in range(m):
        kept_rows[r] = 0.0
    for k in range(rank):
        r = order[k]
        kept_rows[r] = 1.0
        for j in range(n):
            A0[r, j] = A[r, j]
    return low


@njit(cache=True)
def _pivoted_cholesky(S, z, order, stop):
    """Lower Cholesky factor of the symmetric positive semi-definite S (given in its upper
    triangle) with diagonal pivoting, until the remaining diagonals sum to at most ``stop``; rows
    and columns are swapped in S, and alike in ``z`` and ``order``.  Right-looking on the upper
    triangle (U = Lᵀ: the updates run along rows, which are contiguous), then L = Uᵀ written to
    the lower triangle.  Returns the rank reached, or -1 when a pivot is not positive (S not
    semi-definite to rounding)."""
    m = S.shape[0]
    rank = m
    for k in range(m):
        pivot, remaining = k, 0.0
        for j in range(k, m):
            remaining += S[j, j]
            if S[j, j] > S[pivot, pivot]:
                pivot = j
        if remaining <= stop:
            rank = k
            break
        if S[pivot, pivot] <= 0.0:
            return -1
        if pivot != k:
            _swap_symmetric(S, k, pivot)
            z[k], z[pivot] = z[pivot], z[k]
            order[k], order[pivot] = order[pivot], order[k]
        diagonal = math.sqrt(S[k, k])
        S[k, k] = diagonal
        for i in range(k + 1, m):
            S[k, i] /= diagonal
        for j in range(k + 1, m):
            factor = S[k, j]
            target, source = S[j, j:], S[k, j:]     # from 0: numba's loop then vectorizes
            for i in range(target.shape[0]):
                target[i] -= source[i] * factor
    for i in range(m):
        for j in range(i):
            S[i, j] = S[j, i]
    return rank


@njit(cache=True, inline="always")
def _swap_symmetric(S, k, p):
    """Swap rows and columns k < p of the symmetric matrix held in S's upper triangle, together
    with columns k and p of the factor's rows before k."""
    for j in range(k):
        S[j, k], S[j, p] = S[j, p], S[j, k]
    S[k, k], S[p, p] = S[p, p], S[k, k]
    for j in range(k + 1, p):
        S[k, j], S[j, p] = S[j, p], S[k, j]
    for i in range(p + 1, S.shape[0]):
        S[k, i], S[p, i] = S[p, i], S[k, i]


@njit(cache=True, inline="always")
def _solve_kept(L, rank, z):
    """z[:rank] ← S_II⁻¹ z[:rank] with S_II = L Lᵀ, L the leading rank × rank block of ``L``."""
    block, head = L[:rank, :rank], z[:rank]
    solve_lower(block, DENSE, head)
    solve_lower_transposed(block, DENSE, head)


@njit(cache=True)
def _inverse_frobenius_squared(L, rank, T):
    """‖L⁻¹‖_F² = trace(S_II⁻¹) of the leading rank × rank block of the lower factor ``L``, with
    W = L⁻¹ left in ``T``'s lower triangle, row by row: W_i = (e_i − Σ_{k<i} L_ik W_k) / L_ii
    (rows are contiguous)."""
    total = 0.0
    for i in range(rank):
        for j in range(i):
            T[i, j] = 0.0
        for k in range(i):
            value = L[i, k]
            for j in range(k + 1):
                T[i, j] -= value * T[k, j]
        for j in range(i):
            T[i, j] /= L[i, i]
            total += T[i, j] * T[i, j]
        T[i, i] = 1.0 / L[i, i]
        total += T[i, i] * T[i, i]
    return total


@njit(cache=True)
def _dependency_residual(A, row_scale, columns, counts, order, C, rank, residual):
    """ρ² = Σ_k ‖a'_k - Σ_j C_kj a'_j‖² over the dependent rows k (pivot positions ≥ rank) from the
    rows of A themselves (``residual``: an n-vector of scratch)."""
    m = A.shape[0]
    total = 0.0
    for k in range(m - rank):
        row = order[rank + k]
        for i in range(residual.shape[0]):
            residual[i] = 0.0
        for t in range(counts[row]):
            residual[columns[row, t]] = A[row, columns[row, t]] * row_scale[row]
        for j in range(rank):
            coefficient = C[k, j]
            kept = order[j]
            for t in range(counts[kept]):
                residual[columns[kept, t]] -= coefficient * A[kept, columns[kept, t]] * row_scale[kept]
        for i in range(residual.shape[0]):
            total += residual[i] * residual[i]
    return total


@njit(cache=True)
def _minimum_norm(C, rank, dependent, z, G):
    """The minimum-norm multipliers from the basic ones μ_I = z[:rank] (μ_R = 0): v = (I + C Cᵀ)⁻¹
    C μ_I into z[rank:], then z[:rank] -= Cᵀ v (``G``: dependent × dependent scratch)."""
    if dependent == 0:
        return
    for a in range(dependent):
        total = 0.0
        for j in range(rank):
            total += C[a, j] * z[j]
        z[rank + a] = total
        for b in range(a + 1):
            value = 1.0 if a == b else 0.0
            for j in range(rank):
                value += C[a, j] * C[b, j]
            G[a, b] = value
    for k in range(dependent):              # I + C Cᵀ ≥ I: Cholesky without pivoting
        G[k, k] = math.sqrt(G[k, k])
        for i in range(k + 1, dependent):
            G[i, k] /= G[k, k]
        for j in range(k + 1, dependent):
            for i in range(j, dependent):
                G[i, j] -= G[i, k] * G[j, k]
    tail = z[rank:rank + dependent]
    _solve_kept(G, dependent, tail)
    for j in range(rank):
        total = 0.0
        for a in range(dependent):
            total += C[a, j] * tail[a]
        z[j] -= total
