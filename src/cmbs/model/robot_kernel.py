"""Compiled dynamics of a spatial joint-coordinate tree: CRBA for M(q), RNEA for the bias forces.

Spatial vectors are Plücker coordinates in world axes about the world origin (Featherstone,
*Rigid Body Dynamics Algorithms*, Springer 2008, ch. 2): a motion ``v = (ω, v_O)`` (angular
velocity, velocity of the body point at the world origin), a force ``f = (n_O, f)`` (moment about
the world origin, resultant).  In these coordinates no transform is needed between bodies, and
every body's quantities are written once per evaluation (the algorithms in ground coordinates,
Featherstone §5.3 and §6.2 with every transform the identity).

Per body k (one per movable joint), with parent p (-1: the ground), fixed placement ``(E_k, r_k)``
of the joint frame in the parent body's frame and unit axis ``a_k`` (joint frame)::

    revolute:   R_k = R_p E_k Rot(a_k, q_k),   o_k = o_p + R_p r_k,
    prismatic:  R_k = R_p E_k,                 o_k = o_p + R_p r_k + q_k z_k,
    z_k = R_p E_k a_k (the world axis),
    S_k = (z_k, o_k × z_k) (revolute),  S_k = (0, z_k) (prismatic)      (motion subspace),

``Rot(a, θ) = 1 + sin θ [a]× + (1 - cos θ) [a]×²`` (Rodrigues).  Recursive Newton-Euler with
q̈ = 0 and the base accelerating at -g instead of gravity acting on each body (Featherstone §5.3)::

    v_k = v_p + S_k q̇_k,      a_k = a_p + v_k ×ₘ S_k q̇_k,      a_ground = (0, -g),
    f_k = I_k a_k + v_k ×_f I_k v_k,      f_p += f_k,      b_k = S_kᵀ f_k,

so ``b = C(q, q̇) q̇ + g(q)`` and ``Q = u - b`` (joint torques u, one per joint).  Applied loads
(:mod:`cmbs.model.robot_loads`) enter as Featherstone's external forces (§5.3: ``f_k = I_k a_k +
v_k ×_f I_k v_k - f_k^ext``): a force F (world axes) at the world point p of body k is the spatial
force ``f^ext = (p × F, F)`` about the world origin, a moment M is ``(M, 0)``; a force or moment
given in the link's axes is first turned into the world's, ``F = R_k E F_link`` (E the link
frame's rotation in the body frame).  The backward pass's ``S_jᵀ f^ext`` is then, for every joint
j between body k and the ground, ``z_j·((p - o_j) × F)`` (revolute) or ``z_j·F`` (prismatic):
``Q += J_pᵀ F`` (J_p the point's translational Jacobian) and ``Q += J_ωᵀ M`` (J_ω the body's
angular one).  A spring-damper between the point p_a of body a and p_b of body b (either may be
the ground, whose points are fixed in the world) is two such forces, ``-f u`` at p_a and ``+f u``
at p_b, with ``d = p_a - p_b``, ``ℓ = |d|``, ``u = d / ℓ``, ``ℓ̇ = u·(ṗ_a - ṗ_b)`` (the points'
velocities of the forward pass) and the tension ``f = k (ℓ - ℓ0) + c ℓ̇``:
``Q += J_aᵀ(-f u) + J_bᵀ(f u)``.  At ℓ = 0 u is undefined and the spring exerts no force (the
length is computed scaled by the largest component of d, so a tiny ℓ gives a unit u, not 0/0).
A joint spring-damper on coordinate c adds ``-k (q_c - q_rest) - c q̇_c`` to Q_c.
The composite-rigid-body algorithm (Featherstone §6.2)::

    I^c_k = I_k + Σ_children I^c_c,     M_kk = S_kᵀ I^c_k S_k,     M_jk = M_kj = S_jᵀ I^c_k S_k
    for every ancestor j of k.

A spatial inertia about the world origin is held as (m, h = m c, Ī = I_G + m (|c|² 1 - c cᵀ))
with c the centre of mass and I_G the inertia about it, both in world axes (Featherstone ch. 2: the
rigid-body inertia moved to the origin); ``I v = (Ī ω + h × v_O, m v_O - h × ω)``, and composite
inertias are sums of the ten numbers.

Constraint rows (loop closures, :mod:`cmbs.model.robot_closures`; pose drivers,
:mod:`cmbs.model.robot_targets`; joint drivers) follow the tree's terms in the same evaluation.
A body point with local coordinates l is at ``p = o_k + R_k l`` with velocity ``ṗ = v_O + ω × p``
and, at q̈ = 0, acceleration (Featherstone §2.11: the classical acceleration of a body point from
the spatial one)::

    J̇ q̇ (p) = a_O + α × p + ω × ṗ,      (α, a_O) = a_k + (0, g)  (the RNEA's a_k without the base's -g),

and the columns of its Jacobian along the path to the ground are ``S_j,lin + S_j,ang × p``; a
body-fixed vector ``u = R_k ū`` has ``u̇ = ω × u`` and the angular columns ``S_j,ang``.  Rows::

    point  (3):  Φ = p_a - p_b,   A = J_a - J_b,   γ = -(J̇_a q̇ - J̇_b q̇),
    dot    (1):  Φ = u·v (u on body a, v on body b),   A = (u × v)ᵀ (J_ω,a - J_ω,b),
                 γ = -[((ω_a × u) × v + u × (ω_b × v))·(ω_a - ω_b) + (u × v)·(α_a - α_b)],
    line   (1):  Φ = d·v, d = p_a - p_b, v on body b,   A = vᵀ (J_a - J_b) + (v × d)ᵀ J_ω,b,
                 γ = -[(J̇_a q̇ - J̇_b q̇)·v + 2 ḋ·(ω_b × v) + (v × d)·α_b + d·(ω_b × (ω_b × v))],
    mimic  (1):  Φ = q_j - r q_k - o (joint j mimics joint k),   A = e_jᵀ - r e_kᵀ,   γ = 0,
    driver (1):  Φ = q_c - f(t),   A = e_cᵀ,   γ = f''(t),   Φ_t = -f'(t),

from Φ̇ = (u × v)·(ω_a - ω_b) (since u̇·v = ω_a·(u × v) and u·v̇ = -ω_b·(u × v)) and
Φ̇ = ḋ·v + d·(ω_b × v) = ḋ·v + (v × d)·ω_b, whose derivative at q̈ = 0, with
v̈ = α_b × v + ω_b × (ω_b × v), is the bracket of the line's γ; Φ_t = 0 for the closures, and
the ground (body -1) has p = l, u = ū and no motion.  A pose driver's target frame moves with
time instead of a body: its point p_t(t) (velocity ṗ_t, acceleration p̈_t) and the columns v of
its rotation Rot(rpy(t)) (angular velocity ω_t, acceleration α_t; :func:`_target_frame`) take
body b's place in the point and dot rows, with no Jacobian columns, Φ_t = -ṗ_t and
Φ_t = -(u × v)·ω_t, and p̈_t, α_t in γ in place of body b's bias accelerations (the rows'
Φ_tt: γ = -(Φ_qq q̇ q̇ + 2 Φ_qt q̇ + Φ_tt) exactly).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from cmbs.jit import borrow, njit
from cmbs.model.drivers import evaluate_time_functions

REVOLUTE, PRISMATIC = 0, 1
#: constraint elements (module docstring): a point coincidence (3 rows), a dot product of two
#: body-fixed vectors (1 row), a point difference along a vector of body b (1 row), a body
#: point on, or a body vector's dot product with a column of, a pose driver's target frame, and
#: a joint coupled to another (URDF's mimic; 1 row)
CLOSE_POINT, CLOSE_DOT, CLOSE_LINE, TARGET_POINT, TARGET_DOT, JOINT_COUPLING = 0, 1, 2, 3, 4, 5
#: per element in ``closure_reals``: l_a or ū (3), l_b or v̄ (3), v̄ of a line element (3)
ELEMENT_REALS = 9
#: per body in ``placement``: E (3 x 3, row-major), then r (3)
PLACEMENT = 12
#: per body in ``inertia``: mass, centre of mass (3, body frame), inertia about it (xx, xy, xz, yy, yz, zz; body axes)
INERTIA = 10
#: applied loads (:mod:`cmbs.model.robot_loads`): a force at a body point, a moment on a body; their
#: components along the world's axes or along the link's (turning with it)
LOAD_FORCE, LOAD_MOMENT = 0, 1
FRAME_WORLD, FRAME_LINK = 0, 1
#: per load in ``load_reals``: the point in the body frame (3), the link frame's rotation E in the
#: body frame (3 x 3, row-major)
LOAD_REALS = 12
#: per joint spring-damper in ``spring_reals``: stiffness k, rest value q_rest, damping c
SPRING_REALS = 3
#: per spring-damper between two points in ``point_spring_reals``: l_a (3, body a's frame), l_b (3,
#: body b's frame; world coordinates for the ground), stiffness k, damping c, rest length ℓ0
POINT_SPRING_REALS = 9
# work per body: R (9), o (3), S (6), v (6), a (6), f (6), composite inertia (m, h (3), Ī (xx, xy, xz, yy, yz, zz))
_R, _O, _S, _V, _A, _F, _I = 0, 9, 12, 18, 24, 30, 36
WORK = 46


class RobotKernel(NamedTuple):
    """A spatial tree as the compiled loops take it (:mod:`cmbs.model.compiled`); ``mass`` is
    empty (M depends on q and is written into the terms buffer).  Constraint rows: the closure
    elements in order (their rows first), then one row per driver."""

    parent: np.ndarray       # (n,) int64, -1 for the ground
    order: np.ndarray        # (n,) int64, parents before children
    kind: np.ndarray         # (n,) int64, REVOLUTE or PRISMATIC
    placement: np.ndarray    # (n, PLACEMENT)
    axis: np.ndarray         # (n, 3) unit axes in the joint frames
    inertia: np.ndarray      # (n, INERTIA)
    gravity: np.ndarray      # (3,)
    closure_ints: np.ndarray     # (e, 4) int64: element kind, body a, body b (-1: the ground) or the first of
                                 # the target's three time functions (TARGET_*), the target frame's column (TARGET_DOT);
                                 # JOINT_COUPLING: the mimicking and the mimicked coordinate
    closure_reals: np.ndarray    # (e, ELEMENT_REALS): l_a, l_b (points) or ū, v̄ (vectors), then v̄ (CLOSE_LINE);
                                 # JOINT_COUPLING: multiplier, offset;
                                 # in the bodies' frames
    drivers: np.ndarray          # (d, 2) int64: driven coordinate, time function
    tf_table: np.ndarray         # the drivers' time functions (:class:`cmbs.model.drivers.TimeFunctionPack`)
    tf_ops: np.ndarray
    tf_reals: np.ndarray
    sizes: np.ndarray            # (2,) int64: m (constraint rows), depth of the expression stack
    springs: np.ndarray          # (s,) int64: the coordinate of each joint spring-damper
    spring_reals: np.ndarray     # (s, SPRING_REALS): k, q_rest, c
    load_ints: np.ndarray        # (l, 4) int64: LOAD_FORCE or LOAD_MOMENT, body, FRAME_WORLD or FRAME_LINK, the
                                 # first of its three time functions (x, y, z components)
    load_reals: np.ndarray       # (l, LOAD_REALS): point (body frame), E
    point_springs: np.ndarray        # (p, 2) int64: body a, body b (-1: the ground) of each point spring-damper
    point_spring_reals: np.ndarray   # (p, POINT_SPRING_REALS): l_a, l_b, k, c, ℓ0
    mass: np.ndarray         # (0, 0)


def scratch_size(kernel: RobotKernel) -> int:
    """Scratch of a terms buffer: the time functions' values (k, 3), their stack (depth, 3) and
    the work per body."""
    return 3 * kernel.tf_table.shape[0] + 3 * int(kernel.sizes[1]) + WORK * kernel.parent.shape[0]


@njit(cache=True, inline="always")
def _pose(parent, kind, placement, axis, q, k, W, w0):
    """R_k, o_k and S_k of body k into its work slots, from its parent's (module docstring)."""
    p = parent[k]
    base = w0 + WORK * k
    E = placement[k]
    ax, ay, az = axis[k, 0], axis[k, 1], axis[k, 2]
    if p >= 0:
        pb = w0 + WORK * p
        opx, opy, opz = W[pb + _O], W[pb + _O + 1], W[pb + _O + 2]
    else:
        pb = -1
        opx, opy, opz = 0.0, 0.0, 0.0
    # world rotation of the joint frame, G = R_p E, element by element into W[base + _R:]
    for i in range(3):
        for j in range(3):
            if pb >= 0:
                W[base + _R + 3 * i + j] = (W[pb + _R + 3 * i] * E[j] + W[pb + _R + 3 * i + 1] * E[3 + j]
                                            + W[pb + _R + 3 * i + 2] * E[6 + j])
            else:
                W[base + _R + 3 * i + j] = E[3 * i + j]
    rx, ry, rz = E[9], E[10], E[11]
    if pb >= 0:
        ox = opx + W[pb + _R] * rx + W[pb + _R + 1] * ry + W[pb + _R + 2] * rz
        oy = opy + W[pb + _R + 3] * rx + W[pb + _R + 4] * ry + W[pb + _R + 5] * rz
        oz = opz + W[pb + _R + 6] * rx + W[pb + _R + 7] * ry + W[pb + _R + 8] * rz
    else:
        ox, oy, oz = opx + rx, opy + ry, opz + rz
    g = base + _R
    zx = W[g] * ax + W[g + 1] * ay + W[g + 2] * az
    zy = W[g + 3] * ax + W[g + 4] * ay + W[g + 5] * az
    zz = W[g + 6] * ax + W[g + 7] * ay + W[g + 8] * az
    s = base + _S
    if kind[k] == REVOLUTE:
        # R_k = G Rot(a, q) with Rot = 1 + sin [a]x + (1 - cos) [a]x²
        c, sn = math.cos(q[k]), math.sin(q[k])
        t = 1.0 - c
        r00, r01, r02 = 1.0 + t * (ax * ax - 1.0), t * ax * ay - sn * az, t * ax * az + sn * ay
        r10, r11, r12 = t * ax * ay + sn * az, 1.0 + t * (ay * ay - 1.0), t * ay * az - sn * ax
        r20, r21, r22 = t * ax * az - sn * ay, t * ay * az + sn * ax, 1.0 + t * (az * az - 1.0)
        for i in range(3):
            g0, g1, g2 = W[g + 3 * i], W[g + 3 * i + 1], W[g + 3 * i + 2]
            W[g + 3 * i] = g0 * r00 + g1 * r10 + g2 * r20
            W[g + 3 * i + 1] = g0 * r01 + g1 * r11 + g2 * r21
            W[g + 3 * i + 2] = g0 * r02 + g1 * r12 + g2 * r22
        W[s], W[s + 1], W[s + 2] = zx, zy, zz
        W[s + 3] = oy * zz - oz * zy
        W[s + 4] = oz * zx - ox * zz
        W[s + 5] = ox * zy - oy * zx
    else:
        ox += q[k] * zx
        oy += q[k] * zy
        oz += q[k] * zz
        W[s], W[s + 1], W[s + 2] = 0.0, 0.0, 0.0
        W[s + 3], W[s + 4], W[s + 5] = zx, zy, zz
    W[base + _O], W[base + _O + 1], W[base + _O + 2] = ox, oy, oz


