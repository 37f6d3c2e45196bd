"""The linear algebra of the constrained equations of motion, compiled: the saddle-point
(KKT) system [M Aᵀ; A 0][q̈; λ] = [Q; c] and the rank certificate of the constraint Jacobian.

- :func:`schur_solve`: block elimination on the coordinates that carry mass (the range-space
  method) with M's constant factor or a Cholesky factor per call; :func:`band_kkt`: band LU of
  the whole system for large natural models; :func:`full_system`: Gaussian elimination with
  partial pivoting, the path for everything else.
- :func:`certify` and :func:`bounds_meeting`: cheap bounds on the extreme singular values of the
  row-scaled A (Gram matrix traces, reused from step to step by Weyl's inequality) that prove A
  regular without an SVD at almost every evaluation.
- :func:`schur_workspace` sizes every work array once per model; :func:`pack_workspace` and
  :func:`unpack_workspace` carry them as three arrays.

The formulations (:mod:`cmbs.dynamics.lagrange`, :mod:`cmbs.dynamics.projection`) call these.
"""

from __future__ import annotations

import math
import weakref

import numpy as np

from cmbs.banded import band_factor, band_plan, band_solve, gram_profile, inverse_trace, jacobian_pattern
from cmbs.jit import njit
from cmbs.model.compiled import model_kernel
from cmbs.model.model import Model


