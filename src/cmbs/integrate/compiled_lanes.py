"""Batched RK4 in lanes: LANES variants of one natural-coordinate model advance together.

The batched sweep (:func:`cmbs.sweep`) runs thousands of variants of one small mechanism, and a
four-bar stage costs a single run more in bookkeeping (reading the model's index arrays, finding
A's non-zeros, passing the workspace, branching on the formulation) than in arithmetic.  Here a
block of LANES variants shares that bookkeeping: at every stage the model terms of each lane (the
one-state kernel :func:`cmbs.model.natural._evaluate`, copied lane-major), then the rank
certificate, the Baumgarte right-hand side and the Schur-complement solve run once for the block
with the lane index innermost, on lane-major arrays (..., LANES), over the structural non-zeros
of A known in advance.

Every lane performs the operations :func:`cmbs.integrate.compiled_rk4.rk4` performs for its
variant (Lagrange, Baumgarte or the projection), in the same order: the results are bit
for bit those of the one-variant loop (tests/test_lanes.py).  The common path of a stage is that
of :func:`cmbs.dynamics.field.field` where the rank certificate of A holds
(:func:`cmbs.dynamics.kkt.certify`, or the projection's regularity test, with the reference
bounds kept per lane exactly as the one-variant loop keeps them) and M_pp⁻¹ is constant
(natural coordinates): the block elimination of :func:`cmbs.dynamics.kkt.schur_solve`.  A
variant whose stage leaves that path (terms or q̈ not finite, a certificate that does not hold,
a factorisation that fails) leaves its lanes at that step and finishes in the one-variant loop
from the start of the step, with the state and certificate reference it had then: the same
stages again, the same results, including a stop at a singular position or the projection's SVD
through it.  The projection's three constraint inertias share the lanes: where the certificate
holds each has the Lagrange solution (:func:`cmbs.dynamics.projection._by_schur`, the path the
one-variant loop takes there for every inertia), and a variant that leaves continues with its
formulation kernel, its own inertia's SVD included.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from cmbs.dynamics.base import OK
from cmbs.dynamics.kkt import gram_bounds, has_structure, workspace_views
from cmbs.dynamics.lagrange import LagrangeKernel
from cmbs.dynamics.projection import PROJECTION_REGULAR, ProjectionKernel
from cmbs.integrate.compiled_rk4 import _rk4_arrays, _rk4_steps
from cmbs.integrate.continuity import left_branch, watch_array
from cmbs.integrate.variants import fresh
from cmbs.jit import borrow, interpreted, njit, prange
from cmbs.model.natural import NaturalKernel, _evaluate

#: States per block (eight float64 fill an AVX-512 register).
LANES = 8

#: Lane states.
RUNNING, LEAVING, LEFT = 0, 1, 2
#: The formulations the lanes run.
LAGRANGE, BAUMGARTE, PROJECTION = 0, 1, 2


def lane_setup(model: NamedTuple, formulation: NamedTuple, m: int, n: int) -> tuple | None:
    """(method, parameters, schur, plan) of :func:`rk4_lanes` for a model's and a formulation's
    kernels, or None when lanes cannot run the batch: a natural-coordinate model under Lagrange,
    Baumgarte (without ``least_squares``: the lanes solve the regular augmented system) or the
    projection with any inertia (``parameters`` = (ξ, ω, tolerance or threshold, s, semi-definite
    flag); ``schur`` the formulation's unpacked workspace), with :func:`lane_plan`."""
    if not isinstance(model, NaturalKernel):
        return None
    if isinstance(formulation, LagrangeKernel):
        method = BAUMGARTE if formulation.omega != 0.0 else LAGRANGE
        parameters = np.array([formulation.xi, formulation.omega, formulation.tolerance, 0.0, 0.0])
    elif isinstance(formulation, ProjectionKernel):
        method = PROJECTION
        parameters = np.array([0.0, 0.0, formulation.threshold, formulation.scale, float(formulation.semi_definite)])
    else:
        return None
    schur = workspace_views(formulation.floats, formulation.integers, formulation.layout)
    plan = lane_plan(schur, m, n)
    return None if plan is None else (method, parameters, schur, plan)


def lane_plan(schur: tuple, m: int, n: int) -> tuple | None:
    """The sparsity plan of :func:`_schur_lanes` for :func:`rk4_lanes`, or None when lanes cannot
    run the batch.

    Lanes take models whose massive block M_pp is positive definite (the Schur path's flag 1),
    that are not solved by band LU, with 1 <= m <= n constraints and A's structural pattern known
    (``schur`` of :func:`cmbs.dynamics.kkt.schur_workspace` built with it).

    The plan lists, each as [count, items...] along its last axis: the massive non-zeros of each
    row of A, as positions in M_pp's coordinates in increasing order (where
    :func:`cmbs.dynamics.kkt.schur_solve` finds them by scanning A's values); for each entry of
    X = M_pp⁻¹A_pᵀ, the non-zeros of its row of A whose M_pp⁻¹ entry is not zero; for each entry
    of y = M_pp⁻¹Q_p, the non-zero entries of its row of M_pp⁻¹; for each entry (a, b <= a) of
    A_pX, the non-zeros of row a of A whose X[b] is not structurally zero; for each massive q̈,
    the rows of X not structurally zero in it.  The terms left out are products with an exact
    zero, ±0, and the sums they leave start at +0 (or at y, itself such a sum): a sum that starts
    at +0 never becomes -0, and adding ±0 to it changes nothing, so the sums over the plan are
    bit for bit the dense ones (for finite A and Q, which a running lane has)."""
    if schur[1] != 1 or schur[16] == 1:
        return None
    inverse, rows_of, massive = schur[0], schur[13], schur[9]
    if m == 0 or m > n or not has_structure(rows_of, n) or schur[28].shape[0] != m:
        return None
    n_p = massive.size
    rows = [[] for _ in range(m)]
    for i, j in enumerate(massive):
        for r in rows_of[j, 1:1 + rows_of[j, 0]]:
            rows[r].append(i)
    x_terms = [[[column for column in rows[r] if inverse[i, column] != 0.0] for i in range(n_p)] for r in range(m)]
    x_nonzero = [[bool(x_terms[r][i]) for i in range(n_p)] for r in range(m)]
    y_terms = [[j for j in range(n_p) if inverse[i, j] != 0.0] for i in range(n_p)]
    reduced_terms = [[[column for column in rows[a] if x_nonzero[b][column]] for b in range(m)] for a in range(m)]
    q_terms = [[a for a in range(m) if x_nonzero[a][i]] for i in range(n_p)]
    return (_lists(rows, m, n_p), _lists(x_terms, (m, n_p), n_p), _lists(y_terms, n_p, n_p),
            _lists(reduced_terms, (m, m), n_p), _lists(q_terms, n_p, m))


def _lists(nested: list, shape: int | tuple, longest: int) -> np.ndarray:
    """Nested lists of indices as an int64 array of ``shape`` + (longest + 1,): each list's
    length, then its items."""
    table = np.zeros((*np.atleast_1d(shape), longest + 1), dtype=np.int64)
    for index in np.ndindex(*np.atleast_1d(shape)):
        items = nested
        for k in index:
            items = items[k]
        table[index][0] = len(items)
        table[index][1:1 + len(items)] = items
    return table


def rk4_lanes(model: NamedTuple, formulation: NamedTuple, inputs: NamedTuple, Q0: np.ndarray, QD0: np.ndarray,
              U0: np.ndarray, h: float, steps: int, every: int, buffer_size: int, m: int, Qs: np.ndarray,
              QDs: np.ndarray, PHIs: np.ndarray, statuses: np.ndarray, recorded: np.ndarray, lanes: tuple) -> None:
    """:func:`cmbs.integrate.variants.rk4_variants` (same arguments, then the :func:`lane_setup`
    made for the model and formulation; same outputs, bit for bit) in blocks of LANES variants,
    parallel over the blocks (numba threads, :func:`_run_blocks`); then each variant that left its
    lanes goes on in the one-variant loop from the step it left at, one after the other (a sweep
    in which none leaves never loads that loop)."""
    method, parameters, schur, plan = lanes
    N, n = Q0.shape
    exits = (np.full(N, RUNNING, dtype=np.int64), np.zeros(N, dtype=np.int64), np.zeros(N, dtype=np.int64),
             np.zeros((N, n)), np.zeros((N, n)), np.zeros((N, 3)), np.zeros((N, m, n)),
             np.zeros((N, interpreted(watch_array)(n, m).size)))
    _run_blocks(method, parameters, Q0, QD0, U0, h, steps, every, model.ints, model.reals, buffer_size,
                np.ascontiguousarray(formulation.row_scale), m, schur, plan, Qs, QDs, PHIs, *exits)
    states, left_at, records_before, resume_q, resume_qd, resume_reference, resume_A0, resume_watch = exits
    records_total = steps // every + 1
    statuses[states != LEFT] = OK
    recorded[states != LEFT] = records_total
    for v in np.flatnonzero(states == LEFT):
        single, records, work = _rk4_arrays(resume_q[v], resume_qd[v], U0[v], m, records_total, buffer_size)
        own = fresh(formulation)
        own_schur = workspace_views(own.floats, own.integers, own.layout)
        own_schur[27][:] = resume_reference[v]
        own_schur[28][:, :] = resume_A0[v]
        first = records_before[v]
        records[0][:first] = np.arange(first) * every * h     # the times of the lanes' records, for the watch
        done, status, _, _ = _rk4_steps(model, own, inputs, h, steps, every, *single, work, records, left_at[v],
                                        first, resume_watch[v].copy())
        Qs[v, first:done] = records[1][first:done]
        QDs[v, first:done] = records[2][first:done]
        PHIs[v, first:done] = records[6][first:done]
        Qs[v, done:first] = np.nan                  # lanes' records after the start of a jump: not kept
        QDs[v, done:first] = np.nan
        PHIs[v, done:first] = np.nan
        statuses[v] = status
        recorded[v] = done


@njit(cache=True)
def _private_copy(schur):
    """The unpacked workspace tuple with fresh copies of its scratch arrays (the constant M_pp⁻¹,
    its flag and the index arrays are shared), so that blocks running at the same time do not
    write into each other's workspace."""
    return (schur[0].copy() if schur[1] == 0 else schur[0], schur[1], schur[2].copy(), schur[3].copy(),
            schur[4].copy(), schur[5].copy(), schur[6].copy(), schur[7].copy(), schur[8].copy(), schur[9],
            schur[10], schur[11].copy(), schur[12], schur[13].copy(), schur[14], schur[15].copy(), schur[16],
            schur[17], schur[18].copy(), schur[19].copy(), schur[20].copy(), schur[21], schur[22], schur[23],
            schur[24], schur[25], schur[26], schur[27].copy(), schur[28].copy())


@njit(cache=True, parallel=True)
def _run_blocks(method, parameters, Q0, QD0, U0, h, steps, every, ints, reals, buffer_size, row_scale, m, schur, plan,
                Qs, QDs, PHIs, lanes, left_at, records_before, resume_q, resume_qd, resume_reference, resume_A0,
                resume_watch):
    """The lanes of :func:`rk4_lanes`, parallel over blocks of LANES variants: the records of
    every variant while it runs in its lanes, and per variant its lane state (RUNNING to the end,
    or LEFT) and, for a variant that left, its step, the records written before it and the state
    and certificate reference its one-variant run resumes from, written by the lanes (separate
    arguments: numba's parallel loop writes into copies of arrays passed to it in a tuple).  A
    last block with fewer variants fills its other lanes with copies of its first variant, whose
    outputs are not kept."""
    N, n = Q0.shape
    for block in prange((N + LANES - 1) // LANES):
        base = block * LANES
        count = min(LANES, N - base)
        state, work, block_lanes = _lane_arrays(n, m, schur[9].shape[0], schur[10].shape[0], U0.shape[1],
                                                buffer_size)
        q, qd, U = state
        for w in range(LANES):
            v = base + (w if w < count else 0)
            q[w] = Q0[v]
            qd[w] = QD0[v]
            U[w] = U0[v]
        exits = (left_at, records_before, resume_q, resume_qd, resume_reference, resume_A0, resume_watch)
        _lane_steps(method, parameters, h, steps, every, ints, reals, row_scale, _private_copy(schur), plan, state,
                    work, block_lanes, exits, base, count, Qs, QDs, PHIs)
        lanes[base:base + count] = block_lanes[:count]


@njit(cache=True)
def _lane_arrays(n, m, n_p, n_a, n_u, buffer_size):
    """The arrays of a block: two groups and the lane states.  State, per lane (rows): q, q̇ and
    the inputs.  Work: a one-state terms buffer, per lane the stage state and the slopes of the four
    stages, lane-major (lanes last) the terms (Q, Φ, A, γ, Φ_t in a terms buffer's order), the
    Schur workspace (X, y, the reduced matrix and right-hand side), c of Aq̈ = c, λ, q̈, the
    certificate's reference (valid, √λ_low, √λ_high) and A₀ with their values at the step's
    start, the lanes' accumulators (5, LANES) and one lane's A; per lane the branch watch
    (:mod:`cmbs.integrate.continuity`) and its value at the step's start."""
    size = m + n_a
    W = LANES
    state = (np.zeros((W, n)), np.zeros((W, n)), np.zeros((W, n_u)))
    work = (np.zeros(buffer_size), np.zeros((W, n)), np.zeros((W, n)),
            np.zeros((4, W, n)), np.zeros((4, W, n)), np.zeros((n + 3 * m + m * n, W)), np.zeros((m, n_p, W)),
            np.zeros((n_p, W)), np.zeros((size, size, W)), np.zeros((size, W)), np.zeros((m, W)), np.zeros((m, W)),
            np.zeros((n, W)), np.zeros((3, W)), np.zeros((m, n, W)), np.zeros((3, W)), np.zeros((m, n, W)),
            np.zeros((5, W)), np.zeros((m, n)), np.zeros((W, watch_array(n, m).shape[0])),
            np.zeros((W, watch_array(n, m).shape[0])))
    for w in range(W):
        work[19][w] = watch_array(n, m)
    return state, work, np.zeros(W, dtype=np.int64)


@njit(cache=True, error_model="numpy")
def _lane_steps(method, parameters, h, steps, every, ints, reals, row_scale, schur, plan, state, work, lanes, exits,
                base, count, Qs, QDs, PHIs):
    """The RK4 loop of :func:`cmbs.integrate.compiled_rk4._rk4_steps` (constant inputs, the whole run from t = 0)
    for the block's lanes; writes the records of lanes ``0..count-1`` (variants ``base + w``)
    while they run, the lane states in ``lanes``, and for each of those variants that leaves, its
    step, records and resume state in the per-variant ``exits`` (:func:`_leave`).  It borrows
    (:func:`cmbs.jit.borrow`) the block's arrays, which :func:`_lane_arrays` allocated."""
    parameters, ints, reals, row_scale, schur, plan, state, work, lanes, exits = borrow(
        (parameters, ints, reals, row_scale, schur, plan, state, work, lanes, exits))
    q, qd, U = state
    (buffer, sq, sv, kq, kv, terms, X, y, reduced, z, c, lam, qdd, reference, A0, start_reference, start_A0,
     scratch, single_A, watches, start_watches) = work
    n = q.shape[1]
    m = lam.shape[0]
    rows = terms.shape[0]
    a0 = n + m
    Q = terms[:n]
    phi = terms[n:a0]
    A = terms[a0:a0 + m * n].reshape((m, n, LANES))
    gamma = terms[a0 + m * n:a0 + m * n + m]
    phi_t = terms[a0 + m * n + m:a0 + m * n + 2 * m]
    recorded = 0
    for step in range(steps + 1):
        t = step * h
        st = t
        before = recorded
        _copy(reference, start_reference)
        _copy(A0.reshape((m * n, LANES)), start_A0.reshape((m * n, LANES)))
        _copy(watches, start_watches)
        for stage in range(4):
            if stage == 0:
                _copy(q, sq)
                _copy(qd, sv)
            else:
                a = h if stage == 3 else 0.5 * h
                for w in range(LANES):
                    for i in range(n):
                        sq[w, i] = q[w, i] + a * kq[stage - 1, w, i]
                        sv[w, i] = qd[w, i] + a * kv[stage - 1, w, i]
                st = t + a
            _copy(sv, kq[stage])
            for w in range(LANES):          # the one-state kernel, lane by lane, then lane-major
                _evaluate(sq[w], sv[w], st, U[w], ints, reals, buffer)
                for r in range(rows):
                    terms[r, w] = buffer[r]
            _finite_lanes(terms, lanes, scratch[0])
            if method == PROJECTION:
                _certify_lanes(A, row_scale, PROJECTION_REGULAR, parameters[2], True, reference, A0, schur, lanes,
                               single_A, scratch)
            else:
                _certify_lanes(A, row_scale, parameters[2], 0.0, False, reference, A0, schur, lanes, single_A,
                               scratch)
            for r in range(m):
                for w in range(LANES):
                    c[r, w] = gamma[r, w]
            if method == BAUMGARTE:
                _baumgarte_lanes(parameters, sv, phi, A, phi_t, c)
            _schur_lanes(schur[0], Q, A, c, schur[9], schur[10], plan, X, y, reduced, z, qdd, lam, lanes,
                         scratch[1:])
            _finite_lanes(qdd, lanes, scratch[0])
            for w in range(LANES):
                for i in range(n):
                    kv[stage, w, i] = qdd[i, w]
            if _leave(lanes, exits, step, q, qd, start_reference, start_A0, start_watches, before, base, count):
                return
            if stage == 0:
                _watch_lanes(watches, t, qd, kv[0], A, single_A, lanes)
                if _leave(lanes, exits, step, q, qd, start_reference, start_A0, start_watches, before, base, count):
                    return
                if step % every == 0:
                    for w in range(count):
                        if lanes[w] == RUNNING:
                            largest = 0.0
                            for r in range(m):
                                largest = max(largest, abs(phi[r, w]))
                            PHIs[base + w, recorded] = largest
                            for i in range(n):
                                Qs[base + w, recorded, i] = q[w, i]
                                QDs[base + w, recorded, i] = qd[w, i]
                    recorded += 1
                if step == steps:
                    break
        if step == steps:
            break
        for w in range(LANES):
            for i in range(n):
                q[w, i] += (h / 6.0) * (kq[0, w, i] + 2.0 * kq[1, w, i] + 2.0 * kq[2, w, i] + kq[3, w, i])
                qd[w, i] += (h / 6.0) * (kv[0, w, i] + 2.0 * kv[1, w, i] + 2.0 * kv[2, w, i] + kv[3, w, i])


@njit(cache=True, error_model="numpy", inline="always")
def _watch_lanes(watches, t, qd, qdd, A, single_A, lanes):
    """The branch watch of each running lane at its accepted state (t, q̇, q̈ = ``qdd`` (LANES, n),
    the lane-major ``A``), as the one-variant loop keeps it: a lane whose run left its branch
    leaves (its one-variant run, resumed from the step's start with the watch as it was there,
    finds the same jump and ends as that loop does).  ``single_A``: one lane's A."""
    m, n, _ = A.shape
    for w in range(LANES):
        if lanes[w] != RUNNING:
            continue
        for i in range(m):
            for j in range(n):
                single_A[i, j] = A[i, j, w]
        if left_branch(watches[w], t, qd[w], qdd[w], single_A):
            lanes[w] = LEAVING


@njit(cache=True, error_model="numpy", inline="always")
def _copy(source, target):
    """target[:, :] = source for 2-D arrays, element by element (a slice assignment may need a
    temporary)."""
    for i in range(source.shape[0]):
        for k in range(source.shape[1]):
            target[i, k] = source[i, k]


@njit(cache=True, error_model="numpy", inline="always")
def _certify_lanes(A, row_scale, ratio, floor, projection, reference, A0, schur, lanes, single_A, scratch):
    """The rank certificate per running lane (1 <= m <= n): the bounds of
    :func:`cmbs.dynamics.kkt.bounds_meeting` on σ(SA), reused from the lane's reference while
    ‖S(A - A₀)‖_F <= √λ₀_low / 10, else fresh (:func:`cmbs.dynamics.kkt.gram_bounds` on the lane's A)
    with the reference renewed, exactly as the one-variant field keeps it.  A lane leaves unless
    its bounds certify σ_min >= ratio·max(σ_max, 1): the test of :func:`cmbs.dynamics.kkt.certify`
    (Lagrange and Baumgarte: ``ratio`` their tolerance, ``floor`` 0) or, with ``projection``,
    that of :func:`cmbs.dynamics.projection._by_schur` (``ratio`` PROJECTION_REGULAR, and σ_min above
    the SVD threshold ``floor``)."""
    m, n, _ = A.shape
    rows_of = schur[13]
    total = scratch[4]
    for w in range(LANES):
        total[w] = 0.0
    for j in range(n):                      # δ² over the structural non-zeros, in bounds's order
        for a in range(rows_of[j, 0]):
            i = rows_of[j, 1 + a]
            for w in range(LANES):
                difference = (A[i, j, w] - A0[i, j, w]) * row_scale[i]
                total[w] += difference * difference
    for w in range(LANES):
        if lanes[w] != RUNNING:
            continue
        reused = False
        low, high = 0.0, 0.0
        if reference[0, w] == 1.0:
            delta = math.sqrt(total[w])
            if delta <= 0.1 * reference[1, w]:
                low, high = (reference[1, w] - delta) ** 2, (reference[2, w] + delta) ** 2
                reused = True
        if reused and (low < ratio * ratio * max(high, 1.0) or low <= floor * floor):
            reference[0, w] = 0.0
            reused = False
        if not reused:
            for i in range(m):
                for j in range(n):
                    single_A[i, j] = A[i, j, w]
            low, high = gram_bounds(single_A, row_scale, schur[7], schur[8], rows_of, schur[14], schur[15])
            reference[0, w] = 0.0
            if low > 0.0:
                for j in range(n):
                    for a in range(rows_of[j, 0]):
                        i = rows_of[j, 1 + a]
                        A0[i, j, w] = A[i, j, w]
                reference[0, w], reference[1, w], reference[2, w] = 1.0, math.sqrt(low), math.sqrt(high)
        if projection:
            holds = not (low < ratio * ratio * max(high, 1.0) or low <= floor * floor)
        else:
            holds = low >= ratio * ratio * max(high, 1.0)
        if not holds:
            lanes[w] = LEAVING


@njit(cache=True, error_model="numpy", inline="always")
def _baumgarte_lanes(parameters, sv, phi, A, phi_t, c):
    """c -= 2ξωΦ̇ + ω²Φ with Φ̇ = Aq̇ + Φ_t, per lane (Baumgarte's solve in :mod:`cmbs.dynamics.lagrange`)."""
    m, n, _ = A.shape
    for r in range(m):
        for w in range(LANES):
            rate = phi_t[r, w]
            for j in range(n):
                rate += A[r, j, w] * sv[w, j]
            c[r, w] -= 2.0 * parameters[0] * parameters[1] * rate + parameters[1] * parameters[1] * phi[r, w]


@njit(cache=True, error_model="numpy", inline="always")
def _schur_lanes(inverse, Q, A, c, massive, massless, plan, X, y, reduced, z, qdd, lam, lanes, pivot):
    """q̈, λ of [M Aᵀ; A 0][q̈; λ] = [Q; c] per lane by the block elimination of
    :func:`cmbs.dynamics.kkt.schur_solve` with the constant ``inverse`` = M_pp⁻¹ (its flag 1), the same
    operations in the same order, less the products with a structural zero (``plan`` of
    :func:`lane_plan`: bit for bit the same sums); the reduced system by Cholesky without
    massless coordinates, else by :func:`_eliminate_lanes`.  A lane whose factorisation fails
    leaves."""
    row_terms, x_terms, y_terms, reduced_terms, q_terms = plan
    m = c.shape[0]
    n_p = massive.shape[0]
    n_a = massless.shape[0]
    for r in range(m):                      # X = M_pp⁻¹ A_pᵀ
        for i in range(n_p):
            for w in range(LANES):
                X[r, i, w] = 0.0
            for k in range(x_terms[r, i, 0]):
                column = x_terms[r, i, 1 + k]
                for w in range(LANES):
                    X[r, i, w] += inverse[i, column] * A[r, massive[column], w]
    for i in range(n_p):                    # y = M_pp⁻¹ Q_p
        for w in range(LANES):
            y[i, w] = 0.0
        for k in range(y_terms[i, 0]):
            j = y_terms[i, 1 + k]
            for w in range(LANES):
                y[i, w] += inverse[i, j] * Q[massive[j], w]
    for a in range(m):
        for w in range(LANES):
            z[a, w] = -c[a, w]
        for k in range(row_terms[a, 0]):
            column = row_terms[a, 1 + k]
            for w in range(LANES):
                z[a, w] += A[a, massive[column], w] * y[column, w]
        for b in range(a + 1):
            for w in range(LANES):
                reduced[a, b, w] = 0.0
            for k in range(reduced_terms[a, b, 0]):
                column = reduced_terms[a, b, 1 + k]
                for w in range(LANES):
                    reduced[a, b, w] += A[a, massive[column], w] * X[b, column, w]
            for w in range(LANES):
                reduced[b, a, w] = reduced[a, b, w]
        for j in range(n_a):
            for w in range(LANES):
                reduced[a, m + j, w] = -A[a, massless[j], w]
                reduced[m + j, a, w] = A[a, massless[j], w]
    for j in range(n_a):
        for w in range(LANES):
            z[m + j, w] = Q[massless[j], w]
        for i in range(n_a):
            for w in range(LANES):
                reduced[m + j, m + i, w] = 0.0
    if n_a == 0:
        _cholesky_lanes(reduced, z, lanes, pivot[0])
    else:
        _eliminate_lanes(reduced, z, lanes, pivot[0], pivot[1], pivot[2])
    for a in range(m):
        for w in range(LANES):
            lam[a, w] = z[a, w]
    for j in range(n_a):
        for w in range(LANES):
            qdd[massless[j], w] = z[m + j, w]
    for i in range(n_p):
        for w in range(LANES):
            qdd[massive[i], w] = y[i, w]
        for k in range(q_terms[i, 0]):
            a = q_terms[i, 1 + k]
            for w in range(LANES):
                qdd[massive[i], w] -= X[a, i, w] * lam[a, w]


@njit(cache=True, error_model="numpy", inline="always")
def _cholesky_lanes(L, b, lanes, pivot):
    """Solve L Lᵀ x = b per lane in place, the dense Cholesky factorisation and the two triangular
    solves of :func:`cmbs.dynamics.kkt.cholesky_in_place`, :func:`cmbs.dynamics.kkt.solve_lower` and
    :func:`cmbs.dynamics.kkt.solve_lower_transposed` (a dense profile); a lane with a non-positive pivot leaves."""
    size = b.shape[0]
    for j in range(size):
        for w in range(LANES):
            pivot[w] = L[j, j, w]
        for k in range(j):
            for w in range(LANES):
                pivot[w] -= L[j, k, w] * L[j, k, w]
        for w in range(LANES):
            if not pivot[w] > 0.0 and lanes[w] == RUNNING:
                lanes[w] = LEAVING
            pivot[w] = math.sqrt(pivot[w])
            L[j, j, w] = pivot[w]
        for i in range(j + 1, size):
            for w in range(LANES):
                total = L[i, j, w]
                for k in range(j):
                    total -= L[i, k, w] * L[j, k, w]
                L[i, j, w] = total / pivot[w]
    for i in range(size):
        for w in range(LANES):
            total = b[i, w]
            for k in range(i):
                total -= L[i, k, w] * b[k, w]
            b[i, w] = total / L[i, i, w]
    for i in range(size - 1, -1, -1):
        for w in range(LANES):
            b[i, w] /= L[i, i, w]
            for k in range(i):
                b[k, w] -= L[i, k, w] * b[i, w]


@njit(cache=True, error_model="numpy", inline="always")
def _eliminate_lanes(K, rhs, lanes, largest, chosen, scale):
    """:func:`cmbs.dynamics.kkt.solve_in_place` per lane on the lane-major K (size, size, LANES) and rhs
    (size, LANES): Gaussian elimination with partial pivoting, each lane choosing its own pivot
    rows, and the same operations in the same order (an update whose factor is 0, which the
    one-lane code skips, leaves the entries as they are).  A lane with an exactly singular
    matrix leaves."""
    size = rhs.shape[0]
    for column in range(size):
        for w in range(LANES):
            largest[w] = abs(K[column, column, w])
            chosen[w] = column
        for row in range(column + 1, size):
            for w in range(LANES):
                value = abs(K[row, column, w])
                if value > largest[w]:
                    largest[w] = value
                    chosen[w] = row
        for w in range(LANES):
            if largest[w] == 0.0 and lanes[w] == RUNNING:
                lanes[w] = LEAVING
            pivot = int(chosen[w])
            if pivot != column:             # columns left of ``column`` are no longer read
                for k in range(column, size):
                    K[column, k, w], K[pivot, k, w] = K[pivot, k, w], K[column, k, w]
                rhs[column, w], rhs[pivot, w] = rhs[pivot, w], rhs[column, w]
        for w in range(LANES):
            scale[w] = 1.0 / K[column, column, w]
            K[column, column, w] = scale[w]
        for row in range(column + 1, size):
            for w in range(LANES):
                factor = K[row, column, w] * scale[w]
                if factor != 0.0:
                    for k in range(column + 1, size):
                        K[row, k, w] -= factor * K[column, k, w]
                    rhs[row, w] -= factor * rhs[column, w]
    for row in range(size - 1, -1, -1):
        for w in range(LANES):
            total = rhs[row, w]
            for k in range(row + 1, size):
                total -= K[row, k, w] * rhs[k, w]
            rhs[row, w] = total * K[row, row, w]


@njit(cache=True, error_model="numpy", inline="always")
def _finite_lanes(values, lanes, bad):
    """A running lane with a value (rows of the lane-major ``values``) that is not finite leaves:
    the terms, as :func:`cmbs.dynamics.field.field` checks them before any factorisation, and
    q̈ (:func:`cmbs.dynamics.field.field`)."""
    for w in range(LANES):
        bad[w] = 0.0
    for i in range(values.shape[0]):
        for w in range(LANES):
            bad[w] += values[i, w] - values[i, w]       # 0 when finite, NaN otherwise
    for w in range(LANES):
        if lanes[w] == RUNNING and bad[w] != 0.0:
            lanes[w] = LEAVING


@njit(cache=True, error_model="numpy")
def _leave(lanes, exits, step, q, qd, start_reference, start_A0, start_watches, records_before_step, base, count):
    """Lanes LEAVING at a stage of ``step`` become LEFT (computed on, never read); for those of
    the block's ``count`` variants, what their one-variant run resumes from goes into the
    per-variant ``exits`` at row ``base + w``: the step, the records written before it, the state,
    certificate reference and branch watch at the step's start.  True when none of the ``count``
    variants runs any more."""
    left_at, records_before, resume_q, resume_qd, resume_reference, resume_A0, resume_watch = exits
    running = False
    for w in range(LANES):
        if lanes[w] == LEAVING:
            lanes[w] = LEFT
            if w < count:
                v = base + w
                left_at[v] = step
                records_before[v] = records_before_step
                for i in range(q.shape[1]):
                    resume_q[v, i] = q[w, i]
                    resume_qd[v, i] = qd[w, i]
                for k in range(3):
                    resume_reference[v, k] = start_reference[k, w]
                for i in range(start_A0.shape[0]):
                    for j in range(start_A0.shape[1]):
                        resume_A0[v, i, j] = start_A0[i, j, w]
                for i in range(start_watches.shape[1]):
                    resume_watch[v, i] = start_watches[w, i]
        running = running or (w < count and lanes[w] == RUNNING)
    return not running
