"""The natural-coordinate terms for a block of states at once ("lanes").

:func:`evaluate_lanes` computes what :func:`cmbs.model.natural._evaluate` computes (Q, Φ, A, γ,
Φ_t of the thesis's natural-coordinate formulation, chapter 2: rigid-segment, distance, angle,
parallel, body point and driver rows; constant, point, segment, torque, moment, spring and
actuator forces) for LANES states
of one model, with the same operations in the same order: each lane's terms are bit for bit
the one-state kernel's (tests/test_natural_lanes.py).  The lane index is innermost, so each
row's indices are read once for the block and its arithmetic runs on contiguous lanes.  Time
functions (drivers, prescribed forces) depend on t only and are evaluated once for the block.
"""

from __future__ import annotations

import math

from cmbs.jit import njit
from cmbs.model.drivers import evaluate_time_functions
from cmbs.model.natural import (_ACTUATOR, _ACTUATOR_GAIN, _ANGLE, _BODY_POINT, _BODY_POINT_LOCAL, _DISTANCE,
                                _DRIVER, _LENGTH2, _MOMENT, _PARALLEL, _POINT_FORCE, _Q_CONSTANT, _RIGID,
                                _SEGMENT_FORCE, _SEGMENT_FORCE_AT, _SPRING, _SPRING_PARAMETERS, _TF_OPS, _TF_REALS,
                                _TF_TABLE, _TORQUE, _segment_force, layout)
from cmbs.model.packing import int_section, real_section

#: States per block (eight float64 fill an AVX-512 register).
LANES = 8


@njit(cache=True, error_model="numpy", inline="always")
def _add(terms, a0, row, column, n, w, value):
    """A[row, column] += value in lane ``w`` (columns of constants skipped)."""
    if column < n:
        terms[a0 + row * n + column, w] += value


@njit(cache=True, error_model="numpy", inline="always")
def _add_force(terms, index, w, value, n):
    """Q[index] += value in lane ``w`` (constants skipped)."""
    if index < n:
        terms[index, w] += value


@njit(cache=True, error_model="numpy", inline="always")
def _pair_indices(ints, r):
    """The point coordinates (x_i, z_i, x_j, z_j, x_k, z_k, x_l, z_l) of an angle or parallel row
    at ``ints[r:r + 8]``: the vectors u = j - i and w = l - k."""
    return ints[r], ints[r + 1], ints[r + 2], ints[r + 3], ints[r + 4], ints[r + 5], ints[r + 6], ints[r + 7]


@njit(cache=True, error_model="numpy", inline="always")
def _pair(x, v, w, indices):
    """u, w of :func:`_pair_indices` in lane ``w`` and their rates, as
    :func:`cmbs.model.natural._vector_pair` computes them."""
    xi, zi, xj, zj, xk, zk, xl, zl = indices
    ux, uz = x[xj, w] - x[xi, w], x[zj, w] - x[zi, w]
    wx, wz = x[xl, w] - x[xk, w], x[zl, w] - x[zk, w]
    dux, duz = v[xj, w] - v[xi, w], v[zj, w] - v[zi, w]
    dwx, dwz = v[xl, w] - v[xk, w], v[zl, w] - v[zk, w]
    return ux, uz, wx, wz, dux, duz, dwx, dwz


