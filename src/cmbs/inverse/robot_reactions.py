"""Joint reactions of robots (spatial joint-coordinate trees, :mod:`cmbs.model.robot`), loop
closures included: the completion of the recursive Newton-Euler algorithm's backward pass.

Spatial vectors are those of :mod:`cmbs.model.robot_kernel`: Plücker coordinates in world axes
about the world origin, a force ``f = (n_O, f)``.  The model's evaluation at (q, q̇) runs RNEA
with q̈ = 0 and the base accelerating at -g, and leaves for each body k its motion subspace S_k,
its composite inertia I^c_k and the sum over its subtree of the bias wrenches
``Σ (I_j a_j + v_j ×_f I_j v_j - f^ext_j)``, f^ext_j the spatial forces of the point forces,
moments and spring-dampers between two points applied to body j (:mod:`cmbs.model.robot_loads`;
Featherstone, *Rigid Body Dynamics Algorithms*, 2008, §5.3).
With the accelerations q̈, each body's acceleration gains ``â_j = â_parent + S_j q̈_j``, so the
wrench that joint k transmits from its parent (or the ground) to the subtree of k is::

    f^J_k = Σ_{j in subtree(k)} [I_j (a_j + â_j) + v_j ×_f I_j v_j - f^ext_j] - Σ_{j in subtree(k)} w_j,
          I_j = I^c_j - Σ_{children c of j} I^c_c,

with w_j the loop-closure wrenches on body j (gravity is in a_j through the base's -g).  The
closure rows' generalized force is ``-Aᵀλ`` (``M q̈ + Aᵀλ = Q``); by their rows
(:mod:`cmbs.model.robot_kernel`):

    point  Φ = p_a - p_b (λ: 3 numbers):  the force -λ at p_a on body a, +λ at p_b on body b,
    dot    Φ = u·v (λ: 1 number):          the couple -λ (u × v) on body a, +λ (u × v) on body b,
    line   Φ = (p_a - p_b)·v, v on body b:  the force -λ v at p_a on body a, +λ v at p_a on body b,

since the rows' Jacobians are ``J_a - J_b`` at the points, ``(u × v)ᵀ (J_ω,a - J_ω,b)`` and
``vᵀ (J_a - J_b) + (v × d)ᵀ J_ω,b`` with d = p_a - p_b (the force +λ v at p_b and the couple
-λ v × d on body b are the force +λ v at p_a).  A
driver's row (``q_c - f(t)``) has the generalized force -λ on q_c alone: the actuation of joint c,
part of what the joint transmits, and so does a mimic row's (``q_j - r q_k - o``: -λ on q_j
and rλ on q_k, a transmission between the two joints).  A pose driver's rows carry no force: the
joint torques of inverse dynamics' method ``projected`` produce its motion with their multipliers
zero (:mod:`cmbs.inverse.joint_torques`), and a nonzero one, the target's wrench on the link, is
refused.  Hence the check
``S_kᵀ f^J_k = u_k + τ_springs(k) - λ_drivers(k) - (mimic rows' Aᵀλ)_k``: the joint's torque
(revolute) or force (prismatic) along its axis is the actuation of its coordinate, its joint springs'
and dampers' torques ``-k (q_k - q_rest) - c q̇_k`` included.  The rest of f^J_k is carried by the bearing.

Result (world axes): the force of f^J_k and its moment about the joint origin o_k (the child
link frame's origin), ``n_k = n_O - o_k × f``; per movable joint, named by the joint.
"""

from __future__ import annotations

import numpy as np

from cmbs.errors import CmbsError
from cmbs.model.model import Model, base_equations, base_multipliers
from cmbs.model.robot import RobotEquations
from cmbs.model.robot_kernel import CLOSE_LINE, CLOSE_POINT, JOINT_COUPLING, TARGET_DOT, TARGET_POINT, body_work

__all__ = ["robot_reactions"]


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _spatial_inertia(composite: np.ndarray) -> np.ndarray:
    """The 6 x 6 matrix of the inertia (m, h, Ī) (10 numbers, :mod:`cmbs.model.robot_kernel`):
    ``I (ω, v_O) = (Ī ω + h × v_O, m v_O - h × ω)``."""
    m, h = composite[0], composite[1:4]
    i00, i01, i02, i11, i12, i22 = composite[4:10]
    matrix = np.zeros((6, 6))
    matrix[:3, :3] = [[i00, i01, i02], [i01, i11, i12], [i02, i12, i22]]
    matrix[:3, 3:] = _skew(h)
    matrix[3:, :3] = -_skew(h)
    matrix[3:, 3:] = m * np.eye(3)
    return matrix


def _wrench(point: np.ndarray, force: np.ndarray) -> np.ndarray:
    """The force ``force`` applied at ``point`` as (moment about the world origin, force)."""
    return np.concatenate([np.cross(point, force), force])


