"""Sparse structure of the constrained equations of large models: banded KKT solves and
profile Cholesky inverses, so that the cost of one evaluation grows about linearly with the
number of bodies instead of with its cube.

Natural coordinates couple only the points of one segment, and a constraint row only the
coordinates it names, so the augmented (KKT) matrix

    K = [M  Aᵀ]
        [A  0 ]

of a chain of N links has O(N) non-zeros.  Its rows and columns, renumbered once by reverse
Cuthill-McKee (scipy.sparse.csgraph), fall in a band of half-width b independent of N (4-6 for
a chain), and LU with partial pivoting keeps the fill inside 2b superdiagonals (LAPACK's
``gbtrf`` storage: Golub & Van Loan §4.3.5): O(N b²) per solve.  The Gram matrix G = A Aᵀ of
the rank certificate has a narrow profile too; its Cholesky factor keeps it (George & Liu 1981
§4.2) and the diagonal of G⁻¹ follows from the factor by the Takahashi recurrence (Takahashi,
Fagan & Chen 1973; Erisman & Tinney 1975) in O(m b²) instead of forming L⁻¹.
"""

from __future__ import annotations

import numpy as np

from cmbs.jit import njit


def jacobian_pattern(model, samples: int = 3, seed: int = 7) -> np.ndarray:
    """Structural non-zeros of the model's A (m, n), as booleans: the union of the non-zeros of
    A at q0 and at ``samples`` random states around it (an entry that vanishes at q0 only by
    the geometry, e.g. a vertical link's x-derivative, is non-zero at the random states)."""
    rng = np.random.default_rng(seed)
    q0 = np.asarray(model.q0, dtype=float)
    pattern = model.jacobian(q0, 0.0) != 0.0
    for _ in range(samples):
        q = q0 + rng.normal(size=q0.size) * (0.1 + 0.1 * np.abs(q0))
        pattern |= model.jacobian(q, 0.3) != 0.0
    return pattern


def gram_profile(pattern: np.ndarray) -> np.ndarray:
    """``start[i]``: the first row j <= i whose non-zeros share a column with row i's (the
    profile of G = A Aᵀ, which its Cholesky factor keeps)."""
    m = pattern.shape[0]
    overlap = (pattern.astype(np.int64) @ pattern.T.astype(np.int64)) > 0
    start = np.arange(m, dtype=np.int64)
    for i in range(m):
        start[i] = int(np.argmax(overlap[i, :i + 1]))
    return start


def band_plan(mass: np.ndarray, pattern: np.ndarray) -> tuple[np.ndarray, int]:
    """Reverse Cuthill-McKee order of the KKT matrix of a constant ``mass`` (n, n) and a Jacobian
    ``pattern`` (m, n), and its half-bandwidth b in that order.  ``order[k]`` is the original
    index (coordinates 0..n-1, then constraint rows n..n+m-1) at position k."""
    from scipy.sparse import csgraph, csr_matrix   # here: importing scipy.sparse takes about 10 ms

    n, m = mass.shape[0], pattern.shape[0]
    structure = np.zeros((n + m, n + m), dtype=bool)
    structure[:n, :n] = mass != 0.0
    structure[n:, :n] = pattern
    structure[:n, n:] = pattern.T
    structure[np.arange(n + m), np.arange(n + m)] = True
    order = csgraph.reverse_cuthill_mckee(csr_matrix(structure), symmetric_mode=True).astype(np.int64)
    position = np.empty_like(order)
    position[order] = np.arange(order.size)
    rows, columns = np.nonzero(structure)
    width = int(np.max(np.abs(position[rows] - position[columns]))) if rows.size else 0
    return order, width


@njit(cache=True)
def band_factor(AB, width, pivots):
    """LU factorisation with partial pivoting of the band matrix in ``AB`` (LAPACK ``gbtf2``,
    unblocked): lower and upper half-width ``width`` = b, element (i, j) of the matrix at
    ``AB[j, 2b + i - j]``, entries 0..b-1 of each row of AB free for the fill (AB is (size,
    3b + 1)): each matrix column is a contiguous row of AB, as in LAPACK's column-major band
    storage.  In place; row interchanges in ``pivots``.  Returns False at an exactly zero pivot
    column."""
    size = AB.shape[0]
    diagonal = 2 * width
    last = 0                                # last column touched by the U factor so far
    for j in range(size):                   # views from the diagonal down: indices from 0 (faster)
        below = min(width, size - 1 - j)
        column = AB[j, diagonal:diagonal + below + 1]
        pivot = 0
        largest = abs(column[0])
        for i in range(1, below + 1):
            value = abs(column[i])
            if value > largest:
                largest = value
                pivot = i
        pivots[j] = j + pivot
        if largest == 0.0:
            return False
        last = max(last, min(j + width + pivot, size - 1))
        if pivot != 0:                      # swap rows j and j + pivot in columns j..last
            for c in range(j, last + 1):
                row = AB[c]
                a = diagonal + j - c
                row[a], row[a + pivot] = row[a + pivot], row[a]
        inverse = 1.0 / column[0]
        for i in range(1, below + 1):
            column[i] *= inverse
        for c in range(j + 1, last + 1):    # rank-one update of the trailing block
            offset = diagonal + j - c
            target = AB[c, offset:offset + below + 1]
            top = target[0]
            if top != 0.0:
                for i in range(1, below + 1):
                    target[i] -= column[i] * top
    return True


@njit(cache=True)
def band_solve(AB, width, pivots, b):
    """Solve with the factors of :func:`band_factor`, in place in ``b`` (LAPACK ``gbtrs``)."""
    size = AB.shape[0]
    diagonal = 2 * width
    for j in range(size - 1):               # L
        below = min(width, size - 1 - j)
        p = pivots[j]
        if p != j:
            b[j], b[p] = b[p], b[j]
        value = b[j]
        column = AB[j]
        for i in range(1, below + 1):
            b[j + i] -= column[diagonal + i] * value
    for j in range(size - 1, -1, -1):       # U, column j above the diagonal
        column = AB[j]
        value = b[j] / column[diagonal]
        b[j] = value
        for i in range(max(0, j - diagonal), j):
            b[i] -= column[diagonal + i - j] * value


@njit(cache=True)
def inverse_trace(L, start, Z):
    """trace(G⁻¹) from the lower Cholesky factor L of G (profile ``start``: L[i, k] = 0 for
    k < start[i]) by the Takahashi recurrence, for j >= i,

        Z_ij = (δ_ij / L_ii - Σ_{k > i} L_ki Z_kj) / L_ii,

    computed from the last row up; with half-bandwidth b = max(i - start[i]) every Z needed
    lies in the band, stored as Z[i, d] = Z_{i, i+d} (``Z`` is (m, b + 1) or wider): O(m b²)."""
    m = L.shape[0]
    width = 0
    for i in range(m):
        width = max(width, i - start[i])
    total = 0.0
    for i in range(m - 1, -1, -1):
        top = min(i + width, m - 1)
        for j in range(top, i - 1, -1):
            value = 1.0 / L[i, i] if j == i else 0.0
            for k in range(i + 1, top + 1):
                if start[k] > i:
                    continue
                Zkj = Z[k, j - k] if k <= j else Z[j, k - j]
                value -= L[k, i] * Zkj
            Z[i, j - i] = value / L[i, i]
        total += Z[i, 0]
    return total