@njit(cache=True, inline="always")
def _body_inertia(inertia, k, W, w0):
    """Body k's own spatial inertia (m, h, Ī) about the world origin into its composite slots
    (module docstring), from its mass, centre of mass and inertia in the body frame."""
    base = w0 + WORK * k
    R = base + _R
    m = inertia[k, 0]
    bx, by, bz = inertia[k, 1], inertia[k, 2], inertia[k, 3]
    cx = W[base + _O] + W[R] * bx + W[R + 1] * by + W[R + 2] * bz
    cy = W[base + _O + 1] + W[R + 3] * bx + W[R + 4] * by + W[R + 5] * bz
    cz = W[base + _O + 2] + W[R + 6] * bx + W[R + 7] * by + W[R + 8] * bz
    # I_G in world axes: R J Rᵀ, J symmetric from (xx, xy, xz, yy, yz, zz)
    j00, j01, j02, j11, j12, j22 = inertia[k, 4], inertia[k, 5], inertia[k, 6], inertia[k, 7], inertia[k, 8], \
        inertia[k, 9]
    w = base + _I
    W[w] = m
    W[w + 1], W[w + 2], W[w + 3] = m * cx, m * cy, m * cz
    c2 = cx * cx + cy * cy + cz * cz
    slot = w + 4
    for i in range(3):
        # row i of R J
        a0 = W[R + 3 * i] * j00 + W[R + 3 * i + 1] * j01 + W[R + 3 * i + 2] * j02
        a1 = W[R + 3 * i] * j01 + W[R + 3 * i + 1] * j11 + W[R + 3 * i + 2] * j12
        a2 = W[R + 3 * i] * j02 + W[R + 3 * i + 1] * j12 + W[R + 3 * i + 2] * j22
        ci = cx if i == 0 else (cy if i == 1 else cz)
        for j in range(i, 3):
            cj = cx if j == 0 else (cy if j == 1 else cz)
            value = a0 * W[R + 3 * j] + a1 * W[R + 3 * j + 1] + a2 * W[R + 3 * j + 2] - m * ci * cj
            if i == j:
                value += m * c2
            W[slot] = value
            slot += 1


