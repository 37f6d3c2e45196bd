"""Planar joint-coordinate models: serial chains and trees of links, closed by loop constraints.

Every link hangs from a parent link (or from the ground) by one joint with one coordinate
``q_k``:

- revolute:  ``θ_k = θ_p + α_k + q_k``,  ``O_k = O_p + R(θ_p) o_k``;
- prismatic: ``θ_k = θ_p + α_k``,        ``O_k = O_p + R(θ_p) o_k + q_k e_k``,

where ``p`` is the parent (ground: ``θ_p = 0``, ``O_p = 0``), ``o_k`` the joint location in the
parent frame, ``α_k`` a fixed angular offset, ``R(θ)`` the rotation by θ and
``e_k = (cos θ_k, sin θ_k)`` the link's x axis.  A point with local coordinates ``c`` on link k is
at ``r = O_k + R(θ_k) c``; the centre of mass ``G_k`` at ``c = com_k``, the link end at
``c = (L_k, 0)``.

Jacobians.  With ``S = [[0, -1], [1, 0]]`` (rotation by +90°) and ``j`` running over the joints
on the path from link k to the ground (k included), the column ``j`` of the 2×n Jacobian of a
point ``r`` on link k is ``S (r - O_j)`` for a revolute joint and ``e_j`` for a prismatic one;
the angular Jacobian ``ω_k`` (1×n) has a 1 in the revolute columns of that path.  The
velocity-product ("bias") acceleration ``J̇ q̇`` of the point, i.e. its acceleration when
``q̈ = 0``, follows the recursion (``θ̇`` the absolute angular velocities)::

    a_O,k = a_O,p - θ̇_p² R(θ_p) o_k + [prismatic] (2 q̇_k θ̇_k S e_k - q_k θ̇_k² e_k),
    J̇ q̇ (r) = a_O,k - θ̇_k² (r - O_k).

Equations (THEORY §1, ``M q̈ + Aᵀλ = Q``)::

    M = Σ_k m_k J_Gkᵀ J_Gk + I_k ω_kᵀ ω_k,
    Q = Σ_k m_k J_Gkᵀ (g - J̇_Gk q̇) + B u + Σ_springs -f (J_a - J_b)ᵀ e + Σ_forces J_Pᵀ F(t) + Σ_torques e_c T(t),
    closure row  (point a, point or ground b, direction n):
        Φ = n·(r_a - r_b),   A = n·(J_a - J_b),   γ = -n·(J̇_a q̇ - J̇_b q̇),   Φ_t = 0,
    driver row (coordinate c, time function f):
        Φ = q_c - f(t),      A = e_cᵀ,            γ = f''(t),                Φ_t = -f'(t),
    T = ½ q̇ᵀ M q̇,   V = -Σ_k m_k g·r_Gk + Σ_springs ½ k (ℓ - ℓ0)².

Force elements: a spring-damper between points a and b (on links, or fixed on the ground) with
``d = r_a - r_b``, ``ℓ = |d|``, ``e = d/ℓ``, ``ℓ̇ = e·(J_a - J_b) q̇`` has the tension
``f = k (ℓ - ℓ0) + c ℓ̇``, i.e. the force ``-f e`` on a and ``+f e`` on b; a point force F(t)
(ground frame, or the link frame: ``F = R(θ_k) F_local``) at P adds ``J_Pᵀ F``; a joint torque
T(t) adds ``T`` to its coordinate (a torque between a revolute joint's parent and child, a force
along a prismatic one).  Q = J_Pᵀ F is the exact virtual work of a force at P (δr_P = J_P δq),
and the spring's Q is ``-∂V/∂q`` with ``∂ℓ/∂q = eᵀ (J_a - J_b)``.
``- Σ m_k J_Gkᵀ J̇_Gk q̇`` is the exact Coriolis/centrifugal term (``ω̇`` has no velocity-product
part in the plane, since θ_k is linear in q).  All per-link and per-constraint work happens in
one compiled kernel (:func:`_evaluate_kernel`) reading index and parameter arrays precomputed by
:meth:`JointModelBuilder.build`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple, Sequence

from cmbs.jit import borrow, njit
import numpy as np

from cmbs.errors import ModelError, did_you_mean
from cmbs.model.drivers import TimeFunction, TimeFunctionPack, as_time_function, evaluate_time_functions, \
    is_constant
from cmbs.model.model import Model, Terms

__all__ = ["JointModelBuilder", "JointEquations", "JointLayout"]

REVOLUTE, PRISMATIC = 0, 1
_JOINT_TYPES = {"revolute": REVOLUTE, "prismatic": PRISMATIC}
_DIRECTIONS = {"x": ((1.0, 0.0),), "z": ((0.0, 1.0),), "xz": ((1.0, 0.0), (0.0, 1.0))}

# ------------------------------------------------------------------ parameter array layout
# Integer header ip[0:_HEADER]; the named slots hold sizes and offsets into ip (I_O*) or rp (R_O*).
(I_N, I_NR, I_ND, I_NU, I_NTF, I_NOPS, I_DEPTH, I_NP,
 I_OPARENT, I_OTYPE, I_OORDER, I_OCHAINSTART, I_OCHAIN, I_OCLOSURE, I_ODRIVER, I_OACT,
 I_OTAB, I_OOPS, I_OPOINT, R_OCLOSURE, R_OGAIN, R_OPOINT, R_OREALS, R_NREALS,
 I_NS, I_NF, I_NT, I_OSPRING, I_OFORCE, I_OTORQUE, R_OSPRING, R_OFORCE) = range(32)
_HEADER = 32
_LINK_REALS = 8          # per link in rp[2 + 8k:]: ox, oz, angle, comx, comz, mass, inertia, length
_CLOSURE_REALS = 6       # per closure row: a local (or ground) x, z; b local (or ground) x, z; nx, nz
_SPRING_REALS = 7        # per spring: a local (or ground) x, z; b local (or ground) x, z; k, c, rest length
_SPRING_INTS = 2         # per spring: links of a and b (-1: ground)
_FORCE_INTS = 4          # per point force: link, frame (0 ground, 1 link), functions of f_x and f_z
FRAMES = {"ground": 0, "link": 1}
_WORK_PER_LINK = 10      # work per link: θ, θ̇, (cos θ, sin θ), O (2), a_O (2), Jx, Jz (per chain position)


# ------------------------------------------------------------------ compiled kernels
# The kernels index one flat work array ``W`` through offsets instead of slicing it: in numba every
# array view costs ~20 ns (reference counting), more than the arithmetic of a small model.
# Work layout from offset ``wk`` (n links): θ [wk, wk+n), θ̇ [wk+n, wk+2n), (cos θ, sin θ) pairs
# [wk+2n, wk+4n), O pairs [wk+4n, wk+6n), a_O pairs [wk+6n, wk+8n), Jx, Jz [wk+8n, wk+10n).

@njit(cache=True, inline="always")
def _kinematics(ip, rp, q, qd, W, wk):
    """Absolute angles θ, rates θ̇, (cos θ, sin θ), frame origins O and their bias accelerations."""
    n = ip[I_N]
    o_th, o_w, o_cs, o_O, o_a = wk, wk + n, wk + 2 * n, wk + 4 * n, wk + 6 * n
    o_order, o_parent, o_type = ip[I_OORDER], ip[I_OPARENT], ip[I_OTYPE]
    for idx in range(n):
        k = ip[o_order + idx]
        p = ip[o_parent + k]
        base = 2 + _LINK_REALS * k
        ox, oz, angle = rp[base], rp[base + 1], rp[base + 2]
        if p >= 0:
            thp, wp, c, s = W[o_th + p], W[o_w + p], W[o_cs + 2 * p], W[o_cs + 2 * p + 1]
            opx, opz, apx, apz = W[o_O + 2 * p], W[o_O + 2 * p + 1], W[o_a + 2 * p], W[o_a + 2 * p + 1]
        else:
            thp, wp, c, s = 0.0, 0.0, 1.0, 0.0
            opx, opz, apx, apz = 0.0, 0.0, 0.0, 0.0
        rox = c * ox - s * oz
        roz = s * ox + c * oz
        ax = apx - wp * wp * rox
        az = apz - wp * wp * roz
        if ip[o_type + k] == REVOLUTE:
            tk = thp + angle + q[k]
            wk_ = wp + qd[k]
            ex, ez = math.cos(tk), math.sin(tk)
            Ox, Oz = opx + rox, opz + roz
        else:
            tk = thp + angle
            wk_ = wp
            ex, ez = math.cos(tk), math.sin(tk)
            Ox, Oz = opx + rox + q[k] * ex, opz + roz + q[k] * ez
            ax += -2.0 * qd[k] * wp * ez - q[k] * wp * wp * ex
            az += 2.0 * qd[k] * wp * ex - q[k] * wp * wp * ez
        W[o_th + k] = tk
        W[o_w + k] = wk_
        W[o_cs + 2 * k] = ex
        W[o_cs + 2 * k + 1] = ez
        W[o_O + 2 * k] = Ox
        W[o_O + 2 * k + 1] = Oz
        W[o_a + 2 * k] = ax
        W[o_a + 2 * k + 1] = az


@njit(cache=True, inline="always")
def _column(ip, j, px, pz, W, wk):
    """Column j of the Jacobians of point (px, pz) and of the link angle, for joint j on its path."""
    n = ip[I_N]
    if ip[ip[I_OTYPE] + j] == REVOLUTE:
        o_O = wk + 4 * n + 2 * j
        return -(pz - W[o_O + 1]), px - W[o_O], 1.0
    o_cs = wk + 2 * n + 2 * j
    return W[o_cs], W[o_cs + 1], 0.0


@njit(cache=True, inline="always")
def _point(ip, link, lx, lz, W, wk):
    """Position and bias acceleration of a point with local (lx, lz) on ``link`` (-1: ground)."""
    if link < 0:
        return lx, lz, 0.0, 0.0
    n = ip[I_N]
    c, s = W[wk + 2 * n + 2 * link], W[wk + 2 * n + 2 * link + 1]
    rx = c * lx - s * lz
    rz = s * lx + c * lz
    w2 = W[wk + n + link] * W[wk + n + link]
    o_O, o_a = wk + 4 * n + 2 * link, wk + 6 * n + 2 * link
    return W[o_O] + rx, W[o_O + 1] + rz, W[o_a] - w2 * rx, W[o_a + 1] - w2 * rz


@njit(cache=True, inline="always")
def _point_velocity(ip, link, px, pz, qd, W, wk):
    """Velocity J_P q̇ of the point (px, pz) on ``link`` (-1: ground, at rest)."""
    vx, vz = 0.0, 0.0
    if link < 0:
        return vx, vz
    o_cs, o_chain = ip[I_OCHAINSTART], ip[I_OCHAIN]
    for i in range(ip[o_cs + link], ip[o_cs + link + 1]):
        j = ip[o_chain + i]
        cx, cz, cw = _column(ip, j, px, pz, W, wk)
        vx += cx * qd[j]
        vz += cz * qd[j]
    return vx, vz


@njit(cache=True, inline="always")
def _add_point_force(ip, link, px, pz, fx, fz, Q, W, wk):
    """Q += J_Pᵀ F for the force (fx, fz) at the point (px, pz) on ``link`` (-1: ground, no work)."""
    if link < 0:
        return
    o_cs, o_chain = ip[I_OCHAINSTART], ip[I_OCHAIN]
    for i in range(ip[o_cs + link], ip[o_cs + link + 1]):
        j = ip[o_chain + i]
        cx, cz, cw = _column(ip, j, px, pz, W, wk)
        Q[j] += cx * fx + cz * fz


@njit(cache=True, inline="always")
def _spring_geometry(ip, rp, e, W, wk):
    """Ends a, b (position x, z and link) and stretch ℓ - ℓ0 of spring ``e``, with e = (r_a - r_b)/ℓ."""
    o_sp, base = ip[I_OSPRING] + _SPRING_INTS * e, ip[R_OSPRING] + _SPRING_REALS * e
    la, lb = ip[o_sp], ip[o_sp + 1]
    pax, paz, bax, baz = _point(ip, la, rp[base], rp[base + 1], W, wk)
    pbx, pbz, bbx, bbz = _point(ip, lb, rp[base + 2], rp[base + 3], W, wk)
    dx, dz = pax - pbx, paz - pbz
    length = math.sqrt(dx * dx + dz * dz)
    return la, pax, paz, lb, pbx, pbz, dx / length, dz / length, length - rp[base + 6]


@njit(cache=True, inline="always")
def _spring_force(ip, rp, e, qd, W, wk):
    """Ends of spring ``e`` (link and position of a, of b) and the force (fx, fz) = -f e it
    applies to a (b takes the opposite), f = k (ℓ - ℓ0) + c ℓ̇."""
    la, pax, paz, lb, pbx, pbz, ex, ez, stretch = _spring_geometry(ip, rp, e, W, wk)
    base = ip[R_OSPRING] + _SPRING_REALS * e
    vax, vaz = _point_velocity(ip, la, pax, paz, qd, W, wk)
    vbx, vbz = _point_velocity(ip, lb, pbx, pbz, qd, W, wk)
    tension = rp[base + 4] * stretch + rp[base + 5] * (ex * (vax - vbx) + ez * (vaz - vbz))
    return la, pax, paz, lb, pbx, pbz, -tension * ex, -tension * ez


@njit(cache=True, inline="always")
def _applied_force(ip, rp, f, tfv, s0, W, wk):
    """Link, point (x, z) and force (fx, fz) in the ground frame of point force ``f``; the
    time-function values (f, f', f'') of function i are at tfv[s0 + 3 i:]."""
    o_f, n = ip[I_OFORCE] + _FORCE_INTS * f, ip[I_N]
    link, frame = ip[o_f], ip[o_f + 1]
    fx, fz = tfv[s0 + 3 * ip[o_f + 2]], tfv[s0 + 3 * ip[o_f + 3]]
    if frame == 1:
        c, s = W[wk + 2 * n + 2 * link], W[wk + 2 * n + 2 * link + 1]
        fx, fz = c * fx - s * fz, s * fx + c * fz
    r_f = ip[R_OFORCE] + 2 * f
    px, pz, bx, bz = _point(ip, link, rp[r_f], rp[r_f + 1], W, wk)
    return link, px, pz, fx, fz


@njit(cache=True, inline="always")
def _loads(ip, rp, qd, buf, s0, W, wk):
    """Add the force elements to Q = buf[0:n] (module docstring): springs and dampers, point
    forces and joint torques; the time-function values (f, f', f'') of function f are at buf[s0 + 3 f:]."""
    for e in range(ip[I_NS]):
        la, pax, paz, lb, pbx, pbz, fx, fz = _spring_force(ip, rp, e, qd, W, wk)
        _add_point_force(ip, la, pax, paz, fx, fz, buf, W, wk)
        _add_point_force(ip, lb, pbx, pbz, -fx, -fz, buf, W, wk)
    for f in range(ip[I_NF]):
        link, px, pz, fx, fz = _applied_force(ip, rp, f, buf, s0, W, wk)
        _add_point_force(ip, link, px, pz, fx, fz, buf, W, wk)
    o_t = ip[I_OTORQUE]
    for k in range(ip[I_NT]):
        buf[ip[o_t + 2 * k]] += buf[s0 + 3 * ip[o_t + 2 * k + 1]]


@njit(cache=True)
def _evaluate_kernel(ip, rp, q, qd, t, u, buf):
    """Fill a :class:`~cmbs.model.model.Terms` buffer: Q, Φ, A, γ, Φ_t, M, then the scratch.

    Scratch: time-function values (k, 3) [Python ones already written by the caller], the
    expression stack (depth, 3), then the work arrays (see :func:`_kinematics`).  It borrows its
    arguments (:func:`cmbs.jit.borrow`): numba counts no reference for what it views or passes on.
    """
    ip, rp, q, qd, u, buf = borrow((ip, rp, q, qd, u, buf))
    n, nr, nd, nu, ntf = ip[I_N], ip[I_NR], ip[I_ND], ip[I_NU], ip[I_NTF]
    m = nr + nd
    o_phi = n
    o_A = n + m
    o_gam = o_A + m * n
    o_pt = o_gam + m
    o_M = o_pt + m
    s0 = o_M + n * n
    depth = ip[I_DEPTH]
    # sizes are checked here (free) rather than in Python: the kernel does not bounds-check
    if buf.shape[0] != s0 + 3 * ntf + 3 * depth + _WORK_PER_LINK * n:
        raise ValueError("terms workspace does not belong to this model (use model.new_terms())")
    if q.shape[0] != n or qd.shape[0] != n or u.shape[0] != nu:
        raise ValueError("q, qd or u has the wrong size for this model")
    if ntf > 0:
        nops = ip[I_NOPS]
        tfv = buf[s0:s0 + 3 * ntf].reshape((ntf, 3))
        stack = buf[s0 + 3 * ntf:s0 + 3 * ntf + 3 * depth].reshape((depth, 3))
        table = ip[ip[I_OTAB]:ip[I_OTAB] + 4 * ntf].reshape((ntf, 4))
        ops = ip[ip[I_OOPS]:ip[I_OOPS] + 2 * nops].reshape((nops, 2))
        reals = rp[ip[R_OREALS]:ip[R_OREALS] + ip[R_NREALS]]
        evaluate_time_functions(table, ops, reals, t, stack, tfv)
    wk = s0 + 3 * ntf + 3 * depth
    _kinematics(ip, rp, q, qd, buf, wk)
    o_jx, o_jz = wk + 8 * n, wk + 9 * n
    o_cs, o_chain, o_type = ip[I_OCHAINSTART], ip[I_OCHAIN], ip[I_OTYPE]
    gx, gz = rp[0], rp[1]
    for i in range(n):
        buf[i] = 0.0
    for i in range(n * n):
        buf[o_M + i] = 0.0
    # ---- mass matrix, gravity and velocity-product forces, link by link
    for k in range(n):
        base = 2 + _LINK_REALS * k
        mass, inertia = rp[base + 5], rp[base + 6]
        px, pz, bx, bz = _point(ip, k, rp[base + 3], rp[base + 4], buf, wk)
        fx = mass * (gx - bx)
        fz = mass * (gz - bz)
        c0, c1 = ip[o_cs + k], ip[o_cs + k + 1]
        for i in range(c0, c1):
            j = ip[o_chain + i]
            cx, cz, cw = _column(ip, j, px, pz, buf, wk)
            buf[o_jx + i - c0] = cx
            buf[o_jz + i - c0] = cz
            buf[j] += cx * fx + cz * fz
        for i in range(c0, c1):
            j1 = ip[o_chain + i]
            x1, z1 = buf[o_jx + i - c0], buf[o_jz + i - c0]
            w1 = inertia if ip[o_type + j1] == REVOLUTE else 0.0
            for i2 in range(i, c1):
                j2 = ip[o_chain + i2]
                w2 = 1.0 if ip[o_type + j2] == REVOLUTE else 0.0
                value = mass * (x1 * buf[o_jx + i2 - c0] + z1 * buf[o_jz + i2 - c0]) + w1 * w2
                buf[o_M + j1 * n + j2] += value
                if j1 != j2:
                    buf[o_M + j2 * n + j1] += value
    # ---- actuators: Q[c] += gain * u
    o_act, r_gain = ip[I_OACT], ip[R_OGAIN]
    for k in range(nu):
        buf[ip[o_act + k]] += rp[r_gain + k] * u[k]
    # ---- springs, dampers, point forces and joint torques
    _loads(ip, rp, qd, buf, s0, buf, wk)
    # ---- loop closures
    o_cl, r_cl = ip[I_OCLOSURE], ip[R_OCLOSURE]
    for r in range(nr):
        la, lb = ip[o_cl + 2 * r], ip[o_cl + 2 * r + 1]
        base = r_cl + _CLOSURE_REALS * r
        nx, nz = rp[base + 4], rp[base + 5]
        pax, paz, bax, baz = _point(ip, la, rp[base], rp[base + 1], buf, wk)
        pbx, pbz, bbx, bbz = _point(ip, lb, rp[base + 2], rp[base + 3], buf, wk)
        buf[o_phi + r] = nx * (pax - pbx) + nz * (paz - pbz)
        buf[o_gam + r] = -(nx * (bax - bbx) + nz * (baz - bbz))
        buf[o_pt + r] = 0.0
        row = o_A + r * n
        for j in range(n):
            buf[row + j] = 0.0
        if la >= 0:
            for i in range(ip[o_cs + la], ip[o_cs + la + 1]):
                j = ip[o_chain + i]
                cx, cz, cw = _column(ip, j, pax, paz, buf, wk)
                buf[row + j] += nx * cx + nz * cz
        if lb >= 0:
            for i in range(ip[o_cs + lb], ip[o_cs + lb + 1]):
                j = ip[o_chain + i]
                cx, cz, cw = _column(ip, j, pbx, pbz, buf, wk)
                buf[row + j] -= nx * cx + nz * cz
    # ---- drivers q_c - f(t) = 0; the values (f, f', f'') of function f are at buf[s0 + 3 f:]
    o_dr = ip[I_ODRIVER]
    for d in range(nd):
        r = nr + d
        c, f = ip[o_dr + 2 * d], ip[o_dr + 2 * d + 1]
        row = o_A + r * n
        for j in range(n):
            buf[row + j] = 0.0
        buf[row + c] = 1.0
        buf[o_phi + r] = q[c] - buf[s0 + 3 * f]
        buf[o_pt + r] = -buf[s0 + 3 * f + 1]
        buf[o_gam + r] = buf[s0 + 3 * f + 2]


@njit(cache=True)
def _point_kinematics_kernel(ip, rp, q, qd, link, lx, lz, work, J):
    """Position, bias acceleration J̇q̇ and Jacobian J (2, n) of the point (lx, lz) of ``link``."""
    _kinematics(ip, rp, q, qd, work, 0)
    px, pz, bx, bz = _point(ip, link, lx, lz, work, 0)
    for i in range(J.shape[1]):
        J[0, i] = 0.0
        J[1, i] = 0.0
    o_cs, o_chain = ip[I_OCHAINSTART], ip[I_OCHAIN]
    for i in range(ip[o_cs + link], ip[o_cs + link + 1]):
        j = ip[o_chain + i]
        cx, cz, cw = _column(ip, j, px, pz, work, 0)
        J[0, j] = cx
        J[1, j] = cz
    return px, pz, bx, bz


@njit(cache=True)
def _energy_kernel(ip, rp, q, qd):
    """(T, V): T = ½ Σ m_k |J_Gk q̇|² + I_k θ̇_k², V = -Σ m_k g·r_Gk + Σ_springs ½ k (ℓ - ℓ0)²."""
    n = ip[I_N]
    W = np.empty(_WORK_PER_LINK * n)
    _kinematics(ip, rp, q, qd, W, 0)
    o_cs, o_chain = ip[I_OCHAINSTART], ip[I_OCHAIN]
    kinetic = 0.0
    potential = 0.0
    for k in range(n):
        base = 2 + _LINK_REALS * k
        mass, inertia = rp[base + 5], rp[base + 6]
        px, pz, bx, bz = _point(ip, k, rp[base + 3], rp[base + 4], W, 0)
        vx = vz = 0.0
        for i in range(ip[o_cs + k], ip[o_cs + k + 1]):
            j = ip[o_chain + i]
            cx, cz, cw = _column(ip, j, px, pz, W, 0)
            vx += cx * qd[j]
            vz += cz * qd[j]
        kinetic += 0.5 * (mass * (vx * vx + vz * vz) + inertia * W[n + k] * W[n + k])
        potential -= mass * (rp[0] * px + rp[1] * pz)
    for e in range(ip[I_NS]):
        stretch = _spring_geometry(ip, rp, e, W, 0)[8]
        potential += 0.5 * rp[ip[R_OSPRING] + _SPRING_REALS * e + 4] * stretch * stretch
    return kinetic, potential


@njit(cache=True)
def _points_kernel(ip, rp, q):
    """(n_points, 2) positions of the drawable points (link index and local coordinates in ip/rp)."""
    n, npts = ip[I_N], ip[I_NP]
    W = np.empty(_WORK_PER_LINK * n)
    _kinematics(ip, rp, q, np.zeros(n), W, 0)
    out = np.empty((npts, 2))
    o_pt, r_pt = ip[I_OPOINT], ip[R_OPOINT]
    for k in range(npts):
        px, pz, bx, bz = _point(ip, ip[o_pt + k], rp[r_pt + 2 * k], rp[r_pt + 2 * k + 1], W, 0)
        out[k, 0] = px
        out[k, 1] = pz
    return out


@njit(cache=True)
def _point_loads_kernel(ip, rp, q, qd, tfv, links, points, forces):
    """The forces of the springs (two rows each: end a, end b) and point forces at (q, q̇) into
    ``links`` (-1: ground), ``points`` and ``forces`` (ground frame); function values in ``tfv``."""
    W = np.empty(_WORK_PER_LINK * ip[I_N])
    _kinematics(ip, rp, q, qd, W, 0)
    for e in range(ip[I_NS]):
        la, pax, paz, lb, pbx, pbz, fx, fz = _spring_force(ip, rp, e, qd, W, 0)
        links[2 * e], points[2 * e, 0], points[2 * e, 1], forces[2 * e, 0], forces[2 * e, 1] = la, pax, paz, fx, fz
        links[2 * e + 1], points[2 * e + 1, 0], points[2 * e + 1, 1] = lb, pbx, pbz
        forces[2 * e + 1, 0], forces[2 * e + 1, 1] = -fx, -fz
    for f in range(ip[I_NF]):
        row = 2 * ip[I_NS] + f
        links[row], points[row, 0], points[row, 1], forces[row, 0], forces[row, 1] = \
            _applied_force(ip, rp, f, tfv, 0, W, 0)


# ------------------------------------------------------------------ the evaluator
class JointEquations:
    """Evaluator of a joint-coordinate model (the :class:`~cmbs.model.model.ModelEquations` protocol).

    Holds the packed parameter arrays ``ip`` (int64) and ``rp`` (float64) built by
    :meth:`JointModelBuilder.build`; every :meth:`evaluate` is one compiled kernel call (plus a
    Python call per :class:`~cmbs.model.drivers.PythonFunction` driver, evaluated beforehand
    into the scratch rows the kernel reads).
    """

    __slots__ = ("ip", "rp", "n", "m", "scratch_size", "python", "time_functions", "steady_drivers",
                 "work_sources")

    def __init__(self, ip: np.ndarray, rp: np.ndarray, n: int, m: int, scratch_size: int,
                 time_functions: TimeFunctionPack, steady_drivers: frozenset[str] = frozenset(),
                 work_sources: tuple[str, ...] = ()):
        #: the drivers of a constant, which hold their coordinate and do no work
        self.steady_drivers = steady_drivers
        #: the dampers, point forces and joint torques, by name (:attr:`cmbs.model.model.Model.work_sources`)
        self.work_sources = work_sources
        self.ip = ip
        self.rp = rp
        self.n = n
        self.m = m
        self.scratch_size = scratch_size
        self.time_functions = time_functions
        #: the (index, function) pairs evaluated in Python before each kernel call
        self.python: tuple[tuple[int, TimeFunction], ...] = time_functions.python

    def new_terms(self) -> Terms:
        """A workspace sized for this model (scratch included)."""
        return Terms(self.n, self.m, scratch=self.scratch_size)

    def compiled_kernel(self) -> "JointKernel | None":
        """The model's data for the compiled loops, or None when a time function is a Python
        callable."""
        return None if self.python else JointKernel(self.ip, self.rp, np.zeros((0, 0)))

    def evaluate(self, q: np.ndarray, qd: np.ndarray, t: float, u: np.ndarray, terms: Terms) -> None:
        """Fill ``terms`` with M, Q, Φ, A, γ, Φ_t at (q, q̇, t, u) (see the module docstring)."""
        if self.python:
            scratch = terms.scratch
            for k, function in self.python:
                scratch[3 * k:3 * k + 3] = function(t)
        _evaluate_kernel(self.ip, self.rp, q, qd, t, u, terms.buffer)

    def kinetic_energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        """T = ½ q̇ᵀ M(q) q̇, summed link by link from the COM and angular velocities."""
        return float(_energy_kernel(self.ip, self.rp, q, qd)[0])

    def potential_energy(self, q: np.ndarray) -> float:
        """V = -Σ_k m_k g·r_Gk + Σ_springs ½ k (ℓ - ℓ0)²."""
        return float(_energy_kernel(self.ip, self.rp, q, np.zeros(self.n))[1])

    def point_loads(self, q: np.ndarray, qd: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The forces the springs, dampers and point forces apply at (q, q̇, t): per force its link
        (-1: the ground), point (x, z) and force (f_x, f_z) in the ground frame, two rows per spring
        (end a, then end b) then one per point force.  Their generalized force is Σ J_Pᵀ F, the
        part of Q :meth:`evaluate` adds for them (the joint torques act on their coordinates)."""
        rows = 2 * int(self.ip[I_NS]) + int(self.ip[I_NF])
        links, points, forces = np.zeros(rows, np.int64), np.zeros((rows, 2)), np.zeros((rows, 2))
        if rows:
            terms = self.new_terms()          # the kernel writes the time functions' values into its scratch
            self.evaluate(np.asarray(q, dtype=float), np.asarray(qd, dtype=float), t, np.zeros(int(self.ip[I_NU])),
                          terms)
            _point_loads_kernel(self.ip, self.rp, np.asarray(q, dtype=float), np.asarray(qd, dtype=float),
                                terms.scratch, links, points, forces)
        return links, points, forces

    def point_positions(self, q: np.ndarray) -> np.ndarray:
        """(n_points, 2): ``{link}.origin`` and ``{link}.end`` of every link, then the user points."""
        return _points_kernel(self.ip, self.rp, q)

    def point_kinematics(self, link: int, local: tuple[float, float], q: np.ndarray,
                         qd: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position r (2,), Jacobian J = ∂r/∂q (2, n) and bias acceleration J̇q̇ (2,) of the point
        at ``local`` (x, z in the link frame) of link number ``link``: the kinematics the model's
        loop closures use (module docstring)."""
        work = np.zeros(_WORK_PER_LINK * self.n)
        J = np.zeros((2, self.n))
        px, pz, bx, bz = _point_kinematics_kernel(self.ip, self.rp, np.asarray(q, dtype=float),
                                                  np.asarray(qd, dtype=float), link, float(local[0]),
                                                  float(local[1]), work, J)
        return np.array([px, pz]), J, np.array([bx, bz])

    def layout(self) -> "JointLayout":
        """The links, closures, drivers and actuators decoded from the packed arrays."""
        ip, rp, n = self.ip, self.rp, self.n
        links = np.asarray(rp[2:2 + _LINK_REALS * n]).reshape(n, _LINK_REALS)
        nr, nd, nu = int(ip[I_NR]), int(ip[I_ND]), int(ip[I_NU])
        closure_links = np.asarray(ip[ip[I_OCLOSURE]:ip[I_OCLOSURE] + 2 * nr]).reshape(nr, 2)
        closure_reals = np.asarray(rp[ip[R_OCLOSURE]:ip[R_OCLOSURE] + _CLOSURE_REALS * nr]).reshape(nr, _CLOSURE_REALS)
        drivers = np.asarray(ip[ip[I_ODRIVER]:ip[I_ODRIVER] + 2 * nd]).reshape(nd, 2)[:, 0]
        return JointLayout(
            gravity=np.asarray(rp[0:2]), parent=np.asarray(ip[ip[I_OPARENT]:ip[I_OPARENT] + n]),
            revolute=np.asarray(ip[ip[I_OTYPE]:ip[I_OTYPE] + n]) == REVOLUTE,
            order=np.asarray(ip[ip[I_OORDER]:ip[I_OORDER] + n]), origin=links[:, 0:2], angle=links[:, 2],
            com=links[:, 3:5], mass=links[:, 5], inertia=links[:, 6], closure_links=closure_links,
            closure_a=closure_reals[:, 0:2], closure_b=closure_reals[:, 2:4], closure_direction=closure_reals[:, 4:6],
            driver_coordinates=drivers, actuator_coordinates=np.asarray(ip[ip[I_OACT]:ip[I_OACT] + nu]),
            actuator_gains=np.asarray(rp[ip[R_OGAIN]:ip[R_OGAIN] + nu]),
            point_link=np.asarray(ip[ip[I_OPOINT]:ip[I_OPOINT] + ip[I_NP]]),
            point_local=np.asarray(rp[ip[R_OPOINT]:ip[R_OPOINT] + 2 * ip[I_NP]]).reshape(-1, 2))


@dataclass(frozen=True)
class JointLayout:
    """A joint-coordinate model in plain arrays (read-only views of its packed parameters).

    Per link k (model order): ``parent[k]`` (-1: ground), ``revolute[k]``, ``origin[k]`` (o_k in
    the parent frame), ``angle[k]`` (α_k), ``com[k]``, ``mass[k]``, ``inertia[k]`` (about G);
    ``order`` parents before children.  Per closure row r: the links of points a and b
    (-1: ground), their local coordinates (ground coordinates when the link is -1) and the
    ground-fixed direction n_r.  Driver rows follow the closure rows; ``driver_coordinates[d]``
    is the coordinate of driver d; actuator i adds ``actuator_gains[i] u_i`` to Q at
    ``actuator_coordinates[i]``.  Point p of ``model.point_names`` is at ``point_local[p]`` on link
    ``point_link[p]``.
    """

    gravity: np.ndarray
    parent: np.ndarray
    revolute: np.ndarray
    order: np.ndarray
    origin: np.ndarray
    angle: np.ndarray
    com: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    closure_links: np.ndarray
    closure_a: np.ndarray
    closure_b: np.ndarray
    closure_direction: np.ndarray
    driver_coordinates: np.ndarray
    actuator_coordinates: np.ndarray
    actuator_gains: np.ndarray
    point_link: np.ndarray
    point_local: np.ndarray


# ------------------------------------------------------------------ the builder
@dataclass(frozen=True)
class _Link:
    name: str
    parent: str | None
    joint: str
    coordinate: str
    origin: tuple[float, float]
    angle: float
    length: float
    mass: float
    com: tuple[float, float]
    inertia: float
    q0: float
    qd0: float


@dataclass(frozen=True)
class _Point:
    name: str
    link: str
    local: tuple[float, float]


@dataclass(frozen=True)
class _Closure:
    name: str
    point: str
    to: str | tuple[float, float]
    directions: tuple[tuple[float, float], ...]
    spec: object


@dataclass(frozen=True)
class _Driver:
    name: str
    coordinate: str
    function: TimeFunction


@dataclass(frozen=True)
class _Actuator:
    name: str
    coordinate: str
    gain: float


@dataclass(frozen=True)
class _Spring:
    name: str
    ends: tuple[str | tuple[float, float], str | tuple[float, float]]
    stiffness: float
    damping: float
    rest_length: float | None


@dataclass(frozen=True)
class _Force:
    name: str
    point: str
    fx: TimeFunction
    fz: TimeFunction
    frame: str


@dataclass(frozen=True)
class _Torque:
    name: str
    coordinate: str
    torque: TimeFunction


def _name(value: object, what: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise ModelError(f"{what} name must be a non-empty string, got {value!r}")
    return value


def _real(value: object, entry: str, label: str) -> float:
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ModelError(f"{label} must be a number, got {value!r}", entry=entry) from None
    if isinstance(value, bool) or not math.isfinite(number):
        raise ModelError(f"{label} must be a finite number, got {value!r}", entry=entry)
    return number


def _pair(value: object, entry: str, label: str) -> tuple[float, float]:
    try:
        items = list(value)  # type: ignore[call-overload]
    except TypeError:
        raise ModelError(f"{label} must be a pair (x, z), got {value!r}", entry=entry) from None
    if len(items) != 2:
        raise ModelError(f"{label} must be a pair (x, z), got {value!r}", entry=entry)
    return _real(items[0], entry, label), _real(items[1], entry, label)


class JointModelBuilder:
    """Build a planar :class:`~cmbs.model.model.Model` in joint coordinates.

    Add links (each with one revolute or prismatic joint to its parent or to the ground), named
    points on links, loop closures, drivers, actuators and force elements (springs and dampers,
    point forces, joint torques), then call :meth:`build`.  Links may
    be added in any order (a parent after its child is fine); names are resolved by
    :meth:`build`.  See the module docstring for the kinematics and the equations.

    Parameters
    ----------
    name
        Model name.
    gravity
        Gravitational acceleration (g_x, g_z) in m/s² (z up: default (0, -9.81)).
    description, source
        Passed to the model; ``source`` cites where the mechanism comes from.

    Examples
    --------
    Aghili's slider-crank (equal crank and rod l, rod end on the ground line z = 0)::

        b = JointModelBuilder("slider-crank")
        b.add_link("crank", parent=None, coordinate="theta1", length=l, mass=m, com=(l/2, 0),
                   inertia=m*l**2/12)
        b.add_link("rod", parent="crank", coordinate="theta2", origin=(l, 0), length=l, mass=m,
                   com=(l/2, 0), inertia=m*l**2/12)
        b.add_closure("slider", point="rod.end", to=(0.0, 0.0), directions="z")
        model = b.build()
    """

    def __init__(self, name: str, *, gravity: Sequence[float] = (0.0, -9.81), description: str = "",
                 source: str = ""):
        self.name = _name(name, "model")
        self.gravity = _pair(gravity, f"model {name!r}", "gravity")
        self.description = description
        self.source = source
        self._links: dict[str, _Link] = {}
        self._points: dict[str, _Point] = {}
        self._closures: dict[str, _Closure] = {}
        self._drivers: dict[str, _Driver] = {}
        self._actuators: dict[str, _Actuator] = {}
        self._springs: dict[str, _Spring] = {}
        self._forces: dict[str, _Force] = {}
        self._torques: dict[str, _Torque] = {}

    # -------------------------------------------------------------- definition
    def add_link(self, name: str, *, parent: str | None, joint: str = "revolute", coordinate: str,
                 origin: Sequence[float] = (0.0, 0.0), angle: float = 0.0, length: float, mass: float,
                 com: Sequence[float], inertia: float, q0: float = 0.0, qd0: float = 0.0) -> "JointModelBuilder":
        """Add a link joined to ``parent`` (``None``: the ground) by a one-coordinate joint.

        Parameters
        ----------
        name
            Link name (unique).  Its points ``f"{name}.origin"`` (the joint) and ``f"{name}.end"``
            (local ``(length, 0)``) are defined automatically.
        parent
            Name of the parent link, or ``None`` for the ground.
        joint
            ``"revolute"``: ``θ = θ_parent + angle + q``, ``O = O_parent + R(θ_parent)·origin``;
            ``"prismatic"``: ``θ = θ_parent + angle``, ``O = O_parent + R(θ_parent)·origin + q·(cos θ, sin θ)``.
        coordinate
            Name of the joint coordinate q (unique; a model coordinate of kind ``"joint"``).
        origin
            Joint location (x, z) in the parent frame (ground frame if ``parent`` is None), m.
        angle
            Fixed angular offset α of the link frame w.r.t. the parent frame, rad.
        length
            Link length L > 0 (the end point is at local (L, 0)), m.
        mass
            Mass m > 0, kg.
        com
            Centre of mass (along, across) in the link frame, m.
        inertia
            Moment of inertia about the centre of mass, I ≥ 0, kg m².
        q0, qd0
            Initial joint coordinate and rate.

        Returns
        -------
        JointModelBuilder
            ``self``, for chaining.
        """
        name = _name(name, "link")
        entry = f"link {name!r}"
        if name in self._links:
            raise ModelError("duplicate link name", entry=entry)
        if parent is not None:
            parent = _name(parent, "parent link")
        if joint not in _JOINT_TYPES:
            raise ModelError(f"joint must be 'revolute' or 'prismatic', got {joint!r}", entry=entry)
        coordinate = _name(coordinate, "coordinate")
        for other in self._links.values():
            if other.coordinate == coordinate:
                raise ModelError(f"duplicate coordinate name {coordinate!r} (already the coordinate of "
                                 f"link {other.name!r})", entry=entry)
        length = _real(length, entry, "length")
        mass = _real(mass, entry, "mass")
        inertia = _real(inertia, entry, "inertia")
        if length <= 0.0:
            raise ModelError(f"length must be > 0, got {length!r}", entry=entry)
        if mass <= 0.0:
            raise ModelError(f"mass must be > 0, got {mass!r}", entry=entry)
        if inertia < 0.0:
            raise ModelError(f"inertia must be >= 0, got {inertia!r}", entry=entry)
        self._links[name] = _Link(name, parent, joint, coordinate, _pair(origin, entry, "origin"),
                                  _real(angle, entry, "angle"), length, mass, _pair(com, entry, "com"),
                                  inertia, _real(q0, entry, "q0"), _real(qd0, entry, "qd0"))
        return self

    def add_point(self, name: str, *, link: str, local: Sequence[float]) -> "JointModelBuilder":
        """Add a named point fixed on ``link`` at local coordinates ``local = (ξ, η)`` (link frame), m."""
        name = _name(name, "point")
        entry = f"point {name!r}"
        if name in self._points:
            raise ModelError("duplicate point name", entry=entry)
        self._points[name] = _Point(name, _name(link, "link"), _pair(local, entry, "local"))
        return self

    def add_closure(self, name: str, *, point: str, to: str | Sequence[float],
                    directions: str | Sequence[float] = "xz") -> "JointModelBuilder":
        """Add a loop-closure constraint between ``point`` and ``to``.

        Parameters
        ----------
        name
            Constraint name; with ``directions="xz"`` the rows are ``f"{name}.x"`` and ``f"{name}.z"``.
        point
            A named point (user point, ``"{link}.origin"`` or ``"{link}.end"``).
        to
            Another named point, or a fixed ground position (x, z).
        directions
            Which components of ``r_point - r_to`` vanish: ``"xz"`` (both, a pin), ``"x"``, ``"z"``,
            or a vector ``(n_x, n_z)`` giving the one row ``n·(r_point - r_to) = 0``.
        """
        name = _name(name, "closure")
        entry = f"closure {name!r}"
        if name in self._closures:
            raise ModelError("duplicate closure name", entry=entry)
        point = _name(point, "point")
        target: str | tuple[float, float]
        target = _name(to, "point") if isinstance(to, str) else _pair(to, entry, "to")
        if target == point:
            raise ModelError(f"closure of point {point!r} to itself", entry=entry)
        if isinstance(directions, str):
            if directions not in _DIRECTIONS:
                raise ModelError(f"directions must be 'xz', 'x', 'z' or a vector (nx, nz), got {directions!r}",
                                 entry=entry)
            rows = _DIRECTIONS[directions]
        else:
            try:
                vector = _pair(directions, entry, "directions")
            except ModelError:
                raise ModelError(f"directions must be 'xz', 'x', 'z' or a vector (nx, nz), got {directions!r}",
                                 entry=entry) from None
            if vector == (0.0, 0.0):
                raise ModelError("directions vector must be nonzero", entry=entry)
            rows = (vector,)
        spec = directions if isinstance(directions, str) else rows[0]
        self._closures[name] = _Closure(name, point, target, rows, spec)
        return self

    def add_driver(self, coordinate: str, function: object, *, name: str | None = None) -> "JointModelBuilder":
        """Drive a joint coordinate: ``Φ = q_c - f(t) = 0`` (``Φ_t = -f'``, ``γ = f''``).

        ``function`` is anything :func:`cmbs.model.drivers.as_time_function` accepts (number,
        expression string, table, callable).  The constraint is named ``name`` or
        ``f"{coordinate}-driver"``.
        """
        coordinate = _name(coordinate, "coordinate")
        name = f"{coordinate}-driver" if name is None else _name(name, "driver")
        entry = f"driver {name!r}"
        if name in self._drivers:
            raise ModelError("duplicate driver name", entry=entry)
        for other in self._drivers.values():
            if other.coordinate == coordinate:
                raise ModelError(f"coordinate {coordinate!r} is already driven by {other.name!r}", entry=entry)
        try:
            time_function = as_time_function(function)
        except ModelError as error:
            raise error.located(entry=entry) from None
        self._drivers[name] = _Driver(name, coordinate, time_function)
        return self

    def add_actuator(self, name: str, *, coordinate: str, gain: float = 1.0) -> "JointModelBuilder":
        """Add an actuator input ``u_k`` acting on a joint coordinate: ``Q[coordinate] += gain·u_k``."""
        name = _name(name, "actuator")
        entry = f"actuator {name!r}"
        if name in self._actuators:
            raise ModelError("duplicate actuator name", entry=entry)
        self._actuators[name] = _Actuator(name, _name(coordinate, "coordinate"), _real(gain, entry, "gain"))
        return self

    def add_spring(self, name: str, i: str | Sequence[float], j: str | Sequence[float], *, stiffness: float,
                   damping: float = 0.0, rest_length: float | None = None) -> "JointModelBuilder":
        """Linear spring-damper between two points: tension ``f = k (ℓ - ℓ0) + c ℓ̇`` pulls them together.

        ``i`` and ``j`` are named points (user points, ``"{link}.origin"``, ``"{link}.end"``) or
        fixed ground positions (x, z); ``rest_length`` ℓ0 defaults to their distance at q0.  The
        spring's energy ½ k (ℓ - ℓ0)² is part of the model's potential energy; a damper (c > 0)
        is one of its :attr:`~cmbs.model.model.Model.work_sources`.
        """
        name = _name(name, "spring")
        entry = f"spring {name!r}"
        if name in self._springs:
            raise ModelError("duplicate spring name", entry=entry)
        ends = tuple(_name(end, "point") if isinstance(end, str) else _pair(end, entry, "end") for end in (i, j))
        if ends[0] == ends[1]:
            raise ModelError(f"both ends are {ends[0]!r}", entry=entry)
        if not any(isinstance(end, str) for end in ends):
            raise ModelError("both ends are on the ground: the spring would act on nothing", entry=entry)
        stiffness, damping = _real(stiffness, entry, "stiffness"), _real(damping, entry, "damping")
        if stiffness < 0.0 or damping < 0.0:
            raise ModelError(f"stiffness and damping must be >= 0, got {stiffness!r} and {damping!r}", entry=entry)
        if rest_length is not None:
            rest_length = _real(rest_length, entry, "rest_length")
            if rest_length < 0.0:
                raise ModelError(f"rest_length must be >= 0, got {rest_length!r}", entry=entry)
        self._springs[name] = _Spring(name, ends, stiffness, damping, rest_length)  # type: ignore[arg-type]
        return self

    def add_force(self, name: str, *, point: str, fx: object = 0.0, fz: object = 0.0,
                  frame: str = "ground") -> "JointModelBuilder":
        """A force (fx, fz) at a named point; each component anything
        :func:`cmbs.model.drivers.as_time_function` accepts (number, expression of t, table,
        callable).  ``frame`` ``"ground"``: components along the ground axes; ``"link"``: along the
        axes of the point's link (a follower force, turning with it).  Q gains ``J_Pᵀ F``."""
        name = _name(name, "force")
        entry = f"force {name!r}"
        if name in self._forces:
            raise ModelError("duplicate force name", entry=entry)
        if frame not in FRAMES:
            raise ModelError(f"frame must be 'ground' or 'link', got {frame!r}", entry=entry)
        try:
            components = as_time_function(fx), as_time_function(fz)
        except ModelError as error:
            raise error.located(entry=entry) from None
        self._forces[name] = _Force(name, _name(point, "point"), *components, frame)
        return self

    def add_torque(self, name: str, *, coordinate: str, torque: object) -> "JointModelBuilder":
        """A generalized force ``torque`` (number, expression of t, table, callable) on a joint
        coordinate: the torque between a revolute joint's parent and child (N m), or the force
        along a prismatic joint (N)."""
        name = _name(name, "torque")
        entry = f"torque {name!r}"
        if name in self._torques:
            raise ModelError("duplicate torque name", entry=entry)
        try:
            function = as_time_function(torque)
        except ModelError as error:
            raise error.located(entry=entry) from None
        self._torques[name] = _Torque(name, _name(coordinate, "coordinate"), function)
        return self

    # -------------------------------------------------------------- build
    def _topological_order(self, names: list[str]) -> list[int]:
        index = {name: k for k, name in enumerate(names)}
        order: list[int] = []
        state = [0] * len(names)  # 0 new, 1 on the current path, 2 done
        for start in range(len(names)):
            path = []
            k = start
            while state[k] == 0:
                state[k] = 1
                path.append(k)
                parent = self._links[names[k]].parent
                if parent is None:
                    break
                k = index[parent]
                if state[k] == 1:
                    raise ModelError(f"the parent chain closes on itself ({' -> '.join(names[j] for j in path)}"
                                     f" -> {names[k]}); use add_closure for loops",
                                     entry=f"link {names[path[-1]]!r}")
            order.extend(reversed(path))
            for j in path:
                state[j] = 2
        return order

    def _spring_arrays(self, point_of) -> tuple[list[tuple[int, int]], list[float]]:
        """Per spring the links of its ends (-1: ground) and its reals (ends, k, c, ℓ0; ℓ0 = 0
        until :meth:`_default_rest_lengths` when not given)."""
        ints: list[tuple[int, int]] = []
        reals: list[float] = []
        for spring in self._springs.values():
            entry = f"spring {spring.name!r}"
            ends = [point_of(end, entry) if isinstance(end, str) else (-1, end) for end in spring.ends]
            ints.append((ends[0][0], ends[1][0]))
            reals.extend((*ends[0][1], *ends[1][1], spring.stiffness, spring.damping,
                          0.0 if spring.rest_length is None else spring.rest_length))
        return ints, reals

    def _default_rest_lengths(self, ip: np.ndarray, rp: np.ndarray, q0: np.ndarray) -> None:
        """ℓ0 of the springs given none: their length at q0, written into ``rp``."""
        n = q0.size
        work, jacobian = np.zeros(_WORK_PER_LINK * n), np.zeros((2, n))

        def position(link: int, local: np.ndarray) -> np.ndarray:
            if link < 0:
                return local
            return np.array(_point_kinematics_kernel(ip, rp, q0, np.zeros(n), link, local[0], local[1], work,
                                                     jacobian)[:2])

        for e, spring in enumerate(self._springs.values()):
            links, base = ip[ip[I_OSPRING] + 2 * e:ip[I_OSPRING] + 2 * e + 2], ip[R_OSPRING] + _SPRING_REALS * e
            ends = [position(int(links[k]), rp[base + 2 * k:base + 2 * k + 2]) for k in range(2)]
            length = float(np.hypot(*(ends[0] - ends[1])))
            if length == 0.0:
                raise ModelError("its ends coincide at q0, where the spring has no direction: separate them",
                                 entry=f"spring {spring.name!r}")
            if spring.rest_length is None:
                rp[base + 6] = length

    def _work_sources(self) -> tuple[str, ...]:
        """The dampers, and the point forces and joint torques that are not constant zero."""
        def nonzero(function: TimeFunction) -> bool:
            return not (is_constant(function) and function.value == 0)

        return (tuple(f"force {f.name!r}" for f in self._forces.values() if nonzero(f.fx) or nonzero(f.fz))
                + tuple(f"torque {t.name!r}" for t in self._torques.values() if nonzero(t.torque))
                + tuple(f"damper {s.name!r}" for s in self._springs.values() if s.damping > 0))

    def build(self) -> Model:
        """Resolve names, pack the index and parameter arrays and return the frozen :class:`Model`.

        Raises
        ------
        ModelError
            Naming the entry: unknown parent, link, point or coordinate; duplicate point or
            constraint names; a loop in the parent chain; no links.
        """
        if not self._links:
            raise ModelError(f"model {self.name!r} has no links")
        names = list(self._links)
        link_index = {name: k for k, name in enumerate(names)}
        links = [self._links[name] for name in names]
        for link in links:
            if link.parent is not None and link.parent not in link_index:
                raise ModelError(f"unknown parent link {link.parent!r}; links: {', '.join(names)}",
                                 entry=f"link {link.name!r}")
        n = len(links)
        parent = np.array([-1 if link.parent is None else link_index[link.parent] for link in links], np.int64)
        order = self._topological_order(names)
        chains: list[list[int]] = []
        for k in range(n):
            chain = []
            j = k
            while j >= 0:
                chain.append(j)
                j = int(parent[j])
            chains.append(chain)
        chain_start = np.cumsum([0] + [len(chain) for chain in chains]).astype(np.int64)
        coordinate_names = tuple(link.coordinate for link in links)
        coordinate_index = {name: k for k, name in enumerate(coordinate_names)}

        def coordinate_of(name: str, entry: str) -> int:
            if name not in coordinate_index:
                raise ModelError(f"unknown coordinate {name!r}; coordinates: {', '.join(coordinate_names)}",
                                 entry=entry)
            return coordinate_index[name]

        # points: automatic origin/end of every link, then the user points
        point_names: list[str] = []
        point_links: list[int] = []
        point_locals: list[tuple[float, float]] = []
        for k, link in enumerate(links):
            point_names += [f"{link.name}.origin", f"{link.name}.end"]
            point_links += [k, k]
            point_locals += [(0.0, 0.0), (link.length, 0.0)]
        for point in self._points.values():
            entry = f"point {point.name!r}"
            if point.name in point_names:
                raise ModelError("duplicate point name (clashes with an automatic link point)", entry=entry)
            if point.link not in link_index:
                raise ModelError(f"unknown link {point.link!r}; links: {', '.join(names)}", entry=entry)
            point_names.append(point.name)
            point_links.append(link_index[point.link])
            point_locals.append(point.local)
        point_index = {name: k for k, name in enumerate(point_names)}

        def point_of(name: str, entry: str) -> tuple[int, tuple[float, float]]:
            if name not in point_index:
                raise ModelError(f"unknown point {name!r}{did_you_mean(name, point_names)}; points: "
                                 f"{', '.join(point_names)}", entry=entry)
            k = point_index[name]
            return point_links[k], point_locals[k]

        # constraints: closure rows, then drivers
        constraint_names: list[str] = []
        closure_ints: list[tuple[int, int]] = []
        closure_reals: list[float] = []
        for closure in self._closures.values():
            entry = f"closure {closure.name!r}"
            la, ca = point_of(closure.point, entry)
            if isinstance(closure.to, str):
                lb, cb = point_of(closure.to, entry)
            else:
                lb, cb = -1, closure.to
            rows = closure.directions
            suffixes = ("x", "z") if len(rows) == 2 else ("",)
            for direction, suffix in zip(rows, suffixes):
                constraint_names.append(f"{closure.name}.{suffix}" if suffix else closure.name)
                closure_ints.append((la, lb))
                closure_reals.extend((*ca, *cb, *direction))
        nr = len(closure_ints)
        driver_ints: list[tuple[int, int]] = []
        functions: list[TimeFunction] = []
        for driver in self._drivers.values():
            driver_ints.append((coordinate_of(driver.coordinate, f"driver {driver.name!r}"), len(functions)))
            functions.append(driver.function)
            constraint_names.append(driver.name)
        labels = [f"driver {name}" for name in constraint_names[nr:]]
        nd = len(driver_ints)
        spring_ints, spring_reals = self._spring_arrays(point_of)
        force_ints, force_reals = [], []
        for force in self._forces.values():
            link, local = point_of(force.point, f"force {force.name!r}")
            force_ints.append((link, FRAMES[force.frame], len(functions), len(functions) + 1))
            force_reals.extend(local)
            functions += [force.fx, force.fz]
            labels += [f"force {force.name} fx", f"force {force.name} fz"]
        torque_ints = []
        for torque in self._torques.values():
            torque_ints.append((coordinate_of(torque.coordinate, f"torque {torque.name!r}"), len(functions)))
            functions.append(torque.torque)
            labels.append(f"torque {torque.name}")
        seen: set[str] = set()
        for constraint in constraint_names:
            if constraint in seen:
                raise ModelError(f"duplicate constraint name {constraint!r} (closure rows and drivers share "
                                 "one namespace)", entry=f"model {self.name!r}")
            seen.add(constraint)
        actuators = list(self._actuators.values())
        actuator_coordinates = [coordinate_of(act.coordinate, f"actuator {act.name!r}") for act in actuators]
        pack = TimeFunctionPack.build(functions, labels)

        # ---- pack ints
        ip_parts: list[np.ndarray] = [np.zeros(_HEADER, np.int64)]
        offsets: dict[int, int] = {}

        def put(slot: int, values: object) -> None:
            offsets[slot] = sum(part.size for part in ip_parts)
            ip_parts.append(np.asarray(values, dtype=np.int64).ravel())

        put(I_OPARENT, parent)
        put(I_OTYPE, [_JOINT_TYPES[link.joint] for link in links])
        put(I_OORDER, order)
        put(I_OCHAINSTART, chain_start)
        put(I_OCHAIN, [j for chain in chains for j in chain])
        put(I_OCLOSURE, closure_ints)
        put(I_ODRIVER, driver_ints)
        put(I_OACT, actuator_coordinates)
        put(I_OTAB, pack.table)
        put(I_OOPS, pack.ops)
        put(I_OPOINT, point_links)
        put(I_OSPRING, spring_ints)
        put(I_OFORCE, force_ints)
        put(I_OTORQUE, torque_ints)
        ip = np.concatenate(ip_parts)
        for slot, offset in offsets.items():
            ip[slot] = offset
        # ---- pack reals
        link_reals = [(*link.origin, link.angle, *link.com, link.mass, link.inertia, link.length) for link in links]
        rp_parts = [np.array(self.gravity, float), np.array(link_reals, float).ravel(),
                    np.array(closure_reals, float), np.array([act.gain for act in actuators], float),
                    np.array(point_locals, float).ravel(), pack.reals, np.array(spring_reals, float).ravel(),
                    np.array(force_reals, float)]
        starts = np.cumsum([0] + [part.size for part in rp_parts])
        rp = np.concatenate(rp_parts)
        ip[I_N], ip[I_NR], ip[I_ND], ip[I_NU] = n, nr, nd, len(actuators)
        ip[I_NTF], ip[I_NOPS], ip[I_DEPTH], ip[I_NP] = pack.count, pack.ops.shape[0], pack.depth, len(point_names)
        ip[R_OCLOSURE], ip[R_OGAIN], ip[R_OPOINT], ip[R_OREALS] = starts[2], starts[3], starts[4], starts[5]
        ip[R_NREALS] = pack.reals.size
        ip[I_NS], ip[I_NF], ip[I_NT] = len(spring_ints), len(force_ints), len(torque_ints)
        ip[R_OSPRING], ip[R_OFORCE] = starts[6], starts[7]
        q0 = np.array([link.q0 for link in links], float)
        self._default_rest_lengths(ip, rp, q0)
        ip.setflags(write=False)
        rp.setflags(write=False)
        scratch = 3 * pack.count + 3 * pack.depth + _WORK_PER_LINK * n
        equations = JointEquations(ip, rp, n, nr + nd, scratch, pack,
                                   frozenset(d.name for d in self._drivers.values() if is_constant(d.function)),
                                   self._work_sources())

        parameters = {
            "builder": "joints",
            "gravity": self.gravity,
            "links": [dict(vars(link)) for link in links],
            "points": [dict(vars(point)) for point in self._points.values()],
            "closures": [{"name": c.name, "point": c.point, "to": c.to, "directions": c.spec}
                         for c in self._closures.values()],
            "drivers": [{"name": d.name, "coordinate": d.coordinate, "function": d.function}
                        for d in self._drivers.values()],
            "actuators": [dict(vars(act)) for act in actuators],
            "springs": [dict(vars(spring)) for spring in self._springs.values()],
            "forces": [dict(vars(force)) for force in self._forces.values()],
            "torques": [dict(vars(torque)) for torque in self._torques.values()],
        }
        return Model(
            name=self.name,
            coordinate_names=coordinate_names,
            coordinate_kinds=("joint",) * n,
            constraint_names=tuple(constraint_names),
            drivers=np.array([False] * nr + [True] * nd, dtype=bool),
            actuator_names=tuple(act.name for act in actuators),
            q0=q0,
            qd0=np.array([link.qd0 for link in links], float),
            point_names=tuple(point_names),
            lines=tuple((2 * k, 2 * k + 1) for k in range(n)),
            equations=equations,
            description=self.description,
            source=self.source,
            parameters=parameters,
            constant_mass=False,
            segment_masses=tuple((link.name, link.mass) for link in links),
        )


class JointKernel(NamedTuple):
    """A joint-coordinate model as the compiled loops take it (:mod:`cmbs.model.compiled`): its
    index and parameter arrays; ``mass`` is empty (M depends on q and is in the terms buffer)."""

    ints: np.ndarray
    reals: np.ndarray
    mass: np.ndarray


@njit(cache=True, inline="always")
def _evaluate_joints(kernel, q, qd, t, u, buffer):
    """:func:`_evaluate_kernel` for a :class:`JointKernel`."""
    _evaluate_kernel(kernel.ints, kernel.reals, q, qd, t, u, buffer)


JointKernel.evaluate = staticmethod(_evaluate_joints)
