"""Joint reactions of joint-coordinate models by Newton-Euler (THEORY §1; Featherstone's RNEA in
the plane, with loop-closure forces).

Given a consistent (q, q̇, q̈, λ, u) of a :class:`~cmbs.model.joints.JointModelBuilder` model
(``M q̈ + Aᵀλ = Q``), the forward pass gives every link's absolute angle θ_k, rate ω_k,
acceleration ω̇_k, joint origin O_k and centre-of-mass acceleration a_Gk::

    θ_k = θ_p + α_k + [rev] q_k,   ω_k = ω_p + [rev] q̇_k,   ω̇_k = ω̇_p + [rev] q̈_k,
    a_{r on k} = a_{Ok} + ω̇_k S (r - O_k) - ω_k² (r - O_k),
    a_{Ok} = a_{r on p}(O_k) + [pri] (q̈_k e_k + 2 q̇_k ω_k S e_k),

(S the rotation by +90°, e_k the link's x axis).  A closure row r, ``Φ_r = n_r·(r_a - r_b)``,
has the generalized force ``-A_rᵀλ_r``: the force ``-λ_r n_r`` at point a and ``+λ_r n_r`` at b.
The backward pass (children before parents) gives the force F_k and the moment N_k (about O_k)
that the parent — or the ground — applies to link k through joint k::

    F_k = m_k (a_Gk - g) - f_k + Σ_c F_c,
    N_k = I_k ω̇_k + (G_k - O_k) × m_k (a_Gk - g) - Σ_i (r_i - O_k) × f_i
          + Σ_c [N_c + (O_c - O_k) × F_c],

with f_k the closure forces and the forces of springs, dampers and point forces applied to link k
(at points r_i) and c the children of k.  The
generalized force of joint k is then ``N_k`` (revolute) or ``F_k·e_k`` (prismatic); it must equal
the model's actuation, joint torque and driver force on q_k, ``Σ gain·u + T_k(t) - λ_driver``, which the tests use as an
independent check of the Lagrangian equations.  The rest of (F_k, N_k) is the reaction carried
by the joint's bearing or guide.
"""

from __future__ import annotations

import numpy as np

from cmbs.errors import CmbsError
from cmbs.model.joints import JointEquations, JointLayout
from cmbs.model.model import Model, base_equations, base_multipliers

_S = np.array([[0.0, -1.0], [1.0, 0.0]])


def _cross(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _rotation(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


def tree_reactions(model: Model, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, lam: np.ndarray,
                   u: np.ndarray | None = None, t: float = 0.0) -> dict:
    """Forces and moments transmitted by every joint of a joint-coordinate model at time ``t``
    (which the model's point forces may depend on).

    Returns
    -------
    dict with
        ``forces``: {link: (2,) array} — force of the parent (or ground) on the link at its joint
        origin O_k (x, z);
        ``moments``: {link: float} — moment about O_k of the same interaction (counter-clockwise);
        ``joint_forces``: {coordinate: float} — the generalized force of joint k (motor torque
        N_k of a revolute joint, force F_k·e_k along a prismatic one);
        ``closures``: {constraint: float} — the force ``-λ_r`` along n_r applied at the closure's
        first point.
    """
    equations, rows = base_equations(model)
    if not isinstance(equations, JointEquations):
        raise CmbsError(f"model {model.name!r}: joint-coordinate reactions need a joint-coordinate model")
    layout: JointLayout = equations.layout()
    q, qd, qdd, lam = (np.asarray(a, dtype=float) for a in (q, qd, qdd, lam))
    if lam.shape != (model.m,):
        raise CmbsError(f"lam has shape {lam.shape}, expected ({model.m},)")
    full_lam = base_multipliers(lam, rows, equations.m)
    n = q.size
    theta, omega, alpha = np.zeros(n), np.zeros(n), np.zeros(n)
    origin, acc_origin = np.zeros((n, 2)), np.zeros((n, 2))

    def acceleration(k: int, r: np.ndarray) -> np.ndarray:
        d = r - origin[k]
        return acc_origin[k] + alpha[k] * (_S @ d) - omega[k] ** 2 * d

    for k in layout.order:
        p = layout.parent[k]
        th_p, w_p, al_p = (theta[p], omega[p], alpha[p]) if p >= 0 else (0.0, 0.0, 0.0)
        o_p = origin[p] if p >= 0 else np.zeros(2)
        joint = o_p + _rotation(th_p) @ layout.origin[k]
        a_joint = acceleration(p, joint) if p >= 0 else np.zeros(2)
        if layout.revolute[k]:
            theta[k], omega[k], alpha[k] = th_p + layout.angle[k] + q[k], w_p + qd[k], al_p + qdd[k]
            origin[k], acc_origin[k] = joint, a_joint
        else:
            theta[k], omega[k], alpha[k] = th_p + layout.angle[k], w_p, al_p
            e = np.array([np.cos(theta[k]), np.sin(theta[k])])
            origin[k] = joint + q[k] * e
            # the slide point moves with the parent plus the relative motion along e
            acc_origin[k] = acceleration(p, origin[k]) if p >= 0 else np.zeros(2)
            acc_origin[k] += qdd[k] * e + 2.0 * qd[k] * w_p * (_S @ e)

    def position(link: int, local: np.ndarray) -> np.ndarray:
        return local if link < 0 else origin[link] + _rotation(theta[link]) @ local

    applied = [[] for _ in range(n)]   # (point, force) pairs from the closures
    closures = {}
    for r, ((la, lb), a_local, b_local, direction) in enumerate(
            zip(layout.closure_links, layout.closure_a, layout.closure_b, layout.closure_direction)):
        force = -full_lam[r] * direction
        if la >= 0:
            applied[la].append((position(la, a_local), force))
        if lb >= 0:
            applied[lb].append((position(lb, b_local), -force))
    for link, point, force in zip(*equations.point_loads(q, qd, t)):
        if link >= 0:
            applied[link].append((point, force))
    for r, name in enumerate(model.constraint_names):
        if 0 <= rows[r] < layout.closure_links.shape[0]:
            closures[name] = float(-lam[r])

    force, moment = np.zeros((n, 2)), np.zeros(n)
    for k in layout.order[::-1]:
        centre = position(k, layout.com[k])
        inertial = layout.mass[k] * (acceleration(k, centre) - layout.gravity)
        force[k] += inertial
        moment[k] += layout.inertia[k] * alpha[k] + _cross(centre - origin[k], inertial)
        for point, f in applied[k]:
            force[k] -= f
            moment[k] -= _cross(point - origin[k], f)
        p = layout.parent[k]
        if p >= 0:   # what the parent gives to k, the child takes from the parent
            force[p] += force[k]
            moment[p] += moment[k] + _cross(origin[k] - origin[p], force[k])

    names = [name.rpartition(".")[0] for name in model.point_names[0:2 * n:2]]
    joint_forces = {}
    for k, coordinate in enumerate(model.coordinate_names):
        e = np.array([np.cos(theta[k]), np.sin(theta[k])])
        joint_forces[coordinate] = float(moment[k]) if layout.revolute[k] else float(force[k] @ e)
    return {"forces": {names[k]: force[k].copy() for k in range(n)},
            "moments": {names[k]: float(moment[k]) for k in range(n)},
            "joint_forces": joint_forces, "closures": closures}