@njit(cache=True, inline="always")
def _inertia_times(W, w, ox, oy, oz, vx, vy, vz):
    """I v for the spatial inertia (m, h, Ī) at W[w:] and the motion (ω, v_O)."""
    m, hx, hy, hz = W[w], W[w + 1], W[w + 2], W[w + 3]
    i00, i01, i02, i11, i12, i22 = W[w + 4], W[w + 5], W[w + 6], W[w + 7], W[w + 8], W[w + 9]
    nx = i00 * ox + i01 * oy + i02 * oz + hy * vz - hz * vy
    ny = i01 * ox + i11 * oy + i12 * oz + hz * vx - hx * vz
    nz = i02 * ox + i12 * oy + i22 * oz + hx * vy - hy * vx
    fx = m * vx - (hy * oz - hz * oy)
    fy = m * vy - (hz * ox - hx * oz)
    fz = m * vz - (hx * oy - hy * ox)
    return nx, ny, nz, fx, fy, fz


@njit(cache=True)
def evaluate_terms(kernel, q, qd, t, u, buf):
    """Q = u - (C q̇ + g) into buf[0:n], the constraint rows (Φ, A, γ, Φ_t), M, then the scratch:
    the time functions' values (the Python ones written by the caller), their stack and the work
    (module docstring; layout of :class:`~cmbs.model.model.Terms`).  Its arguments are borrowed
    (:func:`cmbs.jit.borrow`)."""
    kernel, q, qd, u, buf = borrow((kernel, q, qd, u, buf))
    parent, order, kind, placement, axis = kernel.parent, kernel.order, kernel.kind, kernel.placement, kernel.axis
    inertia, gravity = kernel.inertia, kernel.gravity
    n = parent.shape[0]
    m = kernel.sizes[0]
    ntf = kernel.tf_table.shape[0]
    depth = kernel.sizes[1]
    o_M = n + m * (n + 3)
    s0 = o_M + n * n
    w0 = s0 + 3 * ntf + 3 * depth
    if buf.shape[0] != w0 + WORK * n:
        raise ValueError("terms workspace does not belong to this model (use model.new_terms())")
    if q.shape[0] != n or qd.shape[0] != n or u.shape[0] != n:
        raise ValueError("q, qd or u has the wrong size for this model")
    if ntf > 0:
        evaluate_time_functions(kernel.tf_table, kernel.tf_ops, kernel.tf_reals, t,
                                buf[s0 + 3 * ntf:w0].reshape((depth, 3)), buf[s0:s0 + 3 * ntf].reshape((ntf, 3)))
    W = buf
    for idx in range(n):
        k = order[idx]
        _pose(parent, kind, placement, axis, q, k, W, w0)
        _body_inertia(inertia, k, W, w0)
        base = w0 + WORK * k
        p = parent[k]
        s, v, a = base + _S, base + _V, base + _A
        for i in range(6):
            if p >= 0:
                W[v + i] = W[w0 + WORK * p + _V + i] + W[s + i] * qd[k]
                W[a + i] = W[w0 + WORK * p + _A + i]
            else:
                W[v + i] = W[s + i] * qd[k]
                W[a + i] = 0.0 if i < 3 else -gravity[i - 3]
        # a += v ×ₘ (S q̇): (ω × sω, ω × sv + v_O × sω)
        wx, wy, wz, vx, vy, vz = W[v], W[v + 1], W[v + 2], W[v + 3], W[v + 4], W[v + 5]
        sx, sy, sz = W[s] * qd[k], W[s + 1] * qd[k], W[s + 2] * qd[k]
        tx, ty, tz = W[s + 3] * qd[k], W[s + 4] * qd[k], W[s + 5] * qd[k]
        W[a] += wy * sz - wz * sy
        W[a + 1] += wz * sx - wx * sz
        W[a + 2] += wx * sy - wy * sx
        W[a + 3] += wy * tz - wz * ty + vy * sz - vz * sy
        W[a + 4] += wz * tx - wx * tz + vz * sx - vx * sz
        W[a + 5] += wx * ty - wy * tx + vx * sy - vy * sx
        # f = I a + v ×_f (I v), v ×_f (n, f) = (ω × n + v_O × f, ω × f)
        w = base + _I
        n0, n1, n2, f0, f1, f2 = _inertia_times(W, w, W[a], W[a + 1], W[a + 2], W[a + 3], W[a + 4], W[a + 5])
        m0, m1, m2, g0, g1, g2 = _inertia_times(W, w, wx, wy, wz, vx, vy, vz)
        f = base + _F
        W[f] = n0 + wy * m2 - wz * m1 + vy * g2 - vz * g1
        W[f + 1] = n1 + wz * m0 - wx * m2 + vz * g0 - vx * g2
        W[f + 2] = n2 + wx * m1 - wy * m0 + vx * g1 - vy * g0
        W[f + 3] = f0 + wy * g2 - wz * g1
        W[f + 4] = f1 + wz * g0 - wx * g2
        W[f + 5] = f2 + wx * g1 - wy * g0
    _apply_loads(kernel.load_ints, kernel.load_reals, buf[s0:s0 + 3 * ntf].reshape((ntf, 3)), W, w0)
    _apply_point_springs(kernel.point_springs, kernel.point_spring_reals, gravity, W, w0)
    for i in range(n * n):
        buf[o_M + i] = 0.0
    for idx in range(n - 1, -1, -1):
        k = order[idx]
        base = w0 + WORK * k
        s, f, w = base + _S, base + _F, base + _I
        bias = 0.0
        for i in range(6):
            bias += W[s + i] * W[f + i]
        buf[k] = u[k] - bias
        # F = I^c_k S_k, then M_jk = S_jᵀ F along the path to the ground
        F0, F1, F2, F3, F4, F5 = _inertia_times(W, w, W[s], W[s + 1], W[s + 2], W[s + 3], W[s + 4], W[s + 5])
        j = k
        while j >= 0:
            sj = w0 + WORK * j + _S
            value = W[sj] * F0 + W[sj + 1] * F1 + W[sj + 2] * F2 + W[sj + 3] * F3 + W[sj + 4] * F4 + W[sj + 5] * F5
            buf[o_M + j * n + k] = value
            buf[o_M + k * n + j] = value
            j = parent[j]
        p = parent[k]
        if p >= 0:
            pbase = w0 + WORK * p
            for i in range(6):
                W[pbase + _F + i] += W[f + i]
            for i in range(10):
                W[pbase + _I + i] += W[w + i]
    springs, spring_reals = kernel.springs, kernel.spring_reals
    for e in range(springs.shape[0]):
        c = springs[e]
        buf[c] -= spring_reals[e, 0] * (q[c] - spring_reals[e, 1]) + spring_reals[e, 2] * qd[c]
    if m > 0:
        _constraint_rows(kernel, q, n, m, s0, w0, buf)