def _closure_wrenches(equations: RobotEquations, R: np.ndarray, o: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """(n, 6): the closure elements' wrenches on each body (module docstring) for the
    multipliers ``lam`` of the equations' rows."""
    kernel = equations.kernel
    wrenches = np.zeros((equations.n, 6))

    def world_point(body: int, local: np.ndarray) -> np.ndarray:
        return local if body < 0 else o[body] + R[body] @ local

    def world_vector(body: int, local: np.ndarray) -> np.ndarray:
        return local if body < 0 else R[body] @ local

    row = 0
    for (kind, body_a, body_b, _), reals in zip(kernel.closure_ints, kernel.closure_reals):
        if kind == CLOSE_POINT:
            force = -lam[row:row + 3]
            on_a = _wrench(world_point(body_a, reals[0:3]), force)
            on_b = -_wrench(world_point(body_b, reals[3:6]), force)
            row += 3
        elif kind == CLOSE_LINE:
            point = world_point(body_a, reals[0:3])
            on_a = _wrench(point, -lam[row] * world_vector(body_b, reals[6:9]))
            on_b = -on_a
            row += 1
        elif kind == JOINT_COUPLING:       # a transmission between two joints: their actuation, no wrench
            row += 1
            continue
        elif kind in (TARGET_POINT, TARGET_DOT):    # a pose driver's rows: no force (projected torques)
            count = 3 if kind == TARGET_POINT else 1
            if np.any(lam[row:row + count] != 0.0):
                raise CmbsError("a pose driver's multipliers are not zero: they would be the target's wrench on "
                                "the link, which no joint transmits; take the joint torques of inverse dynamics' "
                                "method 'projected' (its pose rows carry no force)")
            row += count
            continue
        else:                              # CLOSE_DOT
            couple = -lam[row] * np.cross(world_vector(body_a, reals[0:3]), world_vector(body_b, reals[3:6]))
            on_a = np.concatenate([couple, np.zeros(3)])
            on_b = -on_a
            row += 1
        for body, wrench in ((body_a, on_a), (body_b, on_b)):
            if body >= 0:
                wrenches[body] += wrench
    return wrenches


def robot_reactions(model: Model, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, lam: np.ndarray,
                    u: np.ndarray | None = None, t: float = 0.0) -> dict:
    """Forces and moments transmitted by every movable joint of a robot at a consistent state
    (q, q̇, q̈, λ, u) at time ``t`` (``M q̈ + Aᵀλ = Q``; e.g. a step of
    ``cmbs.inverse_dynamics(...).motion`` or of a simulation with its ``lam``).

    Returns
    -------
    dict with
        ``forces``: {joint: (3,) array} — force of the parent link (or the ground) on the joint's
        child, world axes (N);
        ``moments``: {joint: (3,) array} — moment of the same interaction about the joint origin,
        world axes (N m);
        ``joint_forces``: {joint: float} — its component along the joint's axis: the torque
        (revolute) or force (prismatic) that actuates the joint (its input u plus the torques of
        its springs and dampers, :mod:`cmbs.model.robot_loads`);
        ``closures``: {constraint row: float} — ``-λ`` of each loop-closure row (the force along a
        point row's world axis on link a, or the couple about u × v of an axis row) and of each
        mimic row (the torque on the mimicking joint; r times it, opposite, on the mimicked one).
    """
    equations, rows = base_equations(model)
    if not isinstance(equations, RobotEquations):
        raise CmbsError(f"model {model.name!r}: robot reactions need a robot (a URDF tree)")
    q, qd, qdd, lam = (np.asarray(a, dtype=float) for a in (q, qd, qdd, lam))
    if lam.shape != (model.m,):
        raise CmbsError(f"lam has shape {lam.shape}, expected ({model.m},)")
    u = np.zeros(equations.n) if u is None else np.asarray(u, dtype=float)
    terms = equations.new_terms()
    equations.evaluate(q, qd, t, u, terms)
    work = body_work(equations.kernel, terms.scratch)
    full_lam = base_multipliers(lam, rows, equations.m)
    parent, order = equations.kernel.parent, equations.kernel.order

    inertias = np.array([_spatial_inertia(c) for c in work.composite])
    for k in range(equations.n):          # own inertia = composite minus the children's composites
        if parent[k] >= 0:
            inertias[parent[k]] -= _spatial_inertia(work.composite[k])
    acceleration = np.zeros((equations.n, 6))   # â_k = â_parent + S_k q̈_k
    for k in order:
        acceleration[k] = (acceleration[parent[k]] if parent[k] >= 0 else 0.0) + work.S[k] * qdd[k]
    per_body = np.einsum("kij,kj->ki", inertias, acceleration) - _closure_wrenches(equations, work.R, work.o,
                                                                                  full_lam)
    for k in order[::-1]:             # summed over each subtree, children before parents
        if parent[k] >= 0:
            per_body[parent[k]] += per_body[k]
    transmitted = work.bias_subtree + per_body

    names = [joint.name for joint in equations.joints]
    closures = {name: float(-lam[r]) for r, name in enumerate(model.constraint_names)
                if rows[r] >= 0 and not model.drivers[r]}
    return {"forces": {names[k]: transmitted[k, 3:].copy() for k in range(equations.n)},
            "moments": {names[k]: transmitted[k, :3] - np.cross(work.o[k], transmitted[k, 3:])
                        for k in range(equations.n)},
            "joint_forces": {names[k]: float(work.S[k] @ transmitted[k]) for k in range(equations.n)},
            "closures": closures}
