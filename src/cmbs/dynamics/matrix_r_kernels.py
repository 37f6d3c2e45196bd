"""The numerical work of matrix R (:mod:`cmbs.dynamics.matrix_r`), once: the kernels that
:class:`~cmbs.dynamics.matrix_r.MatrixRSolver` calls on the Python loop and the compiled loops
(:mod:`cmbs.integrate.compiled_rk4`, :mod:`cmbs.integrate.compiled_adaptive` through
:class:`MatrixRKernel`, :mod:`cmbs.integrate.compiled_reduced`) call inside theirs.  Without numba
they run as Python (:mod:`cmbs.jit`).

With the partition's r constraint rows A_r = [A_d A_z] split into their dependent (d) and
independent (z) columns (A_d regular; García de Jalón & Bayo 1994 ch. 5, thesis §3.5.4)::

    R = [-A_d⁻¹ A_z ; I],   S = [A_d⁻¹ γ_r ; 0]   (rows in the partition's order),
    Rᵀ M R z̈ = Rᵀ (Q - M S),   q̈ = R z̈ + S,   λ_r = -A_d⁻ᵀ (M q̈ - Q)_d,   λ = 0 on the other rows.

Every kernel after :func:`factor_dependent` uses the LU factors of A_d it left in ``Ad``,
``pivots``.  The recovery (:func:`recover`) evaluates the model through its kernel tuple
(:func:`cmbs.model.compiled.evaluate`); a model with Python-callable terms is evaluated through
:class:`PythonEquations` by the interpreted recovery (:func:`cmbs.jit.interpreted`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cmbs.dynamics.base import NON_FINITE, OK, SINGULAR
from cmbs.dynamics.dense import copy_vector
from cmbs.dynamics.kkt import lu_in_place, lu_solve, lu_solve_transposed, solve_in_place
from cmbs.jit import njit
from cmbs.model.compiled import evaluate

#: :func:`recover`'s status codes besides OK and NON_FINITE
NOT_CONVERGED, VELOCITIES_KEPT = 4, 5
#: The status of a loop's stage or step whose recovery met non-finite constraints or an exactly
#: singular A_d (:func:`recover`'s NON_FINITE): it ends the run, as the Python path's
#: :class:`~cmbs.errors.SingularSystemError` does, where an adaptive loop would retry a
#: NON_FINITE stage with a smaller step.  (Apart from the adaptive loop's own codes.)
UNRECOVERED = 7
#: The status of an update of the partition (:func:`update_partition`) that found A_d singular
#: (κ₂ above SINGULAR_CONDITION) and no better partition: a user's partition, or an automatic one
#: chosen again there: it ends the run (the solver's message, ``loop_failure``).
SINGULAR_PARTITION = 8
#: κ₂ above which a partition's A_d counts as singular (a user partition fails, an automatic one
#: is chosen again)
SINGULAR_CONDITION = 1e12
#: The entries of a :class:`MatrixRKernel`'s ``conditions``: the smallest κ₂ of the partition
#: since it was chosen (an automatic partition is chosen again when κ₂ grows by
#: ``condition_growth`` from it), and the κ₂ of the singular partition an update met (for the
#: message of SINGULAR_PARTITION).
REFERENCE, MET = 0, 1
#: Relative difference below which two pivot candidates of the partition's choice count as equal:
#: ties in exact arithmetic (every column of the row-scaled Aᵀ has norm 1 at the first step; a
#: symmetric mechanism has equal entries) differ by rounding, and the first of them is chosen.
PIVOT_TIE = 1e-12


class PythonEquations(NamedTuple):
    """A model whose terms only Python evaluates (user equations, Python-callable time
    functions), as the interpreted :func:`recover` takes it: ``terms`` is a
    :class:`~cmbs.model.model.Terms` of ``model`` whose buffer the recovery is given."""

    model: object
    terms: object

    @staticmethod
    def evaluate(equations: "PythonEquations", q: np.ndarray, qd: np.ndarray, t: float, u: np.ndarray,
                 buffer: np.ndarray) -> None:
        """The terms at (q, q̇, t, u) into ``buffer`` (``equations.terms.buffer``)."""
        equations.model.evaluate(q, qd, t, u, out=equations.terms)


@njit(cache=True)
def factor_dependent(A, rows, dependent, Ad, pivots):
    """LU factors (in ``Ad``, ``pivots``) of the dependent block A_d of ``A``: the partition's
    constraint rows and dependent columns.  False when exactly singular."""
    for a in range(rows.shape[0]):
        for j in range(rows.shape[0]):
            Ad[a, j] = A[rows[a], dependent[j]]
    return lu_in_place(Ad, pivots)


@njit(cache=True)
def _norms(A, rows, Ad, pivots, side, rows_too):
    """(‖A_r‖₁, ‖A_d⁻¹‖₁, ‖A_r‖∞, ‖A_d⁻¹‖∞) from ``A`` (A_r: the partition's rows, all columns)
    and the LU factors of A_d: A_d⁻¹ column by column (r triangular solve pairs); the ∞-norms
    only when ``rows_too`` (else 0).  ``side`` is overwritten."""
    r, n = rows.shape[0], A.shape[1]
    norm_one = inverse_one = norm_inf = inverse_inf = 0.0
    for c in range(n):
        column = 0.0
        for a in range(r):
            column += abs(A[rows[a], c])
        norm_one = max(norm_one, column)
    if rows_too:
        for a in range(r):
            row = 0.0
            for c in range(n):
                row += abs(A[rows[a], c])
            norm_inf = max(norm_inf, row)
    row_sums = np.zeros(r if rows_too else 0)
    for j in range(r):
        for a in range(r):
            side[a] = 0.0
        side[j] = 1.0
        lu_solve(Ad, pivots, side)
        column = 0.0
        for a in range(r):
            column += abs(side[a])
            if rows_too:
                row_sums[a] += abs(side[a])
        inverse_one = max(inverse_one, column)
    for a in range(row_sums.shape[0]):
        inverse_inf = max(inverse_inf, row_sums[a])
    return norm_one, inverse_one, norm_inf, inverse_inf


@njit(cache=True)
def condition_one(A, rows, Ad, pivots, side):
    """κ₁ = ‖A_r‖₁ ‖A_d⁻¹‖₁ (:func:`cmbs.dynamics.matrix_r.partition_condition` with norm 1) from
    the LU factors of A_d; 1 without dependent coordinates."""
    if rows.shape[0] == 0:
        return 1.0
    norm_one, inverse_one, _, _ = _norms(A, rows, Ad, pivots, side, False)
    return norm_one * inverse_one


@njit(cache=True)
def condition_two_bound(A, rows, Ad, pivots, side):
    """An upper bound of κ₂ = ‖A_r‖₂ ‖A_d⁻¹‖₂: sqrt(κ₁ κ_∞) ≥ κ₂, since ‖B‖₂ ≤ sqrt(‖B‖₁ ‖B‖∞)
    for every matrix B (Golub & Van Loan, Matrix Computations, 4th ed., §2.3.3), from the LU
    factors of A_d: r triangular solve pairs instead of SVDs."""
    if rows.shape[0] == 0:
        return 1.0
    norm_one, inverse_one, norm_inf, inverse_inf = _norms(A, rows, Ad, pivots, side, True)
    return np.sqrt(norm_one * inverse_one * norm_inf * inverse_inf)


@njit(cache=True)
def condition_two(A, rows, dependent):
    """κ₂ = ‖A_r‖₂ / σ_min(A_d) by SVDs; inf for a singular A_d, 1 without dependent
    coordinates."""
    r, n = rows.shape[0], A.shape[1]
    if r == 0:
        return 1.0
    block = np.empty((r, r))
    partition_rows = np.empty((r, n))
    for a in range(r):
        for c in range(n):
            partition_rows[a, c] = A[rows[a], c]
        for j in range(r):
            block[a, j] = A[rows[a], dependent[j]]
    smallest = np.linalg.svd(block)[1][-1]
    return np.linalg.norm(partition_rows, 2) / smallest if smallest > 0 else np.inf


@njit(cache=True)
def row_scaled(A):
    """A with each row divided by its Euclidean norm (a zero row left as it is)."""
    m, n = A.shape
    scaled = np.empty((m, n))
    for a in range(m):
        norm = 0.0
        for j in range(n):
            norm += A[a, j] * A[a, j]
        norm = np.sqrt(norm)
        if norm == 0.0:
            norm = 1.0
        for j in range(n):
            scaled[a, j] = A[a, j] / norm
    return scaled


@njit(cache=True)
def numerical_rank(A, tolerance):
    """The numerical rank of A: the singular values of the row-scaled A (:func:`row_scaled`)
    above ``tolerance`` times the largest (or times 1, if that is larger)."""
    if A.shape[0] == 0:
        return 0
    sigma = np.linalg.svd(row_scaled(A), full_matrices=False)[1]
    cutoff = tolerance * max(sigma[0], 1.0)
    rank = 0
    for value in sigma:
        if value > cutoff:
            rank += 1
    return rank


@njit(cache=True)
def pivot_columns(B, count, chosen):
    """The first ``count`` pivot columns of the Householder QR factorisation with column pivoting
    of ``B`` (Businger & Golub 1965; Golub & Van Loan, Matrix Computations, 4th ed., §5.4.2) into
    ``chosen``, in the order chosen; ``B`` is overwritten.  Step k brings forward the column of
    largest norm in rows k.. (the first on a tie, as LAPACK's dgeqp3, up to PIVOT_TIE), whose
    Householder reflection then zeroes it below row k in every column.  The norms are computed
    afresh at each step, not downdated."""
    rows, columns = B.shape
    order = np.arange(columns)
    for k in range(count):
        pivot, largest = k, -1.0
        for j in range(k, columns):
            norm = 0.0
            for i in range(k, rows):
                norm += B[i, j] * B[i, j]
            if norm > largest * (1.0 + PIVOT_TIE):
                pivot, largest = j, norm
        if pivot != k:
            for i in range(rows):
                B[i, k], B[i, pivot] = B[i, pivot], B[i, k]
            order[k], order[pivot] = order[pivot], order[k]
        chosen[k] = order[k]
        alpha = -np.sqrt(largest) if B[k, k] > 0.0 else np.sqrt(largest)
        B[k, k] -= alpha                     # v = x - α e₁ in B[k:, k]; H = I - 2 v vᵀ / vᵀv
        length = 0.0
        for i in range(k, rows):
            length += B[i, k] * B[i, k]
        if length == 0.0:
            continue
        for j in range(k + 1, columns):
            along = 0.0
            for i in range(k, rows):
                along += B[i, k] * B[i, j]
            along *= 2.0 / length
            for i in range(k, rows):
                B[i, j] -= along * B[i, k]


@njit(cache=True)
def pivot_rows(C, count, chosen):
    """The first ``count`` pivot rows of Gaussian elimination with partial pivoting of ``C``
    (Golub & Van Loan §3.4.3) into ``chosen``, in the order chosen; ``C`` is overwritten.  Step k
    brings forward the row of largest |C[i, k]| in rows k.. (the first on a tie, as LAPACK's
    dgetrf, up to PIVOT_TIE), then eliminates column k below it."""
    rows, columns = C.shape
    order = np.arange(rows)
    for k in range(count):
        pivot, largest = k, abs(C[k, k])
        for i in range(k + 1, rows):
            if abs(C[i, k]) > largest * (1.0 + PIVOT_TIE):
                pivot, largest = i, abs(C[i, k])
        if pivot != k:
            for j in range(columns):
                C[k, j], C[pivot, j] = C[pivot, j], C[k, j]
            order[k], order[pivot] = order[pivot], order[k]
        chosen[k] = order[k]
        if C[k, k] == 0.0:
            continue
        for i in range(k + 1, rows):
            factor = C[i, k] / C[k, k]
            for j in range(k + 1, columns):
                C[i, j] -= factor * C[k, j]


@njit(cache=True)
def choose_partition(A, automatic, rows, dependent, independent):
    """The partition at the configuration of ``A``, in place: r = len(rows) constraint rows, the
    first r pivots of a QR factorisation with column pivoting of the row-scaled Aᵀ
    (:func:`pivot_columns`: the rows farthest from dependent on the ones before); when
    ``automatic``, r dependent coordinates, the first r pivots of Gaussian elimination with
    partial pivoting of those rows' transpose (:func:`pivot_rows`: the coordinates whose block
    A_d the elimination keeps regular), and the others independent, each in increasing order.
    Without ``automatic`` the dependent and independent coordinates are the user's, as given."""
    r, n = rows.shape[0], A.shape[1]
    chosen = np.empty(r, dtype=np.int64)
    pivot_columns(row_scaled(A).T.copy(), r, chosen)
    copy_vector(np.sort(chosen), rows)
    if not automatic:
        return
    block = np.empty((n, r))
    for j in range(n):
        for a in range(r):
            block[j, a] = A[rows[a], j]
    pivot_rows(block, r, chosen)
    copy_vector(np.sort(chosen), dependent)
    is_dependent = np.zeros(n, dtype=np.bool_)
    for j in range(r):
        is_dependent[dependent[j]] = True
    b = 0
    for j in range(n):
        if not is_dependent[j]:
            independent[b] = j
            b += 1


@njit(cache=True)
def recover(model, q, qd, t, u_zero, buffer, n, m, rows, dependent, independent, tolerance, iterations, limit, Ad,
            pivots, side, worst):
    """The consistent state with z and ż held: dependent coordinates by Newton on Φ_r = 0
    (d ← d - A_d⁻¹ Φ_r, started from the given q, until max |Φ_r| < ``tolerance``, at most
    ``iterations`` evaluations), in place in ``q``, and dependent velocities from
    A_d ḋ = -A_z ż - Φ_t at the recovered q, in place in ``qd``.  Leaves the terms at the
    recovered q (q̇ = 0, u = 0) in ``buffer`` and A_d's LU factors there in ``Ad``, ``pivots``.

    Returns OK, NOT_CONVERGED, NON_FINITE (Φ_r not finite or A_d exactly singular), or
    VELOCITIES_KEPT (positions recovered, q̇ unchanged) where κ₁ at the given q exceeds
    ``limit`` (:attr:`~cmbs.dynamics.matrix_r.MatrixRSolver.recovery_limit`; inf recovers
    them everywhere); raises ``worst`` = [κ₁, t] when that condition is the largest so far."""
    r = rows.shape[0]
    zeros = np.zeros(n)
    converged = False
    velocities_kept = False
    A = buffer[n + m:n + m + m * n].reshape((m, n))
    for iteration in range(iterations):
        evaluate(model, q, zeros, t, u_zero, buffer)
        largest = 0.0
        for a in range(r):
            value = abs(buffer[n + rows[a]])
            if not value < np.inf:
                return NON_FINITE
            largest = max(largest, value)
        if not factor_dependent(A, rows, dependent, Ad, pivots):
            return NON_FINITE
        if iteration == 0:
            condition = condition_one(A, rows, Ad, pivots, side)
            if condition > worst[0]:
                worst[0], worst[1] = condition, t
            velocities_kept = condition > limit
        if largest < tolerance:
            converged = True
            break
        for a in range(r):
            side[a] = buffer[n + rows[a]]
        lu_solve(Ad, pivots, side)
        for j in range(r):
            q[dependent[j]] -= side[j]
    if not converged:
        return NOT_CONVERGED
    if velocities_kept:
        return VELOCITIES_KEPT
    phi_t = buffer[n + 2 * m + m * n:n + 3 * m + m * n]
    for a in range(r):
        total = -phi_t[rows[a]]
        for j in range(independent.shape[0]):
            total -= A[rows[a], independent[j]] * qd[independent[j]]
        side[a] = total
    lu_solve(Ad, pivots, side)
    for j in range(r):
        qd[dependent[j]] = side[j]
    return OK


@njit(cache=True)
def velocity_matrix(A, rows, dependent, independent, Ad, pivots, side, R):
    """R (n, k) into ``R``: column b is e_z(b) - A_d⁻¹ A_z e_b on the dependent rows."""
    r = rows.shape[0]
    R[:, :] = 0.0
    for b in range(independent.shape[0]):
        R[independent[b], b] = 1.0
        for a in range(r):
            side[a] = A[rows[a], independent[b]]
        lu_solve(Ad, pivots, side)
        for j in range(r):
            R[dependent[j], b] = -side[j]


@njit(cache=True)
def dependent_accelerations(A, gamma, rows, dependent, Ad, pivots, side, qdd):
    """The dependent accelerations of ``qdd`` in place from A_r q̈ = γ_r with the independent ones
    held: q̈_d += A_d⁻¹ (γ_r - A_r q̈)."""
    r, n = rows.shape[0], A.shape[1]
    for a in range(r):
        total = gamma[rows[a]]
        for j in range(n):
            total -= A[rows[a], j] * qdd[j]
        side[a] = total
    lu_solve(Ad, pivots, side)
    for j in range(r):
        qdd[dependent[j]] += side[j]


@njit(cache=True)
def factored_dependent_accelerations(A, gamma, rows, dependent, Ad, pivots, side, qdd):
    """:func:`dependent_accelerations` after factoring A_d of ``A``; False when A_d is exactly
    singular."""
    if not factor_dependent(A, rows, dependent, Ad, pivots):
        return False
    dependent_accelerations(A, gamma, rows, dependent, Ad, pivots, side, qdd)
    return True


def accelerations_work(n: int, k: int, r: int) -> tuple:
    """The work arrays of :func:`accelerations` for n coordinates, k independent and r dependent
    ones: A_d's LU factors and pivots, a side vector (r), R (n, k), Rᵀ M R (k, k), its
    right-hand side (k), S (n), M R (n, k), Q - M S (n)."""
    return (np.empty((r, r)), np.empty(r, dtype=np.int64), np.empty(r), np.empty((n, k)), np.empty((k, k)),
            np.empty(k), np.empty(n), np.empty((n, k)), np.empty(n))


@njit(cache=True)
def accelerations(Q, A, gamma, M, rows, dependent, independent, work, qdd, lam):
    """q̈ and λ by matrix R (module docstring) at the terms (Q, A, γ, M), with A_d's LU factors
    in ``work`` (:func:`accelerations_work`).  Returns OK, SINGULAR (Rᵀ M R exactly singular)
    or NON_FINITE."""
    Ad, pivots, side, R, reduced, zrhs, S, MR, force = work
    n, m = Q.shape[0], A.shape[0]
    r, k = rows.shape[0], independent.shape[0]
    velocity_matrix(A, rows, dependent, independent, Ad, pivots, side, R)
    S[:] = 0.0
    for a in range(r):
        side[a] = gamma[rows[a]]
    lu_solve(Ad, pivots, side)
    for j in range(r):
        S[dependent[j]] = side[j]
    for i in range(n):                       # M R (skipping M's zeros: a natural model's M is sparse) and Q - M S
        force[i] = Q[i]
        for c in range(k):
            MR[i, c] = 0.0
        for j in range(n):
            mass_ij = M[i, j]
            if mass_ij != 0.0:
                force[i] -= mass_ij * S[j]
                for c in range(k):
                    MR[i, c] += mass_ij * R[j, c]
    for b in range(k):                       # Rᵀ (M R), symmetric, and Rᵀ (Q - M S)
        for c in range(b, k):
            total = 0.0
            for i in range(n):
                total += R[i, b] * MR[i, c]
            reduced[b, c] = total
            reduced[c, b] = total
        total = 0.0
        for i in range(n):
            total += R[i, b] * force[i]
        zrhs[b] = total
    if not solve_in_place(reduced, zrhs):
        return SINGULAR
    for i in range(n):
        total = S[i]
        for b in range(k):
            total += R[i, b] * zrhs[b]
        qdd[i] = total
    for a in range(m):
        lam[a] = 0.0
    for j in range(r):                       # (M q̈ - Q)_d = -A_dᵀ λ_r
        c = dependent[j]
        total = -Q[c]
        for i in range(n):
            total += M[c, i] * qdd[i]
        side[j] = -total
    lu_solve_transposed(Ad, pivots, side)
    for a in range(r):
        lam[rows[a]] = side[a]
    for i in range(n):
        if not (abs(qdd[i]) < np.inf):
            return NON_FINITE
    return OK


@njit(cache=True)
def factored_accelerations(Q, A, gamma, M, rows, dependent, independent, work, qdd, lam):
    """:func:`accelerations` after factoring A_d of ``A`` into ``work``; SINGULAR also when A_d
    is exactly singular."""
    if not factor_dependent(A, rows, dependent, work[0], work[1]):
        return SINGULAR
    return accelerations(Q, A, gamma, M, rows, dependent, independent, work, qdd, lam)


@njit(cache=True)
def factored_velocity_matrix(A, rows, dependent, independent, Ad, pivots, side, R):
    """:func:`velocity_matrix` after factoring A_d of ``A``; False when A_d is exactly singular."""
    if not factor_dependent(A, rows, dependent, Ad, pivots):
        return False
    velocity_matrix(A, rows, dependent, independent, Ad, pivots, side, R)
    return True


class MatrixRKernel(NamedTuple):
    """Matrix R as the compiled loops take it (:mod:`cmbs.dynamics.field`) and as
    :class:`~cmbs.dynamics.matrix_r.MatrixRSolver` keeps it: the partition (constraint rows,
    dependent and independent coordinates: arrays of fixed sizes, changed in place by
    :func:`update_partition`), the recovery's tolerance, iteration limit and κ₁ limit
    (:attr:`~cmbs.dynamics.matrix_r.MatrixRSolver.recovery_limit`), whether the partition is
    chosen automatically and κ₂'s growth that calls for a new one (``condition_growth``), the
    ``conditions`` (κ₂ entries REFERENCE, MET) and the number of ``repartitions`` (one
    entry), zero inputs for the recovery's evaluations, ``worst`` = [κ₁, t], the largest κ₁ a
    recovery met, and the work arrays of :func:`accelerations_work`, each a field.  Made once by
    :class:`~cmbs.dynamics.matrix_r.MatrixRSolver`, whose state it is."""

    m: int
    rows: np.ndarray
    dependent: np.ndarray
    independent: np.ndarray
    tolerance: float
    iterations: int
    recovery_limit: float
    automatic: bool
    condition_growth: float
    conditions: np.ndarray
    repartitions: np.ndarray
    no_input: np.ndarray
    worst: np.ndarray
    Ad: np.ndarray
    pivots: np.ndarray
    side: np.ndarray
    R: np.ndarray
    reduced: np.ndarray
    reduced_rhs: np.ndarray
    S: np.ndarray
    MR: np.ndarray
    force: np.ndarray


@njit(cache=True)
def kernel_work(kernel):
    """The work arrays of ``kernel`` as :func:`accelerations` takes them."""
    return (kernel.Ad, kernel.pivots, kernel.side, kernel.R, kernel.reduced, kernel.reduced_rhs, kernel.S, kernel.MR,
            kernel.force)


@njit(cache=True)
def set_reference(A, kernel):
    """κ₂ of the kernel's partition at ``A`` as its REFERENCE; returns κ₂."""
    kernel.conditions[REFERENCE] = condition_two(A, kernel.rows, kernel.dependent)
    return kernel.conditions[REFERENCE]


@njit(cache=True)
def repartition(A, kernel):
    """The kernel's partition chosen again at the configuration of ``A`` (:func:`choose_partition`;
    the constraint rows only for a user's partition), counted; returns its κ₂.

    The number of dependent coordinates stays the rank found at the initial configuration: near a
    singular position the numerical rank of A drops for an instant, and taking that drop for a
    change of mobility would release a constraint the mechanism still obeys."""
    choose_partition(A, kernel.automatic, kernel.rows, kernel.dependent, kernel.independent)
    kernel.repartitions[0] += 1
    return set_reference(A, kernel)


@njit(cache=True)
def update_partition(A, kernel):
    """The partition at ``A`` kept, or chosen again (:func:`repartition`, automatic partition)
    when κ₂ has grown by ``condition_growth`` from its smallest value since the partition was
    chosen: the REFERENCE follows κ₂ down.  A user's partition is kept; its κ₂ by SVDs only
    where the bound from A_d's LU factors (:func:`condition_two_bound`) cannot rule out
    SINGULAR_CONDITION.  Returns OK, or SINGULAR_PARTITION (κ₂ in MET) where
    the partition kept or chosen has κ₂ above SINGULAR_CONDITION.

    The reference must follow κ₂ down: a partition chosen near a singular position, where every
    partition's κ₂ is large (2.3e3 on A02's N = 2, 1.7e-3 rad from a passage, RK4 at 1 ms), was
    kept while κ₂ stayed below 1.25 times that, long after it had become a poor choice: as the
    cranks turned vertical 0.26 s later (independent B1.z) the recovery of the dependent
    coordinates stopped converging at κ₂ = 1.8e3.  An automatic partition's κ₂ is computed at
    every update, since the bound (sqrt(κ₁ κ∞), 1.2 to 2 times κ₂ on A02) cannot tell a fall
    below the reference from a rise by 1.25."""
    rows, dependent = kernel.rows, kernel.dependent
    conditions = kernel.conditions
    if kernel.automatic:
        condition = condition_two(A, rows, dependent)
        if condition < conditions[REFERENCE]:
            conditions[REFERENCE] = condition
        elif condition > kernel.condition_growth * conditions[REFERENCE]:
            condition = repartition(A, kernel)
    else:
        if factor_dependent(A, rows, dependent, kernel.Ad, kernel.pivots) and \
                condition_two_bound(A, rows, kernel.Ad, kernel.pivots, kernel.side) <= SINGULAR_CONDITION:
            return OK
        condition = condition_two(A, rows, dependent)
    if condition > SINGULAR_CONDITION:
        conditions[MET] = condition
        return SINGULAR_PARTITION
    return OK


@njit(cache=True)
def _solve(kernel, terms, t, qd, qdd, lam):
    """q̈, λ by matrix R at the terms (:func:`factored_accelerations`), at the state as it is (a
    loop recovers its stage states before, :func:`_stage_state`)."""
    Q, _, A, gamma, _, M = terms
    return factored_accelerations(Q, A, gamma, M, kernel.rows, kernel.dependent, kernel.independent,
                                  kernel_work(kernel), qdd, lam)


@njit(cache=True)
def _recovered(kernel, model, q, qd, t, buffer):
    """:func:`recover` of (q, q̇) in place with the kernel's partition and limits: OK (also where
    the integrated velocities are kept), NOT_CONVERGED or UNRECOVERED."""
    status = recover(model, q, qd, t, kernel.no_input, buffer, q.shape[0], kernel.m, kernel.rows, kernel.dependent,
                     kernel.independent, kernel.tolerance, kernel.iterations, kernel.recovery_limit, kernel.Ad,
                     kernel.pivots, kernel.side, kernel.worst)
    if status == VELOCITIES_KEPT:
        return OK
    return UNRECOVERED if status == NON_FINITE else status


@njit(cache=True)
def _stage_state(kernel, model, q, qd, t, buffer):
    """The stage hook: the stage state recovered in place (:meth:`MatrixRSolver.stage_state
    <cmbs.dynamics.matrix_r.MatrixRSolver.stage_state>`)."""
    return _recovered(kernel, model, q, qd, t, buffer)


@njit(cache=True)
def _after_step(kernel, model, q, qd, t, buffer):
    """The after-step hook: the accepted state recovered in place, the partition updated there
    (:func:`update_partition`, on the terms the recovery left), and after a new partition
    recovered again with it, so that the stage hook leaves the state as it is
    (:meth:`MatrixRSolver.after_step <cmbs.dynamics.matrix_r.MatrixRSolver.after_step>`)."""
    status = _recovered(kernel, model, q, qd, t, buffer)
    if status != OK:
        return status
    n, m = q.shape[0], kernel.m
    before = kernel.repartitions[0]
    status = update_partition(buffer[n + m:n + m + m * n].reshape((m, n)), kernel)
    if status != OK or kernel.repartitions[0] == before:
        return status
    return _recovered(kernel, model, q, qd, t, buffer)


MatrixRKernel.solve = staticmethod(_solve)
MatrixRKernel.stage_state = staticmethod(_stage_state)
MatrixRKernel.after_step = staticmethod(_after_step)