@njit(cache=True, inline="always")
def _apply_loads(ints, reals, values, W, w0):
    """Subtracts each applied load's spatial force about the world origin, ``(p × F, F)`` or
    ``(M, 0)``, from its body's f (module docstring), the components at t in ``values`` (k, 3)."""
    for e in range(ints.shape[0]):
        kind, body, frame, f0 = ints[e, 0], ints[e, 1], ints[e, 2], ints[e, 3]
        cx, cy, cz = values[f0, 0], values[f0 + 1, 0], values[f0 + 2, 0]
        if frame == FRAME_LINK:
            # into the body's axes by E, then into the world's by R_k
            bx = reals[e, 3] * cx + reals[e, 4] * cy + reals[e, 5] * cz
            by = reals[e, 6] * cx + reals[e, 7] * cy + reals[e, 8] * cz
            bz = reals[e, 9] * cx + reals[e, 10] * cy + reals[e, 11] * cz
            cx, cy, cz, _, _, _, _, _, _ = _vector_motion(body, bx, by, bz, W, w0)
        if kind == LOAD_FORCE:
            px, py, pz = _point_position(body, reals[e, 0], reals[e, 1], reals[e, 2], W, w0)
            _apply_force(body, px, py, pz, cx, cy, cz, W, w0)
        else:
            f = w0 + WORK * body + _F
            W[f], W[f + 1], W[f + 2] = W[f] - cx, W[f + 1] - cy, W[f + 2] - cz