@njit(cache=True, error_model="numpy", inline="always")
def evaluate_lanes(q, qd, t, U, ints, reals, buffer, x, v, terms):
    """Q, Φ, A, γ, Φ_t at the LANES states (q[w], q̇[w]) with inputs U[w] into the lane-major
    ``terms`` (n + 3m + mn, LANES), rows in the order of a :class:`~cmbs.model.model.Terms`
    buffer.  ``buffer`` is a one-state terms buffer whose scratch holds the time functions and
    their stack, as for the one-state kernel; ``x``, ``v`` (n_ext, LANES) receive the extended
    coordinates (q, constants) and velocities (q̇, 0)."""
    n = q.shape[1]
    real_base, c0, n_ext, m, a0, g0, t0, s0, x0 = layout(ints, n, buffer.shape[0])
    for k in range(n):
        for w in range(LANES):
            x[k, w] = q[w, k]
            v[k, w] = qd[w, k]
    for k in range(n, n_ext):
        for w in range(LANES):
            x[k, w] = reals[c0 + k - n]
            v[k, w] = 0.0
    n_tf = (ints[2 + _TF_TABLE] - ints[1 + _TF_TABLE]) // 4
    if n_tf > 0:
        evaluate_time_functions(int_section(ints, _TF_TABLE).reshape((n_tf, 4)),
                                int_section(ints, _TF_OPS).reshape((-1, 2)), real_section(ints, reals, _TF_REALS), t,
                                buffer[s0 + 3 * n_tf:x0].reshape((-1, 3)), buffer[s0:s0 + 3 * n_tf].reshape((n_tf, 3)))
    terms[a0:g0] = 0.0
    terms[t0:s0] = 0.0
    row = 0
    i0 = ints[1 + _RIGID]
    l0 = ints[real_base + 1 + _LENGTH2]
    for k in range((ints[2 + _RIGID] - i0) // 4):
        xi, zi, xj, zj = ints[i0 + 4 * k], ints[i0 + 4 * k + 1], ints[i0 + 4 * k + 2], ints[i0 + 4 * k + 3]
        for w in range(LANES):
            dx, dz = x[xj, w] - x[xi, w], x[zj, w] - x[zi, w]
            dvx, dvz = v[xj, w] - v[xi, w], v[zj, w] - v[zi, w]
            terms[n + row, w] = dx * dx + dz * dz - reals[l0 + k]
            _add(terms, a0, row, xi, n, w, -2.0 * dx)
            _add(terms, a0, row, zi, n, w, -2.0 * dz)
            _add(terms, a0, row, xj, n, w, 2.0 * dx)
            _add(terms, a0, row, zj, n, w, 2.0 * dz)
            terms[g0 + row, w] = -2.0 * (dvx * dvx + dvz * dvz)
        row += 1

    i0 = ints[1 + _DISTANCE]
    for k in range((ints[2 + _DISTANCE] - i0) // 5):
        xi, zi, xj, zj, s = (ints[i0 + 5 * k], ints[i0 + 5 * k + 1], ints[i0 + 5 * k + 2], ints[i0 + 5 * k + 3],
                             ints[i0 + 5 * k + 4])
        for w in range(LANES):
            dx, dz = x[xj, w] - x[xi, w], x[zj, w] - x[zi, w]
            dvx, dvz = v[xj, w] - v[xi, w], v[zj, w] - v[zi, w]
            terms[n + row, w] = dx * dx + dz * dz - x[s, w] * x[s, w]
            _add(terms, a0, row, xi, n, w, -2.0 * dx)
            _add(terms, a0, row, zi, n, w, -2.0 * dz)
            _add(terms, a0, row, xj, n, w, 2.0 * dx)
            _add(terms, a0, row, zj, n, w, 2.0 * dz)
            terms[a0 + row * n + s, w] += -2.0 * x[s, w]
            terms[g0 + row, w] = -2.0 * (dvx * dvx + dvz * dvz) + 2.0 * v[s, w] * v[s, w]
        row += 1

    i0 = ints[1 + _ANGLE]
    for k in range((ints[2 + _ANGLE] - i0) // 9):
        r = i0 + 9 * k
        indices = _pair_indices(ints, r)
        pi, pk, pj, pl, qi, qk, qj, ql = indices
        angle = ints[r + 8]
        for w in range(LANES):
            ux, uz, wx, wz, dux, duz, dwx, dwz = _pair(x, v, w, indices)
            f, df = x[angle, w], v[angle, w]
            c, s = math.cos(f), math.sin(f)
            cross = ux * wz - uz * wx
            dot = ux * wx + uz * wz
            dcross = dux * wz + ux * dwz - duz * wx - uz * dwx
            ddot = dux * wx + ux * dwx + duz * wz + uz * dwz
            terms[n + row, w] = c * cross - s * dot
            gux, guz = c * wz - s * wx, -c * wx - s * wz
            gwx, gwz = -c * uz - s * ux, c * ux - s * uz
            _add(terms, a0, row, pi, n, w, -gux)
            _add(terms, a0, row, pk, n, w, -guz)
            _add(terms, a0, row, pj, n, w, gux)
            _add(terms, a0, row, pl, n, w, guz)
            _add(terms, a0, row, qi, n, w, -gwx)
            _add(terms, a0, row, qk, n, w, -gwz)
            _add(terms, a0, row, qj, n, w, gwx)
            _add(terms, a0, row, ql, n, w, gwz)
            terms[a0 + row * n + angle, w] += -s * cross - c * dot
            cross_vv = dux * dwz - duz * dwx
            dot_vv = dux * dwx + duz * dwz
            quadratic = (-c * df * df * cross - 2.0 * s * df * dcross + 2.0 * c * cross_vv
                         + s * df * df * dot - 2.0 * c * df * ddot - 2.0 * s * dot_vv)
            terms[g0 + row, w] = -quadratic
        row += 1

    i0 = ints[1 + _PARALLEL]
    for k in range((ints[2 + _PARALLEL] - i0) // 8):
        indices = _pair_indices(ints, i0 + 8 * k)
        pi, pk, pj, pl, qi, qk, qj, ql = indices
        for w in range(LANES):
            ux, uz, wx, wz, dux, duz, dwx, dwz = _pair(x, v, w, indices)
            terms[n + row, w] = ux * wz - uz * wx
            _add(terms, a0, row, pi, n, w, -wz)
            _add(terms, a0, row, pk, n, w, wx)
            _add(terms, a0, row, pj, n, w, wz)
            _add(terms, a0, row, pl, n, w, -wx)
            _add(terms, a0, row, qi, n, w, uz)
            _add(terms, a0, row, qk, n, w, -ux)
            _add(terms, a0, row, qj, n, w, -uz)
            _add(terms, a0, row, ql, n, w, ux)
            terms[g0 + row, w] = -2.0 * (dux * dwz - duz * dwx)
        row += 1

    i0 = ints[1 + _BODY_POINT]
    p0 = ints[real_base + 1 + _BODY_POINT_LOCAL]
    for k in range((ints[2 + _BODY_POINT] - i0) // 6):
        r = i0 + 6 * k
        xi, zi, xj, zj, xk, zk = ints[r], ints[r + 1], ints[r + 2], ints[r + 3], ints[r + 4], ints[r + 5]
        s, e = reals[p0 + 2 * k], reals[p0 + 2 * k + 1]
        for w in range(LANES):
            dx, dz = x[xj, w] - x[xi, w], x[zj, w] - x[zi, w]
            terms[n + row, w] = x[xk, w] - x[xi, w] - s * dx + e * dz
            _add(terms, a0, row, xi, n, w, s - 1.0)
            _add(terms, a0, row, zi, n, w, -e)
            _add(terms, a0, row, xj, n, w, -s)
            _add(terms, a0, row, zj, n, w, e)
            _add(terms, a0, row, xk, n, w, 1.0)
            terms[g0 + row, w] = 0.0
            terms[n + row + 1, w] = x[zk, w] - x[zi, w] - s * dz - e * dx
            _add(terms, a0, row + 1, xi, n, w, e)
            _add(terms, a0, row + 1, zi, n, w, s - 1.0)
            _add(terms, a0, row + 1, xj, n, w, -e)
            _add(terms, a0, row + 1, zj, n, w, -s)
            _add(terms, a0, row + 1, zk, n, w, 1.0)
            terms[g0 + row + 1, w] = 0.0
        row += 2

    i0 = ints[1 + _DRIVER]
    for k in range((ints[2 + _DRIVER] - i0) // 2):
        c, f = ints[i0 + 2 * k], ints[i0 + 2 * k + 1]
        for w in range(LANES):
            terms[n + row, w] = x[c, w] - buffer[s0 + 3 * f]
            terms[a0 + row * n + c, w] = 1.0
            terms[t0 + row, w] = -buffer[s0 + 3 * f + 1]
            terms[g0 + row, w] = buffer[s0 + 3 * f + 2]
        row += 1

    r0 = ints[real_base + 1 + _Q_CONSTANT]
    for k in range(n):
        for w in range(LANES):
            terms[k, w] = reals[r0 + k]
    i0 = ints[1 + _POINT_FORCE]
    for k in range((ints[2 + _POINT_FORCE] - i0) // 4):
        xi, zi, fx, fz = ints[i0 + 4 * k], ints[i0 + 4 * k + 1], ints[i0 + 4 * k + 2], ints[i0 + 4 * k + 3]
        for w in range(LANES):
            if xi < n:
                terms[xi, w] += buffer[s0 + 3 * fx]
            if zi < n:
                terms[zi, w] += buffer[s0 + 3 * fz]
    i0 = ints[1 + _TORQUE]
    for k in range((ints[2 + _TORQUE] - i0) // 2):
        for w in range(LANES):
            terms[ints[i0 + 2 * k], w] += buffer[s0 + 3 * ints[i0 + 2 * k + 1]]
    i0 = ints[1 + _SEGMENT_FORCE]
    p0 = ints[real_base + 1 + _SEGMENT_FORCE_AT]
    for k in range((ints[2 + _SEGMENT_FORCE] - i0) // 7):
        r = i0 + 7 * k
        xi, zi, xj, zj = ints[r], ints[r + 1], ints[r + 2], ints[r + 3]
        first, second, frame = buffer[s0 + 3 * ints[r + 4]], buffer[s0 + 3 * ints[r + 5]], ints[r + 6]
        s, e = reals[p0 + 2 * k], reals[p0 + 2 * k + 1]
        for w in range(LANES):
            fx, fz = _segment_force(x[:, w], xi, zi, xj, zj, first, second, frame)
            _add_force(terms, xi, w, (1.0 - s) * fx - e * fz, n)
            _add_force(terms, zi, w, e * fx + (1.0 - s) * fz, n)
            _add_force(terms, xj, w, s * fx + e * fz, n)
            _add_force(terms, zj, w, s * fz - e * fx, n)
    i0 = ints[1 + _MOMENT]
    for k in range((ints[2 + _MOMENT] - i0) // 5):
        r = i0 + 5 * k
        xi, zi, xj, zj = ints[r], ints[r + 1], ints[r + 2], ints[r + 3]
        moment = buffer[s0 + 3 * ints[r + 4]]
        for w in range(LANES):
            dx, dz = x[xj, w] - x[xi, w], x[zj, w] - x[zi, w]
            scale = moment / (dx * dx + dz * dz)
            _add_force(terms, xi, w, scale * dz, n)
            _add_force(terms, zi, w, -scale * dx, n)
            _add_force(terms, xj, w, -scale * dz, n)
            _add_force(terms, zj, w, scale * dx, n)
    i0 = ints[1 + _SPRING]
    r0 = ints[real_base + 1 + _SPRING_PARAMETERS]
    for k in range((ints[2 + _SPRING] - i0) // 4):
        xi, zi, xj, zj = ints[i0 + 4 * k], ints[i0 + 4 * k + 1], ints[i0 + 4 * k + 2], ints[i0 + 4 * k + 3]
        for w in range(LANES):
            dx, dz = x[xj, w] - x[xi, w], x[zj, w] - x[zi, w]
            length = math.sqrt(dx * dx + dz * dz)
            ex, ez = dx / length, dz / length
            rate = ex * (v[xj, w] - v[xi, w]) + ez * (v[zj, w] - v[zi, w])
            tension = reals[r0 + 3 * k] * (length - reals[r0 + 3 * k + 2]) + reals[r0 + 3 * k + 1] * rate
            if xi < n:
                terms[xi, w] += tension * ex
            if zi < n:
                terms[zi, w] += tension * ez
            if xj < n:
                terms[xj, w] += -tension * ex
            if zj < n:
                terms[zj, w] += -tension * ez
    i0 = ints[1 + _ACTUATOR]
    r0 = ints[real_base + 1 + _ACTUATOR_GAIN]
    for k in range(ints[2 + _ACTUATOR] - i0):
        for w in range(LANES):
            terms[ints[i0 + k], w] += reals[r0 + k] * U[w, k]