def pack_workspace(schur: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The :func:`schur_workspace` tuple as three arrays (floats, ints, layout), which a call from
    Python unboxes in a fraction of the time its 27 entries take (about 1.6 µs, more than the
    four-bar's whole evaluation).  ``layout[k]`` = (0: float array, 1: int array, 2: scalar;
    offset or scalar value; rows; columns; dimensions), a 1-D array having one column."""
    floats, integers, layout = [], [], []
    sizes = [0, 0]
    for entry in schur:
        if isinstance(entry, (int, np.integer)):
            layout.append((2, int(entry), 0, 0, 0))
            continue
        array = np.ascontiguousarray(entry)
        group = 0 if array.dtype == np.float64 else 1
        rows, columns = (array.shape[0], 1) if array.ndim == 1 else array.shape
        layout.append((group, sizes[group], rows, columns, array.ndim))
        (floats if group == 0 else integers).append(array.ravel().astype(np.float64 if group == 0 else np.int64))
        sizes[group] += array.size
    return (np.concatenate(floats) if floats else np.zeros(0), np.concatenate(integers) if integers else
            np.zeros(0, dtype=np.int64), np.array(layout, dtype=np.int64))


def workspace_views(floats: np.ndarray, integers: np.ndarray, layout: np.ndarray) -> tuple:
    """The :func:`schur_workspace` tuple from :func:`pack_workspace`'s arrays, for Python callers
    (views; compiled code unpacks with :func:`unpack_workspace`)."""
    entries = []
    for group, start, rows, columns, dimensions in layout:
        if group == 2:
            entries.append(int(start))
            continue
        values = (floats if group == 0 else integers)[start:start + rows * columns]
        entries.append(values.reshape((rows, columns)) if dimensions == 2 else values)
    return tuple(entries)


@njit(cache=True, inline="always")
def _matrix(values, layout, k):
    return values[layout[k, 1]:layout[k, 1] + layout[k, 2] * layout[k, 3]].reshape((layout[k, 2], layout[k, 3]))


@njit(cache=True, inline="always")
def _vector(values, layout, k):
    return values[layout[k, 1]:layout[k, 1] + layout[k, 2]]


@njit(cache=True, inline="always")
def unpack_workspace(floats, integers, layout):
    """The :func:`schur_workspace` tuple again from :func:`pack_workspace`'s arrays (views)."""
    return (_matrix(floats, layout, 0), layout[1, 1], _matrix(floats, layout, 2), _matrix(floats, layout, 3),
            _vector(floats, layout, 4), _matrix(integers, layout, 5), _vector(integers, layout, 6),
            _matrix(floats, layout, 7), _matrix(floats, layout, 8), _vector(integers, layout, 9),
            _vector(integers, layout, 10), _vector(floats, layout, 11), _vector(integers, layout, 12),
            _matrix(integers, layout, 13), _vector(integers, layout, 14), _matrix(floats, layout, 15), layout[16, 1],
            layout[17, 1], _matrix(floats, layout, 18), _vector(integers, layout, 19), _vector(floats, layout, 20),
            _vector(integers, layout, 21), _vector(integers, layout, 22), _vector(integers, layout, 23),
            _vector(floats, layout, 24), _vector(integers, layout, 25), _vector(integers, layout, 26),
            _vector(floats, layout, 27), _matrix(floats, layout, 28))


@njit(cache=True)
def _gram_extremes(G):
    """Smallest and largest eigenvalue of the small symmetric matrix ``G`` (overwritten) by
    cyclic Jacobi rotations (Golub & Van Loan §8.5): for a few rows this avoids LAPACK's call
    and workspace overhead, which is larger than the arithmetic."""
    m = G.shape[0]
    for sweep in range(60):
        off = 0.0
        scale = 0.0
        for i in range(m):
            scale += G[i, i] * G[i, i]
            for j in range(i + 1, m):
                off += G[i, j] * G[i, j]
        if off <= 1e-32 * scale:
            break
        for p in range(m - 1):
            for r in range(p + 1, m):
                if G[p, r] == 0.0:
                    continue
                theta = (G[r, r] - G[p, p]) / (2.0 * G[p, r])
                t = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                for k in range(m):      # columns p, r
                    gkp, gkr = G[k, p], G[k, r]
                    G[k, p] = c * gkp - s * gkr
                    G[k, r] = s * gkp + c * gkr
                for k in range(m):      # rows p, r
                    gpk, grk = G[p, k], G[r, k]
                    G[p, k] = c * gpk - s * grk
                    G[r, k] = s * gpk + c * grk
    smallest, largest = G[0, 0], G[0, 0]
    for i in range(1, m):
        smallest = min(smallest, G[i, i])
        largest = max(largest, G[i, i])
    return smallest, largest


@njit(cache=True)
def cholesky_in_place(L, start):
    """Lower Cholesky factor L Lᵀ = K of the symmetric positive definite K given in ``L``'s lower
    triangle, in place (the upper triangle is not read).  ``start[i]`` is the first column of
    row i that may be non-zero (the profile of K, which the factor keeps: George & Liu 1981
    §4.2); :data:`DENSE` (or zeros) for a dense K.  Returns False when K is not numerically
    positive definite (a pivot ≤ 0 or NaN; ``L`` then partly overwritten)."""
    size = L.shape[0]
    for j in range(size):
        pivot = L[j, j]
        for k in range(_first(start, j), j):
            pivot -= L[j, k] * L[j, k]
        if not pivot > 0.0:
            return False
        pivot = math.sqrt(pivot)
        L[j, j] = pivot
        for i in range(j + 1, size):
            if _first(start, i) > j:
                continue
            total = L[i, j]
            for k in range(max(_first(start, i), _first(start, j)), j):
                total -= L[i, k] * L[j, k]
            L[i, j] = total / pivot
    return True


#: The profile argument of :func:`cholesky_in_place`, :func:`solve_lower` and
#: :func:`solve_lower_transposed` for a dense matrix.
DENSE = np.zeros(0, dtype=np.int64)


@njit(cache=True, inline="always")
def _first(start, i):
    """The first column of row i in the profile ``start`` (0 for :data:`DENSE`)."""
    return start[i] if start.shape[0] else 0


@njit(cache=True)
def solve_lower(L, start, b):
    """Solve L x = b in place for the lower triangular L with row profile ``start``."""
    for i in range(L.shape[0]):
        total = b[i]
        for k in range(_first(start, i), i):
            total -= L[i, k] * b[k]
        b[i] = total / L[i, i]


@njit(cache=True)
def solve_lower_transposed(L, start, b):
    """Solve Lᵀ x = b in place for the lower triangular L with row profile ``start``."""
    for i in range(L.shape[0] - 1, -1, -1):
        b[i] /= L[i, i]
        for k in range(_first(start, i), i):
            b[k] -= L[i, k] * b[i]


@njit(cache=True)
def _gram(X, scale, gram, rows_of, start):
    """G = (SX)(SX)ᵀ into ``gram`` (S = diag(scale)), column by column over the rows each column
    touches, so a sparse X costs Σ_k nnz(column k)² instead of rows² x columns.

    ``rows_of`` (columns, rows + 1): row k holds column k's structural rows after their count
    (:func:`column_rows`, from the Jacobian's pattern; G then has the profile ``start`` and only
    that profile is cleared, filled and mirrored: O(m b) for a band), or a count of -1 when there
    is no pattern: the column is then scanned (O(mn)) and G cleared whole.  Entries of G outside
    the profile stay zero from the workspace's creation (callers that overwrite G restore them)."""
    m, n = X.shape
    structured = has_structure(rows_of, n)
    for i in range(m):
        for j in range(start[i] if structured else 0, i + 1 if structured else m):
            gram[i, j] = 0.0
    for k in range(n):
        count = rows_of[k, 0]
        if count < 0:
            count = 0
            for i in range(m):
                if X[i, k] != 0.0:
                    rows_of[k, 1 + count] = i
                    count += 1
            rows_of[k, 0] = -1
        for a in range(count):
            i = rows_of[k, 1 + a]
            xi = X[i, k] * scale[i]
            if xi == 0.0:
                continue
            for b in range(a + 1):
                j = rows_of[k, 1 + b]
                gram[i, j] += xi * X[j, k] * scale[j]
    for i in range(m):
        for j in range(start[i] if structured else 0, i):
            gram[j, i] = gram[i, j]


@njit(cache=True, inline="always")
def has_structure(rows_of, n):
    """True when ``rows_of`` (:func:`column_rows`) lists A's structural rows, False when its
    counts are -1 (no pattern: the columns are scanned)."""
    return n > 0 and rows_of[0, 0] >= 0


def column_rows(pattern: np.ndarray | None, m: int, n: int) -> np.ndarray:
    """The ``rows_of`` workspace of :func:`_gram`: for each column of A's structural ``pattern``
    (m, n), its row count and rows; without a pattern, counts of -1 (scan each call)."""
    rows_of = np.zeros((max(n, 1), m + 1), dtype=np.int64)
    if pattern is None:
        rows_of[:, 0] = -1
        return rows_of
    for k in range(n):
        rows = np.flatnonzero(pattern[:, k])
        rows_of[k, 0] = rows.size
        rows_of[k, 1:1 + rows.size] = rows
    return rows_of


@njit(cache=True)
def gram_bounds(A, row_scale, gram, factor, rows_of, start, Z):
    """Bounds (λ_low, λ_high) on the extreme eigenvalues of the Gram matrix G = (SA)(SA)ᵀ
    (S = diag(row_scale)), left in ``gram``, with λ_low <= λ_min(G) and λ_max(G) <= λ_high:
    λ_high = trace G and λ_low = 1 / trace G⁻¹, because the trace of a positive definite matrix
    lies between its largest eigenvalue and m times it.  trace G⁻¹ comes from the Cholesky
    factor L of G (in ``factor``, keeping G's profile ``start``) by the Takahashi recurrence
    (:func:`cmbs.banded.inverse_trace`, workspace ``Z``): O(m b²) for a profile of half-width b.
    λ_low = 0 when G is not numerically positive definite."""
    m = A.shape[0]
    _gram(A, row_scale, gram, rows_of, start)
    trace = 0.0
    for i in range(m):
        trace += gram[i, i]
        for j in range(start[i], i + 1):
            factor[i, j] = gram[i, j]
    if not cholesky_in_place(factor, start):
        return 0.0, trace
    if Z.shape[1] < m:                      # a narrow profile: O(m b²)
        return 1.0 / inverse_trace(factor, start, Z), trace
    total = 0.0                             # dense: ‖L⁻¹‖_F² column by column, the entries below
    for j in range(m):                      # the diagonal in factor's upper triangle (scratch)
        diagonal = 1.0 / factor[j, j]
        total += diagonal * diagonal
        for i in range(j + 1, m):
            value = -factor[i, j] * diagonal
            for k in range(j + 1, i):
                value -= factor[i, k] * factor[j, k]
            value /= factor[i, i]
            factor[j, i] = value
            total += value * value
    return 1.0 / total, trace


#: Largest m·n for which :func:`bounds` keeps a reference A without A's structure (its test then
#: costs m·n operations; with the structure, one per structural non-zero).
BOUNDS_REUSE_SIZE = 1024


@njit(cache=True, inline="always")
def bounds(A, row_scale, reference, A0, gram, factor, rows_of, start, Z):
    """(λ_low, λ_high, reused): bounds on the extreme eigenvalues of G = (SA)(SA)ᵀ as
    :func:`gram_bounds` gives them, from a reference A₀ bounded earlier when A is close to it.

    By Weyl's inequality for singular values (Golub & Van Loan, Cor. 8.6.2), with
    δ = ‖S(A - A₀)‖_F ≥ ‖S(A - A₀)‖₂: σ_min(SA) ≥ σ_min(SA₀) - δ and σ_max(SA) ≤ σ_max(SA₀) + δ,
    so (√λ₀_low - δ)² and (√λ₀_high + δ)² are bounds again.  Reused while δ ≤ √λ₀_low / 10 (the
    lower bound loses at most 19 %); otherwise, or without a valid reference, the Gram bounds
    are computed afresh (which leaves G in ``gram``: ``reused`` False) and A becomes the
    reference (``reference`` = (valid, √λ_low, √λ_high), ``A0``) when they prove full rank.
    A step moves A little, so most stages of a run skip the Gram matrix, its Cholesky factor and
    trace G⁻¹.  With A's structure (``rows_of`` of :func:`column_rows`), δ and the copy into A₀
    run over the structural non-zeros only: the entries outside are zero in A and A₀ alike."""
    m, n = A.shape
    structured = has_structure(rows_of, n)
    if reference[0] == 1.0:
        total = 0.0
        for j in range(n):
            for a in range(rows_of[j, 0] if structured else m):
                i = rows_of[j, 1 + a] if structured else a
                difference = (A[i, j] - A0[i, j]) * row_scale[i]
                total += difference * difference
        delta = math.sqrt(total)
        if delta <= 0.1 * reference[1]:
            return (reference[1] - delta) ** 2, (reference[2] + delta) ** 2, True
    low, high = gram_bounds(A, row_scale, gram, factor, rows_of, start, Z)
    reference[0] = 0.0
    if low > 0.0 and A0.shape[0] == m:
        for j in range(n):
            for a in range(rows_of[j, 0] if structured else m):
                i = rows_of[j, 1 + a] if structured else a
                A0[i, j] = A[i, j]
        reference[0], reference[1], reference[2] = 1.0, math.sqrt(low), math.sqrt(high)
    return low, high, False


@njit(cache=True, inline="always")
def bounds_meeting(A, row_scale, ratio, floor, reference, A0, gram, factor, rows_of, start, Z):
    """(λ_low, λ_high) of :func:`bounds`, computed afresh (G then in ``gram``) when reused ones
    fail the caller's test λ_low >= ratio²·max(λ_high, 1) and λ_low > floor²: a test lost only
    to the reuse's slack is decided on the fresh bounds."""
    low, high, reused = bounds(A, row_scale, reference, A0, gram, factor, rows_of, start, Z)
    if reused and (low < ratio * ratio * max(high, 1.0) or low <= floor * floor):
        reference[0] = 0.0
        low, high, reused = bounds(A, row_scale, reference, A0, gram, factor, rows_of, start, Z)
    return low, high


@njit(cache=True, inline="always")
def certify(A, row_scale, tolerance, reference, A0, gram, factor, rows_of, start, Z):
    """(singular, certified, decided) for the constraint Jacobian A: ``singular`` when σ_min/σ_max
    of the row-scaled SA is below ``tolerance`` (as KKTSolver's SVD test, with σ_max replaced by
    1 when smaller); ``certified`` when cheap bounds already prove it is not (:func:`bounds`).
    Only uncertified cases pay for the eigenvalues: Jacobi rotations for up to 12 rows
    (:func:`_gram_extremes`); beyond, ``decided`` is False, G is left in ``gram`` (the bounds
    that failed were fresh) and the caller decides by :func:`gram_singular` (LAPACK, which
    creates its work arrays)."""
    m, n = A.shape
    if m == 0:
        return False, True, True
    if m > n:
        return True, False, True
    low, high = bounds_meeting(A, row_scale, tolerance, 0.0, reference, A0, gram, factor, rows_of, start, Z)
    if low >= tolerance * tolerance * max(high, 1.0):
        return False, True, True
    if m > 12:
        return False, False, False
    low, high = _gram_extremes(gram)        # fresh bounds failed: G is in gram
    gram[:, :] = 0.0                        # the rotations filled it: zero outside the profile again
    smallest, largest = math.sqrt(max(low, 0.0)), math.sqrt(max(high, 0.0))
    return smallest < tolerance * max(largest, 1.0), False, True


@njit(cache=True)
def gram_singular(gram, tolerance):
    """The singularity test of :func:`certify` on the Gram matrix ``gram`` = (SA)(SA)ᵀ, by
    LAPACK's symmetric eigenvalues (σ² of SA)."""
    eigenvalues = np.linalg.eigvalsh(gram)
    smallest = math.sqrt(max(eigenvalues[0], 0.0))
    largest = math.sqrt(max(eigenvalues[eigenvalues.shape[0] - 1], 0.0))
    return smallest < tolerance * max(largest, 1.0)



@njit(cache=True, inline="always")
def schur_solve(M, Q, A, c, schur, qdd, lam):
    """q̈, λ of [M Aᵀ; A 0][q̈; λ] = [Q; c] by block elimination of the coordinates p that carry
    mass (the range-space method, Golub & Van Loan §4.2; Nocedal & Wright §16.2).  Split
    q = (p, a) with a the massless coordinates (zero rows of M, e.g. a natural model's angle
    coordinates), X = M_pp⁻¹A_pᵀ, y = M_pp⁻¹Q_p::

        [A_p X  -A_a] [λ  ]   [A_p y - c]
        [A_aᵀ    0  ] [q̈_a] = [Q_a      ],      q̈_p = y - Xλ

    solved by Cholesky when a is empty (A_p X is then positive definite for a full-rank A),
    else by Gaussian elimination with partial pivoting: m + n_a unknowns instead of n + m.  The
    products with A use its non-zeros only (a natural model's rows have a few).

    ``schur`` is the tuple of :func:`schur_workspace`.  Its flag 1: the first matrix is the
    constant M_pp⁻¹ (natural coordinates: inverted once); 0: M is factored here by Cholesky
    (joint coordinates); -1: M_pp is not positive definite (returns False: the caller solves
    the full system).  Returns False when a factorisation meets a non-positive pivot or the
    reduced system is singular."""
    matrix, flag, X, K, y, columns, counts, massive, massless, z, dense = (
        schur[0], schur[1], schur[2], schur[3], schur[4], schur[5], schur[6], schur[9], schur[10], schur[11],
        schur[12])
    n_p = massive.shape[0]
    n_a = massless.shape[0]
    m = c.shape[0]
    if flag < 0:
        return False
    if flag == 0:
        for i in range(n_p):
            for j in range(i + 1):
                matrix[i, j] = M[massive[i], massive[j]]
        if not cholesky_in_place(matrix, dense):
            return False
    for r in range(m):                      # non-zeros of A_p's rows; X's rows
        count = 0
        for i in range(n_p):
            if A[r, massive[i]] != 0.0:
                columns[r, count] = i
                count += 1
        counts[r] = count
        if flag == 1:                       # Σ_t A[r, c_t] M_pp⁻¹[c_t, :]: M_pp⁻¹ is symmetric
            row = X[r]
            for i in range(n_p):
                row[i] = 0.0
            for t in range(count):
                value, source = A[r, massive[columns[r, t]]], matrix[columns[r, t]]
                for i in range(n_p):
                    row[i] += source[i] * value
        else:
            for i in range(n_p):
                X[r, i] = A[r, massive[i]]
            solve_lower(matrix, dense, X[r])
            solve_lower_transposed(matrix, dense, X[r])
    if flag == 1:
        for i in range(n_p):
            total = 0.0
            for j in range(n_p):
                total += matrix[i, j] * Q[massive[j]]
            y[i] = total
    else:
        for i in range(n_p):
            y[i] = Q[massive[i]]
        solve_lower(matrix, dense, y)
        solve_lower_transposed(matrix, dense, y)
    reduced = K                             # (m + n_a)², as schur_workspace sizes it
    for a in range(m):
        total = -c[a]
        for t in range(counts[a]):
            total += A[a, massive[columns[a, t]]] * y[columns[a, t]]
        z[a] = total
        for b in range(a + 1):
            value = 0.0
            for t in range(counts[a]):
                value += A[a, massive[columns[a, t]]] * X[b, columns[a, t]]
            reduced[a, b] = reduced[b, a] = value
        for j in range(n_a):
            reduced[a, m + j] = -A[a, massless[j]]
            reduced[m + j, a] = A[a, massless[j]]
    for j in range(n_a):
        z[m + j] = Q[massless[j]]
        for i in range(n_a):
            reduced[m + j, m + i] = 0.0
    if n_a == 0:
        if not cholesky_in_place(reduced, dense):
            return False
        solve_lower(reduced, dense, z)
        solve_lower_transposed(reduced, dense, z)
    elif not solve_in_place(reduced, z):
        return False
    for a in range(m):
        lam[a] = z[a]
    for j in range(n_a):
        qdd[massless[j]] = z[m + j]
    for i in range(n_p):
        total = y[i]
        for a in range(m):
            total -= X[a, i] * lam[a]
        qdd[massive[i]] = total
    return True


def schur_workspace(constant_mass: bool, mass: np.ndarray, m: int, pattern: np.ndarray | None = None) -> tuple:
    """The ``schur`` tuple of :func:`schur_solve` for a model with ``m`` constraints and the
    constant mass matrix ``mass`` (``constant_mass``: a natural model) or one of M's shape;
    ``pattern``, the structural non-zeros of A (:func:`cmbs.banded.jacobian_pattern`), lets
    the Gram matrix keep its profile and large natural models solve by band LU.

    Natural coordinates: the coordinates with a zero row in M are massless (a), the others (p)
    have the constant M_pp, inverted once here (flag 1; -1 when M_pp is not positive definite);
    joint coordinates: all carry mass and M is factored at each call (flag 0).  Then
    workspaces: X (m, n_p), the reduced matrix (m + n_a)², y (n_p,), A's row non-zeros (m, n)
    and their counts (m,), two Gram matrices (m, m), the index arrays of p and a, a vector
    (m + n_a,), the dense profile (zeros) of a matrix of max(n, m) rows, the Gram's column
    lists (:func:`column_rows`), the Gram's profile (m,) and the Takahashi band (m, b + 1); then the band KKT
    plan (:func:`band_kkt`): its flag (1: used), half-width b, storage (3b + 1, n + m),
    pivots, right-hand side, the position of each unknown, M's non-zeros (row, column, value)
    and A's structural non-zeros (row, column); last the reference of :func:`bounds`: (valid,
    √λ_low, √λ_high) and its A (m, n), empty without ``pattern`` when m·n > BOUNDS_REUSE_SIZE."""
    n = mass.shape[0]
    flag = 0
    massive = np.arange(n)
    matrix = np.zeros((n, n))
    if constant_mass:
        massive = np.flatnonzero(np.any(mass != 0.0, axis=1))
        block = mass[np.ix_(massive, massive)]
        try:
            np.linalg.cholesky(block)       # positive definite: the inverse is safe
            inverse = np.linalg.inv(block)
            matrix = (inverse + inverse.T) / 2.0    # exactly symmetric: its rows are its columns
            flag = 1
        except np.linalg.LinAlgError:
            flag = -1
    massless = np.setdiff1d(np.arange(n), massive)
    size = m + massless.size
    start = np.zeros(m, dtype=np.int64) if pattern is None else gram_profile(pattern)
    width = int(np.max(np.arange(m) - start, initial=0))
    band = _band_workspace(constant_mass, flag, mass, pattern, m, massive.size)
    return (matrix, flag, np.zeros((m, massive.size)), np.zeros((size, size)), np.zeros(massive.size),
            np.zeros((m, max(n, 1)), dtype=np.int64), np.zeros(m, dtype=np.int64), np.zeros((m, m)),
            np.zeros((m, m)), massive.astype(np.int64), massless.astype(np.int64), np.zeros(size),
            np.zeros(max(n, m), dtype=np.int64), column_rows(pattern, m, n),
            start, np.zeros((max(m, 1), width + 1)), *band, np.zeros(3),
            np.zeros((m, n)) if m * n <= BOUNDS_REUSE_SIZE or pattern is not None else np.zeros((0, 0)))


#: Band KKT solves are used from this many unknowns (n + m) on, when cheaper than the Schur path
#: (measured: the band LU wins from about 22 unknowns, a pinned 8-link chain; the cost estimate
#: of :func:`_band_workspace` chooses between the two).
BAND_MINIMUM_SIZE = 20


def _band_workspace(constant_mass: bool, flag: int, mass: np.ndarray, pattern: np.ndarray | None, m: int,
                    n_p: int) -> tuple:
    """The band part of :func:`schur_workspace`: used (flag 1) for natural models of at least
    BAND_MINIMUM_SIZE unknowns whose band LU, ~(n + m)·3b² operations, is cheaper than the
    Schur path's ~m³/3 + m²·n_p."""
    n = mass.shape[0]
    use = 0
    width = 0
    order = np.arange(n + m, dtype=np.int64)
    if constant_mass and flag == 1 and pattern is not None and n + m >= BAND_MINIMUM_SIZE:
        order, width = band_plan(mass, pattern)
        use = 1 if (n + m) * 3.0 * width * width < m ** 3 / 3.0 + m * m * n_p else 0
    position = np.empty(n + m, dtype=np.int64)
    position[order] = np.arange(n + m)
    mass_rows, mass_columns = np.nonzero(mass)
    a_rows, a_columns = np.nonzero(pattern) if pattern is not None else (np.zeros(0, int), np.zeros(0, int))
    return (use, width, np.zeros((n + m, 3 * width + 1)), np.zeros(n + m, dtype=np.int64), np.zeros(n + m),
            position, mass_rows.astype(np.int64), mass_columns.astype(np.int64),
            np.ascontiguousarray(mass[mass_rows, mass_columns], dtype=float), a_rows.astype(np.int64),
            a_columns.astype(np.int64))


@njit(cache=True)
def band_kkt(Q, A, c, schur, qdd, lam):
    """q̈, λ of [M Aᵀ; A 0][q̈; λ] = [Q; c] by band LU in the reverse Cuthill-McKee order of
    :func:`cmbs.banded.band_plan` (M's non-zeros are constant and listed in the workspace, A's
    read at its structural non-zeros).  Returns False for an exactly singular matrix."""
    width, AB, pivots, rhs, position = schur[17], schur[18], schur[19], schur[20], schur[21]
    mass_rows, mass_columns, mass_values, a_rows, a_columns = schur[22], schur[23], schur[24], schur[25], schur[26]
    n = Q.shape[0]
    m = c.shape[0]
    diagonal = 2 * width
    AB[:, :] = 0.0
    for k in range(mass_rows.shape[0]):
        i, j = position[mass_rows[k]], position[mass_columns[k]]
        AB[j, diagonal + i - j] = mass_values[k]
    for k in range(a_rows.shape[0]):
        value = A[a_rows[k], a_columns[k]]
        i, j = position[n + a_rows[k]], position[a_columns[k]]
        AB[j, diagonal + i - j] = value
        AB[i, diagonal + j - i] = value
    for i in range(n):
        rhs[position[i]] = Q[i]
    for r in range(m):
        rhs[position[n + r]] = c[r]
    if not band_factor(AB, width, pivots):
        return False
    band_solve(AB, width, pivots, rhs)
    for i in range(n):
        qdd[i] = rhs[position[i]]
    for r in range(m):
        lam[r] = rhs[position[n + r]]
    return True


def banded(floats: np.ndarray, integers: np.ndarray, layout: np.ndarray) -> bool:
    """Whether :func:`packed_workspace`'s arrays planned band LU (:func:`_band_workspace`'s flag).

    A formulation then makes its kernel of a class of its own whose solve calls :func:`band_kkt`
    (e.g. :class:`cmbs.dynamics.lagrange.BandLagrangeKernel`), not a flag tested at every
    evaluation: a run compiles only the linear algebra its model uses (band LU adds about 5 s to
    a first compilation), and the solve calls :func:`schur_solve` or :func:`band_kkt` itself (a
    call between would pass the workspace's views at every evaluation: 20 % of a four-bar RK4
    run)."""
    return bool(workspace_views(floats, integers, layout)[16] == 1)


@njit(cache=True)
def solve_in_place(K, rhs):
    """Gaussian elimination with partial pivoting on a small dense system; the solution
    overwrites ``rhs`` and K is destroyed (its diagonal ends holding the pivots' reciprocals:
    one division per column).  Returns False for an exactly singular matrix.  (The pivot search
    is that of :func:`lu_in_place`; eliminating into the right-hand side directly avoids the
    pivot array, whose allocation costs 13 % of a four-bar stage.)"""
    size = rhs.shape[0]
    for column in range(size):
        pivot = column
        largest = abs(K[column, column])
        for row in range(column + 1, size):
            if abs(K[row, column]) > largest:
                largest = abs(K[row, column])
                pivot = row
        if largest == 0.0:
            return False
        if pivot != column:                 # columns left of ``column`` are no longer read
            for k in range(column, size):
                K[column, k], K[pivot, k] = K[pivot, k], K[column, k]
            rhs[column], rhs[pivot] = rhs[pivot], rhs[column]
        inverse = 1.0 / K[column, column]
        K[column, column] = inverse
        for row in range(column + 1, size):
            factor = K[row, column] * inverse
            if factor != 0.0:
                for k in range(column + 1, size):
                    K[row, k] -= factor * K[column, k]
                rhs[row] -= factor * rhs[column]
    for row in range(size - 1, -1, -1):
        total = rhs[row]
        for k in range(row + 1, size):
            total -= K[row, k] * rhs[k]
        rhs[row] = total * K[row, row]
    return True


@njit(cache=True, inline="always")
def assemble_kkt(M, Q, A, K, rhs):
    """K = [M Aᵀ; A 0] and ``rhs[:n]`` = Q (``rhs[n:]``, the constraints' c, left as it is)."""
    n, m = M.shape[0], A.shape[0]
    for i in range(n):
        for j in range(n):
            K[i, j] = M[i, j]
        rhs[i] = Q[i]
    for r in range(m):
        for j in range(n):
            K[n + r, j] = A[r, j]
            K[j, n + r] = A[r, j]
        for j in range(m):
            K[n + r, n + j] = 0.0


@njit(cache=True)
def full_system(M, Q, A, K, rhs, qdd, lam):
    """q̈, λ of the augmented system [M Aᵀ; A 0][q̈; λ] = [Q; c] (c given in ``rhs[n:]``) by
    Gaussian elimination with partial pivoting (:func:`solve_in_place`): the path of
    :func:`field` when the Schur complement cannot be used.  Returns False when singular."""
    n, m = qdd.shape[0], lam.shape[0]
    assemble_kkt(M, Q, A, K, rhs)
    if not solve_in_place(K, rhs):
        return False
    for i in range(n):
        qdd[i] = rhs[i]
    for r in range(m):
        lam[r] = rhs[n + r]
    return True


@njit(cache=True)
def lu_in_place(K, pivots):
    """LU factorisation with partial pivoting of the square ``K`` in place (unit lower factor
    below the diagonal); row swaps in ``pivots``.  Returns False for an exactly singular matrix."""
    size = K.shape[0]
    for column in range(size):
        pivot = column
        largest = abs(K[column, column])
        for row in range(column + 1, size):
            if abs(K[row, column]) > largest:
                largest = abs(K[row, column])
                pivot = row
        pivots[column] = pivot
        if largest == 0.0:
            return False
        if pivot != column:
            for k in range(size):
                K[column, k], K[pivot, k] = K[pivot, k], K[column, k]
        for row in range(column + 1, size):
            factor = K[row, column] / K[column, column]
            K[row, column] = factor
            if factor != 0.0:
                for k in range(column + 1, size):
                    K[row, k] -= factor * K[column, k]
    return True


@njit(cache=True)
def lu_solve(K, pivots, b):
    """Solve K x = b in place with the factors of :func:`lu_in_place`."""
    size = K.shape[0]
    for i in range(size):
        if pivots[i] != i:
            b[i], b[pivots[i]] = b[pivots[i]], b[i]
    for i in range(size):
        for k in range(i):
            b[i] -= K[i, k] * b[k]
    for i in range(size - 1, -1, -1):
        for k in range(i + 1, size):
            b[i] -= K[i, k] * b[k]
        b[i] /= K[i, i]


@njit(cache=True)
def lu_solve_transposed(K, pivots, b):
    """Solve Kᵀ x = b in place with the factors of :func:`lu_in_place` (K = Pᵀ L U)."""
    size = K.shape[0]
    for i in range(size):                   # Uᵀ y = b
        for k in range(i):
            b[i] -= K[k, i] * b[k]
        b[i] /= K[i, i]
    for i in range(size - 1, -1, -1):       # Lᵀ w = y
        for k in range(i + 1, size):
            b[i] -= K[k, i] * b[k]
    for i in range(size - 1, -1, -1):       # x = Pᵀ w
        if pivots[i] != i:
            b[i], b[pivots[i]] = b[pivots[i]], b[i]


def packed_workspace(model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(floats, integers, layout): the :func:`schur_workspace` of a model (built with its
    Jacobian's structure, :func:`cmbs.banded.jacobian_pattern`, when it has a compiled kernel:
    a user-equation model's A is scanned instead), packed by :func:`pack_workspace`, with scratch
    of its own.

    Built once per model object (about 0.8 ms for a 14-link chain) and kept while the model
    lives; each call returns copies of the float and integer arrays, so that runs at the same
    time (threads of a sweep) do not write into each other's scratch."""
    cached = _WORKSPACES.get(id(model))
    if cached is None:
        constant = bool(model.constant_mass)
        mass = np.array(model.mass_matrix(model.q0), dtype=float) if constant else np.zeros((model.n, model.n))
        pattern = jacobian_pattern(model) if model_kernel(model) is not None else None
        schur = schur_workspace(constant, mass, model.m, pattern)
        cached = pack_workspace(schur)
        _WORKSPACES[id(model)] = cached
        weakref.finalize(model, _WORKSPACES.pop, id(model), None)
    floats, integers, layout = cached
    return floats.copy(), integers.copy(), layout


#: :func:`packed_workspace`'s arrays by the id of a live model (an entry leaves with its model).
_WORKSPACES: dict[int, tuple] = {}