@njit(cache=True, inline="always")
def _apply_point_springs(ints, reals, gravity, W, w0):
    """Subtracts each point spring-damper's two forces, ``-f u`` at p_a and ``f u`` at p_b as
    spatial forces about the world origin, from its bodies' f (module docstring; nothing for the
    ground and nothing at ℓ = 0)."""
    for e in range(ints.shape[0]):
        ba, bb = ints[e, 0], ints[e, 1]
        ax, ay, az, vax, vay, vaz, _, _, _ = _point_motion(ba, reals[e, 0], reals[e, 1], reals[e, 2], gravity, W, w0)
        bx, by, bz, vbx, vby, vbz, _, _, _ = _point_motion(bb, reals[e, 3], reals[e, 4], reals[e, 5], gravity, W, w0)
        length, ux, uy, uz = _length_direction(ax - bx, ay - by, az - bz)
        if length == 0.0:
            continue
        tension = reals[e, 6] * (length - reals[e, 8]) + reals[e, 7] * (ux * (vax - vbx) + uy * (vay - vby)
                                                                         + uz * (vaz - vbz))
        fx, fy, fz = tension * ux, tension * uy, tension * uz
        _apply_force(ba, ax, ay, az, -fx, -fy, -fz, W, w0)
        _apply_force(bb, bx, by, bz, fx, fy, fz, W, w0)


@njit(cache=True, inline="always")
def _apply_force(body, px, py, pz, fx, fy, fz, W, w0):
    """Subtracts the force F at the world point p, the spatial force ``(p × F, F)`` about the
    world origin, from ``body``'s f (nothing for the ground, -1)."""
    if body < 0:
        return
    f = w0 + WORK * body + _F
    nx, ny, nz = _cross(px, py, pz, fx, fy, fz)
    W[f], W[f + 1], W[f + 2] = W[f] - nx, W[f + 1] - ny, W[f + 2] - nz
    W[f + 3], W[f + 4], W[f + 5] = W[f + 3] - fx, W[f + 4] - fy, W[f + 5] - fz


@njit(cache=True, inline="always")
def _length_direction(dx, dy, dz):
    """(ℓ, u) of d: ℓ = |d| and u = d / ℓ, both computed scaled by d's largest component (no
    underflow of a tiny ℓ); (0, 0) when d = 0."""
    scale = max(abs(dx), abs(dy), abs(dz))
    if scale == 0.0:
        return 0.0, 0.0, 0.0, 0.0
    sx, sy, sz = dx / scale, dy / scale, dz / scale
    norm = math.sqrt(sx * sx + sy * sy + sz * sz)
    return scale * norm, sx / norm, sy / norm, sz / norm


@njit(cache=True, inline="always")
def _point_position(body, lx, ly, lz, W, w0):
    """World position of the point with local coordinates l on ``body`` (-1: the ground, l is
    then the position)."""
    if body < 0:
        return lx, ly, lz
    base = w0 + WORK * body
    R = base + _R
    return (W[base + _O] + W[R] * lx + W[R + 1] * ly + W[R + 2] * lz,
            W[base + _O + 1] + W[R + 3] * lx + W[R + 4] * ly + W[R + 5] * lz,
            W[base + _O + 2] + W[R + 6] * lx + W[R + 7] * ly + W[R + 8] * lz)


@njit(cache=True, inline="always")
def _point_motion(body, lx, ly, lz, gravity, W, w0):
    """World position p, velocity ṗ and bias acceleration J̇ q̇ (q̈ = 0) of the point with local
    coordinates l on ``body`` (-1: the ground; module docstring)."""
    if body < 0:
        return lx, ly, lz, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    base = w0 + WORK * body
    v, a = base + _V, base + _A
    px, py, pz = _point_position(body, lx, ly, lz, W, w0)
    wx, wy, wz = W[v], W[v + 1], W[v + 2]
    vx = W[v + 3] + wy * pz - wz * py
    vy = W[v + 4] + wz * px - wx * pz
    vz = W[v + 5] + wx * py - wy * px
    ax, ay, az = W[a], W[a + 1], W[a + 2]
    bx = W[a + 3] + gravity[0] + ay * pz - az * py + wy * vz - wz * vy
    by = W[a + 4] + gravity[1] + az * px - ax * pz + wz * vx - wx * vz
    bz = W[a + 5] + gravity[2] + ax * py - ay * px + wx * vy - wy * vx
    return px, py, pz, vx, vy, vz, bx, by, bz


@njit(cache=True, inline="always")
def _vector_motion(body, ux, uy, uz, W, w0):
    """World vector u = R ū of ``body``, its angular velocity ω and bias angular acceleration α
    (all zero for the ground)."""
    if body < 0:
        return ux, uy, uz, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    base = w0 + WORK * body
    R, v, a = base + _R, base + _V, base + _A
    wx = W[R] * ux + W[R + 1] * uy + W[R + 2] * uz
    wy = W[R + 3] * ux + W[R + 4] * uy + W[R + 5] * uz
    wz = W[R + 6] * ux + W[R + 7] * uy + W[R + 8] * uz
    return wx, wy, wz, W[v], W[v + 1], W[v + 2], W[a], W[a + 1], W[a + 2]


@njit(cache=True, inline="always")
def _cross(ax, ay, az, bx, by, bz):
    """a × b."""
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@njit(cache=True, inline="always")
def _target_frame(values, f0, column):
    """Column ``column`` of a pose driver's target rotation ``Rz(ψ) Ry(θ) Rx(φ)`` (URDF's rpy: roll
    φ, pitch θ, yaw ψ), its angular velocity ω and acceleration α (world axes), from the values
    ``(f, f', f'')`` of φ, θ, ψ in rows f0, f0 + 1, f0 + 2 of ``values``.  With the axes of the
    fixed-axis sequence z, y' = Rz(ψ) y and x'' = Rz(ψ) Ry(θ) x, ``ω = ψ' z + θ' y' + φ' x''`` and,
    as z' = 0, (y')' = ψ' z × y' and (x'')' = (ψ' z + θ' y') × x'',
    ``α = ψ'' z + θ'' y' + θ' ψ' (z × y') + φ'' x'' + φ' (ψ' z + θ' y') × x''``."""
    roll, dr, ddr = values[f0, 0], values[f0, 1], values[f0, 2]
    pitch, dp, ddp = values[f0 + 1, 0], values[f0 + 1, 1], values[f0 + 1, 2]
    yaw, dy, ddy = values[f0 + 2, 0], values[f0 + 2, 1], values[f0 + 2, 2]
    cr, sr, cp, sp, cy, sy = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), \
        math.sin(yaw)
    if column == 0:
        vx, vy, vz = cy * cp, sy * cp, -sp
    elif column == 1:
        vx, vy, vz = cy * sp * sr - sy * cr, sy * sp * sr + cy * cr, cp * sr
    else:
        vx, vy, vz = cy * sp * cr + sy * sr, sy * sp * cr - cy * sr, cp * cr
    yx, yy = -sy, cy                       # y' (z component 0)
    xx, xy, xz = cy * cp, sy * cp, -sp     # x''
    wx, wy, wz = dp * yx + dr * xx, dp * yy + dr * xy, dy + dr * xz
    # ω without the roll rate, which turns x''
    ox, oy, oz = dp * yx, dp * yy, dy
    tx, ty, tz = _cross(ox, oy, oz, xx, xy, xz)
    ax = ddp * yx + dp * dy * (-cy) + ddr * xx + dr * tx
    ay = ddp * yy + dp * dy * (-sy) + ddr * xy + dr * ty
    az = ddy + ddr * xz + dr * tz
    return vx, vy, vz, wx, wy, wz, ax, ay, az


@njit(cache=True, inline="always")
def _add_point_columns(parent, body, sign, px, py, pz, buf, row, n, W, w0):
    """Adds ``sign`` times the linear Jacobian of the point p on ``body`` to rows row..row+2 of A
    (row-major from buf index ``row``): column j is S_j,lin + S_j,ang × p along the path."""
    j = body
    while j >= 0:
        s = w0 + WORK * j + _S
        sx, sy, sz = W[s], W[s + 1], W[s + 2]
        buf[row + j] += sign * (W[s + 3] + sy * pz - sz * py)
        buf[row + n + j] += sign * (W[s + 4] + sz * px - sx * pz)
        buf[row + 2 * n + j] += sign * (W[s + 5] + sx * py - sy * px)
        j = parent[j]


@njit(cache=True, inline="always")
def _add_angular_columns(parent, body, sign, cx, cy, cz, buf, row, W, w0):
    """Adds ``sign`` times c·S_j,ang to the entries j of A's row at buf index ``row`` along the path."""
    j = body
    while j >= 0:
        s = w0 + WORK * j + _S
        buf[row + j] += sign * (cx * W[s] + cy * W[s + 1] + cz * W[s + 2])
        j = parent[j]


@njit(cache=True, inline="always")
def _add_directed_columns(parent, body, sign, px, py, pz, cx, cy, cz, buf, row, W, w0):
    """Adds ``sign`` times c·(S_j,lin + S_j,ang × p) (the point p's velocity column along c) to the
    entries j of A's row at buf index ``row`` along the path."""
    j = body
    while j >= 0:
        s = w0 + WORK * j + _S
        sx, sy, sz = W[s], W[s + 1], W[s + 2]
        buf[row + j] += sign * (cx * (W[s + 3] + sy * pz - sz * py) + cy * (W[s + 4] + sz * px - sx * pz)
                                + cz * (W[s + 5] + sx * py - sy * px))
        j = parent[j]


@njit(cache=True, inline="always")
def _constraint_rows(kernel, q, n, m, s0, w0, buf):
    """Φ, A, γ, Φ_t of the constraint elements and the drivers (module docstring) from the
    poses, velocities and accelerations of the forward pass; the time functions' values are at
    buf[s0:] (k, 3)."""
    parent, gravity, ints, reals = kernel.parent, kernel.gravity, kernel.closure_ints, kernel.closure_reals
    ntf = kernel.tf_table.shape[0]
    values = buf[s0:s0 + 3 * ntf].reshape((ntf, 3))
    W = buf
    o_A = n + m
    o_gam = o_A + m * n
    o_pt = o_gam + m
    for i in range(m * n):
        buf[o_A + i] = 0.0
    for i in range(m):
        buf[o_pt + i] = 0.0
    row = 0
    for e in range(ints.shape[0]):
        kind, ba, bb = ints[e, 0], ints[e, 1], ints[e, 2]
        if kind == CLOSE_POINT or kind == TARGET_POINT:
            ax, ay, az, _, _, _, gax, gay, gaz = _point_motion(ba, reals[e, 0], reals[e, 1], reals[e, 2], gravity, W,
                                                               w0)
            if kind == CLOSE_POINT:
                bx, by, bz, _, _, _, gbx, gby, gbz = _point_motion(bb, reals[e, 3], reals[e, 4], reals[e, 5], gravity,
                                                                   W, w0)
                _add_point_columns(parent, bb, -1.0, bx, by, bz, buf, o_A + row * n, n, W, w0)
            else:
                # the target point p_t(t): Φ_t = -ṗ_t, its acceleration p̈_t in place of J̇_b q̇
                bx, by, bz = values[bb, 0], values[bb + 1, 0], values[bb + 2, 0]
                gbx, gby, gbz = values[bb, 2], values[bb + 1, 2], values[bb + 2, 2]
                buf[o_pt + row], buf[o_pt + row + 1], buf[o_pt + row + 2] = -values[bb, 1], -values[bb + 1, 1], \
                    -values[bb + 2, 1]
            buf[n + row], buf[n + row + 1], buf[n + row + 2] = ax - bx, ay - by, az - bz
            buf[o_gam + row], buf[o_gam + row + 1], buf[o_gam + row + 2] = gbx - gax, gby - gay, gbz - gaz
            _add_point_columns(parent, ba, 1.0, ax, ay, az, buf, o_A + row * n, n, W, w0)
            row += 3
        elif kind == JOINT_COUPLING:
            # ba mimics bb (coordinates): q_a - r q_b - o = 0, a linear row (γ = 0, Φ_t = 0)
            ratio = reals[e, 0]
            buf[n + row] = q[ba] - ratio * q[bb] - reals[e, 1]
            buf[o_A + row * n + ba] += 1.0
            buf[o_A + row * n + bb] -= ratio
            buf[o_gam + row] = 0.0
            row += 1
        elif kind == CLOSE_LINE:
            ax, ay, az, vax, vay, vaz, gax, gay, gaz = _point_motion(ba, reals[e, 0], reals[e, 1], reals[e, 2],
                                                                     gravity, W, w0)
            bx, by, bz, vbx, vby, vbz, gbx, gby, gbz = _point_motion(bb, reals[e, 3], reals[e, 4], reals[e, 5],
                                                                     gravity, W, w0)
            vx, vy, vz, wbx, wby, wbz, abx, aby, abz = _vector_motion(bb, reals[e, 6], reals[e, 7], reals[e, 8], W,
                                                                      w0)
            dx, dy, dz = ax - bx, ay - by, az - bz
            ex, ey, ez = _cross(vx, vy, vz, dx, dy, dz)                  # v × d
            wvx, wvy, wvz = _cross(wbx, wby, wbz, vx, vy, vz)            # ω_b × v = v̇
            wwx, wwy, wwz = _cross(wbx, wby, wbz, wvx, wvy, wvz)         # ω_b × (ω_b × v)
            buf[n + row] = dx * vx + dy * vy + dz * vz
            buf[o_gam + row] = -((gax - gbx) * vx + (gay - gby) * vy + (gaz - gbz) * vz
                                 + 2.0 * ((vax - vbx) * wvx + (vay - vby) * wvy + (vaz - vbz) * wvz)
                                 + ex * abx + ey * aby + ez * abz + dx * wwx + dy * wwy + dz * wwz)
            _add_directed_columns(parent, ba, 1.0, ax, ay, az, vx, vy, vz, buf, o_A + row * n, W, w0)
            _add_directed_columns(parent, bb, -1.0, bx, by, bz, vx, vy, vz, buf, o_A + row * n, W, w0)
            _add_angular_columns(parent, bb, 1.0, ex, ey, ez, buf, o_A + row * n, W, w0)
            row += 1
        else:
            ux, uy, uz, wax, way, waz, aax, aay, aaz = _vector_motion(ba, reals[e, 0], reals[e, 1], reals[e, 2], W, w0)
            if kind == CLOSE_DOT:
                vx, vy, vz, wbx, wby, wbz, abx, aby, abz = _vector_motion(bb, reals[e, 3], reals[e, 4], reals[e, 5], W,
                                                                          w0)
            else:
                vx, vy, vz, wbx, wby, wbz, abx, aby, abz = _target_frame(values, bb, ints[e, 3])
            cx, cy, cz = _cross(ux, uy, uz, vx, vy, vz)
            buf[n + row] = ux * vx + uy * vy + uz * vz
            # u̇ = ω_a × u, v̇ = ω_b × v; d/dt (u × v) = u̇ × v + u × v̇
            dux, duy, duz = _cross(wax, way, waz, ux, uy, uz)
            dvx, dvy, dvz = _cross(wbx, wby, wbz, vx, vy, vz)
            dcx = duy * vz - duz * vy + uy * dvz - uz * dvy
            dcy = duz * vx - dux * vz + uz * dvx - ux * dvz
            dcz = dux * vy - duy * vx + ux * dvy - uy * dvx
            buf[o_gam + row] = -(dcx * (wax - wbx) + dcy * (way - wby) + dcz * (waz - wbz)
                                 + cx * (aax - abx) + cy * (aay - aby) + cz * (aaz - abz))
            _add_angular_columns(parent, ba, 1.0, cx, cy, cz, buf, o_A + row * n, W, w0)
            if kind == CLOSE_DOT:
                _add_angular_columns(parent, bb, -1.0, cx, cy, cz, buf, o_A + row * n, W, w0)
            else:
                buf[o_pt + row] = -(cx * wbx + cy * wby + cz * wbz)
            row += 1
    drivers = kernel.drivers
    for d in range(drivers.shape[0]):
        c, f = drivers[d, 0], drivers[d, 1]
        buf[n + row] = q[c] - values[f, 0]
        buf[o_A + row * n + c] = 1.0
        buf[o_pt + row] = -values[f, 1]
        buf[o_gam + row] = values[f, 2]
        row += 1


@njit(cache=True, inline="always")
def _evaluate_robot(kernel, q, qd, t, u, buffer):
    """:func:`evaluate_terms` for a :class:`RobotKernel`."""
    evaluate_terms(kernel, q, qd, t, u, buffer)


RobotKernel.evaluate = staticmethod(_evaluate_robot)


@njit(cache=True)
def _energy_kernel(parent, order, kind, placement, axis, inertia, gravity, springs, spring_reals, point_springs,
                   point_spring_reals, q, qd):
    """(T, V): T = ½ Σ_k v_kᵀ I_k v_k (= ½ q̇ᵀ M q̇), V = -Σ_k m_k g·c_k (c_k the centre of mass)
    + Σ_joint springs ½ k (q_c - q_rest)² + Σ_point springs ½ k (ℓ - ℓ0)²."""
    n = parent.shape[0]
    W = np.zeros(WORK * n)
    kinetic = 0.0
    potential = 0.0
    for idx in range(n):
        k = order[idx]
        _pose(parent, kind, placement, axis, q, k, W, 0)
        _body_inertia(inertia, k, W, 0)
        base = WORK * k
        p = parent[k]
        for i in range(6):
            W[base + _V + i] = W[base + _S + i] * qd[k] + (W[WORK * p + _V + i] if p >= 0 else 0.0)
        v, w = base + _V, base + _I
        n0, n1, n2, f0, f1, f2 = _inertia_times(W, w, W[v], W[v + 1], W[v + 2], W[v + 3], W[v + 4], W[v + 5])
        kinetic += 0.5 * (W[v] * n0 + W[v + 1] * n1 + W[v + 2] * n2 + W[v + 3] * f0 + W[v + 4] * f1 + W[v + 5] * f2)
        potential -= gravity[0] * W[w + 1] + gravity[1] * W[w + 2] + gravity[2] * W[w + 3]
    for e in range(springs.shape[0]):
        stretch = q[springs[e]] - spring_reals[e, 1]
        potential += 0.5 * spring_reals[e, 0] * stretch * stretch
    for e in range(point_springs.shape[0]):
        reals = point_spring_reals[e]
        ax, ay, az = _point_position(point_springs[e, 0], reals[0], reals[1], reals[2], W, 0)
        bx, by, bz = _point_position(point_springs[e, 1], reals[3], reals[4], reals[5], W, 0)
        stretch = _length_direction(ax - bx, ay - by, az - bz)[0] - reals[8]
        potential += 0.5 * reals[6] * stretch * stretch
    return kinetic, potential


def energies(kernel: RobotKernel, q: np.ndarray, qd: np.ndarray) -> tuple[float, float]:
    """Kinetic and potential energy (T, V) of the tree and its springs at (q, q̇)
    (:func:`_energy_kernel`)."""
    kinetic, potential = _energy_kernel(kernel.parent, kernel.order, kernel.kind, kernel.placement, kernel.axis,
                                        kernel.inertia, kernel.gravity, kernel.springs, kernel.spring_reals,
                                        kernel.point_springs, kernel.point_spring_reals,
                                        np.ascontiguousarray(q, dtype=float),
                                        np.ascontiguousarray(qd, dtype=float))
    return float(kinetic), float(potential)


@njit(cache=True)
def _poses_kernel(parent, order, kind, placement, axis, q, R, o, S):
    """World rotation R (n, 3, 3), origin o (n, 3) and motion subspace S (n, 6) of every body."""
    n = parent.shape[0]
    W = np.zeros(WORK * n)
    for idx in range(n):
        k = order[idx]
        _pose(parent, kind, placement, axis, q, k, W, 0)
        for i in range(3):
            o[k, i] = W[WORK * k + _O + i]
            for j in range(3):
                R[k, i, j] = W[WORK * k + _R + 3 * i + j]
        for i in range(6):
            S[k, i] = W[WORK * k + _S + i]


def body_poses(kernel: RobotKernel, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(R, o, S): each body's world rotation (n, 3, 3), frame origin (n, 3) and motion subspace
    (n, 6) in world Plücker coordinates (module docstring) at ``q``."""
    n = kernel.parent.shape[0]
    R, o, S = np.zeros((n, 3, 3)), np.zeros((n, 3)), np.zeros((n, 6))
    _poses_kernel(kernel.parent, kernel.order, kernel.kind, kernel.placement, kernel.axis,
                  np.ascontiguousarray(q, dtype=float), R, o, S)
    return R, o, S


class BodyWork(NamedTuple):
    """What :func:`evaluate_terms` leaves per body in the terms' scratch, as arrays (views):
    world rotation R (n, 3, 3), frame origin o (n, 3), motion subspace S (n, 6), the sum over the
    body's subtree of the bias wrenches ``I a + v ×_f I v - f^ext`` (RNEA at q̈ = 0, base at -g,
    the spatial forces f^ext of the applied loads and the point springs; n, 6)
    and the composite inertia (m, h, Ī) of its subtree (n, 10), all in world Plücker coordinates
    (module docstring)."""

    R: np.ndarray
    o: np.ndarray
    S: np.ndarray
    bias_subtree: np.ndarray
    composite: np.ndarray


def body_work(kernel: RobotKernel, scratch: np.ndarray) -> BodyWork:
    """The per-body work of the last evaluation into a terms buffer whose scratch is ``scratch``
    (``terms.scratch`` after ``model.evaluate``)."""
    n = kernel.parent.shape[0]
    start = 3 * kernel.tf_table.shape[0] + 3 * int(kernel.sizes[1])
    work = scratch[start:start + WORK * n].reshape(n, WORK)
    return BodyWork(work[:, _R:_R + 9].reshape(n, 3, 3), work[:, _O:_O + 3], work[:, _S:_S + 6],
                    work[:, _F:_F + 6], work[:, _I:_I + 10])
