"""Joint reaction forces of planar natural-coordinate models (THEORY §1-2); joint-coordinate
models are handled by :mod:`cmbs.inverse.tree_reactions`.

Convention of the library: ``M q̈ + Aᵀλ = Q``, so the generalized constraint force of row r is
``-A_rᵀ λ_r``.  Work in extended coordinates (q followed by the constants of fixed points, whose
accelerations are zero).  Segment s, with points (i, j), extended indices e_s (4 of them), element
mass matrix M_e, element gravity force Q_e = C_Gᵀ(m g) and rigidity row ρ_s
(Φ_ρ = |r_j - r_i|² - L², gradient A_ρ,e = 2(-d, d), d = r_j - r_i), is a free body:

    M_e q̈_e = Q_e + F_s + C_s - A_ρᵀ λ_ρ                                          (1)

- ``-A_ρᵀλ_ρ`` is the force of its own rigidity row: internal to the body (a pair of equal and
  opposite forces along i-j), not a reaction, so it is removed.
- ``C_s`` is the generalized force of the *couples* that angle coordinates (and slider locks)
  transmit to the segment.  An angle row ``Φ = cos φ (u×w) - sin φ (u·w)`` with a direction
  ``u = r_b - r_a`` made of this segment's two points has gradient ``+g_u`` at b and ``-g_u`` at a
  (``g_u = ∂Φ/∂u``), so its force ``-g_u λ`` at b and ``+g_u λ`` at a sums to zero: a pure couple,
  of moment ``u × (-g_u λ)``.  The same holds for w, and for the parallel-lock row of a slider
  (``Φ = u×w``, ``∂Φ/∂u = (w_z, -w_x)``, ``∂Φ/∂w = (-u_z, u_x)``).  Directions given by two points
  that are not the two points of one segment are not couples on a body: their forces stay in F.
- ``F_s`` = (F(s, i), F(s, j)): the forces, x and z, that everything else applies to the segment at
  its two points — neighbouring segments (the pin forces), the ground at fixed points, slider
  rows (their force on the sliding point; for a slider along a moving segment also the force on
  the guide, as its equivalent at the guide's two points), distance coordinates, springs,
  dampers, applied point forces and point masses at those points.  Torques applied on angle
  coordinates and driver forces on angles reach the segments through the angle rows, i.e. in C_s.
  Forces at other points of the segment and moments on it (``[forces]`` with ``segment``,
  ``[moments]``) are applied loads, not reactions: they join Q_e (their generalized force,
  :meth:`~cmbs.model.natural.NaturalEquations.segment_loads`).

Hence (the result of :func:`joint_reactions`)

    F_s = M_e q̈_e - Q_e + A_ρᵀ λ_ρ - C_s                                           (2)

Bodies with further points K (tied to the frame by the rows Φ_K = r_K - C_K q_e, C_K the 2×4
map of K's local position): the rows' force on the body is ``-(∂Φ_K/∂q_e)ᵀ λ_K = C_Kᵀ λ_K``, the
generalized force of the point force ``λ_K`` at K.  So the force the rest of the mechanism
applies to the body at K is F(s, K) = λ_K, and F_s above, less Σ_K C_Kᵀ λ_K, is the force at I
and J.

Checks that hold for this split (tests/test_reactions.py): Newton's third law at a pin shared by
two segments and nothing else, ``F(a, P) + F(b, P) = 0``; for each segment
``F(s, i) + F(s, j) + m g = m a_G`` and, about G, ``Σ (r_P - r_G) × F(s, P) + couple_s = I_G α``.

Angle torques.  For an angle coordinate φ from direction u to direction w (for an absolute angle u
is the ground x axis), the couple its row applies to the body of w is

    τ_φ = A[row, φ] λ_row          (and -τ_φ to the body of u)

because ``w × (-g_w λ) = A[row, φ] λ`` and ``u × (-g_u λ) = -A[row, φ] λ`` (from the kernel's
formulas).  The equation of the massless φ column, ``A[row, φ] λ_row + Σ_drivers λ = Q_φ``, makes
τ_φ = Q_φ - λ_driver: the applied torques and actuator inputs on φ plus the driver force on φ
(``-λ_driver``, as in :mod:`cmbs.inverse.ida`) — the joint (motor) torque, counter-clockwise
positive on the "to" segment.  The generalized force on φ's column, ``-A[row, φ] λ_row = -τ_φ``,
is the couple on the "from" side.

Sliders.  For a slider row ``Φ = u×w``, u the guide direction and w = r_P - r_base, the force on
the sliding point P is ``-(∂Φ/∂r_P) λ = λ (u_z, -u_x)``: normal to the guide (frictionless).  A
lock row reports its couple on the locked segment (counter-clockwise positive).
"""

from __future__ import annotations

import numpy as np

from cmbs.errors import CmbsError
from cmbs.model.model import Model, base_equations, base_multipliers
from cmbs.model.natural import _ANGLE, _DISTANCE, _PARALLEL, NaturalEquations, point_map
from cmbs.trajectory import Trajectory


def _section(ints: np.ndarray, k: int) -> np.ndarray:
    return ints[ints[1 + k]:ints[2 + k]]


def _cross(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _equations(model: Model) -> tuple[NaturalEquations, np.ndarray, list[str]]:
    """The natural-coordinate equations under the model's wrappers, the base row of every
    model row (-1: none) and the names of the base rows."""
    equations, rows = base_equations(model)
    if not isinstance(equations, NaturalEquations):
        raise CmbsError(f"model {model.name!r}: joint reactions need a natural-coordinate model")
    if not equations.segments and any(name.startswith("rigid ") for name in model.constraint_names):
        raise CmbsError(f"model {model.name!r}: its equations carry no segment data")
    names = [""] * equations.m
    for k in np.flatnonzero(rows >= 0):
        names[rows[k]] = model.constraint_names[k]
    return equations, rows, names


def _couple_rows(names: list[str], equations: NaturalEquations):
    """(row, kind, name, extended indices) of the angle and slider (parallel) rows."""
    ints = equations.ints
    row = len(equations.segments) + _section(ints, _DISTANCE).size // 5
    rows = []
    angle = _section(ints, _ANGLE).reshape(-1, 9)
    for r in angle:
        rows.append((row, "angle", names[row].partition(" ")[2], r))
        row += 1
    for r in _section(ints, _PARALLEL).reshape(-1, 8):
        name = names[row].partition(" ")[2]
        kind = "lock" if name.endswith(" lock") else "slider"
        rows.append((row, kind, name[:-5] if kind == "lock" else name, r))
        row += 1
    return rows


def extended_state(model: Model, equations, rows: np.ndarray, q: np.ndarray, qdd: np.ndarray,
                   lam: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(q, x, ẍ, λ_base) of a natural-coordinate model's state: the extended coordinates
    x = (q, constants) and accelerations (zero for the constants), and the multipliers of the
    base equations' rows (:func:`~cmbs.model.model.base_multipliers`) from the model's ``lam``."""
    q, qdd, lam = (np.asarray(value, dtype=float) for value in (q, qdd, lam))
    if lam.shape != (model.m,):
        raise CmbsError(f"lam has shape {lam.shape}, expected ({model.m},)")
    constants = equations.constants
    return (q, np.concatenate([q, constants]), np.concatenate([qdd, np.zeros(constants.size)]),
            base_multipliers(lam, rows, equations.m))


def joint_reactions(model: Model, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, lam: np.ndarray,
                    t: float = 0.0) -> dict:
    """Reaction forces on every segment at its two points, joint torques and slider forces.

    ``q``, ``qdd`` and ``lam`` (multipliers of all m rows, convention ``M q̈ + Aᵀλ = Q``, e.g.
    ``extras['lam']`` of :func:`~cmbs.inverse.inverse_dynamics` or of a Lagrange simulation) must
    be consistent; ``qd`` is accepted for a uniform signature but the reactions do not depend on
    it (velocity terms are inside q̈ and λ); ``t`` is the time of the applied segment forces and
    moments.  See the module docstring for the
    equations and signs.

    Returns
    -------
    dict with
        ``forces``: {(segment, point): (2,) array (F_x, F_z)} — the force the rest of the
        mechanism applies to the segment at that point, eq. (2) (every point of a body);
        ``couples``: {segment: float} — total couple (counter-clockwise) transmitted to it by
        angle and slider-lock rows (C_s);
        ``torques``: {angle: float} — τ_φ = A[row, φ] λ_row, the couple on the angle's "to"
        segment (minus it on the "from" segment);
        ``sliders``: {slider: (2,) array} — the constraint force on the sliding point;
        ``slider_couples``: {slider: float} — for sliders with ``lock``, the couple on the
        locked segment.
    """
    equations, rows, names = _equations(model)
    q, x, a, lam = extended_state(model, equations, rows, q, qdd, lam)

    # couple rows: gradients with respect to each direction, their couples on segments
    segment_of = {}
    for k, segment in enumerate(equations.segments):
        segment_of.setdefault(tuple(segment.indices), (k, 1.0))
        segment_of.setdefault(tuple(segment.indices[[2, 3, 0, 1]]), (k, -1.0))
    generalized = [np.zeros(4) for _ in equations.segments]   # C_s in (x_i, z_i, x_j, z_j)
    couples = np.zeros(len(equations.segments))
    torques, sliders, slider_couples = {}, {}, {}
    for row, kind, name, r in _couple_rows(names, equations):
        u = x[r[2:4]] - x[r[0:2]]
        w = x[r[6:8]] - x[r[4:6]]
        if kind == "angle":
            c, s = np.cos(x[r[8]]), np.sin(x[r[8]])
            g_u = c * np.array([w[1], -w[0]]) - s * w
            g_w = c * np.array([-u[1], u[0]]) - s * u
            torques[name] = float((-s * _cross(u, w) - c * float(u @ w)) * lam[row])
        else:
            g_u = np.array([w[1], -w[0]])
            g_w = np.array([-u[1], u[0]])
        if kind == "slider":
            sliders[name] = -g_w * lam[row]
            continue  # the slider row's forces are reactions at points: they stay in F
        directions = ((r[0:4], u, g_u), (r[4:8], w, g_w))
        for position, (indices, vector, gradient) in enumerate(directions):
            match = segment_of.get(tuple(indices))
            if match is None:
                continue
            k, orientation = match
            force_b = -gradient * lam[row]          # at the direction's tip b; -force_b at a
            # segment frame: b = j when orientation is +1, b = i when -1
            generalized[k] += orientation * np.concatenate([-force_b, force_b])
            moment = _cross(vector, force_b)
            couples[k] += moment
            if kind == "lock" and position == 1:
                slider_couples[name] = moment

    forces = {}
    loads = equations.segment_loads(q, t)
    for k, segment in enumerate(equations.segments):
        idx = segment.indices
        d = x[idx[2:4]] - x[idx[0:2]]
        rigid = np.concatenate([-2.0 * d, 2.0 * d]) * lam[segment.rigid_row]
        F = segment.mass_matrix @ a[idx] - segment.gravity - loads[k] + rigid - generalized[k]
        for point in segment.attached:
            at_point = lam[point.row:point.row + 2]
            forces[(segment.name, point.name)] = at_point
            F = F - point_map(segment.length, point.local).T @ at_point
        forces[(segment.name, segment.points[0])] = F[0:2]
        forces[(segment.name, segment.points[1])] = F[2:4]
    return {"forces": forces, "couples": {s.name: float(c) for s, c in zip(equations.segments, couples)},
            "torques": torques, "sliders": sliders, "slider_couples": slider_couples}


def joint_reaction_history(model: Model, motion: Trajectory) -> dict:
    """Joint reactions at every instant of ``motion`` (a trajectory of this model with extras
    ``'lam'`` (k, m), e.g. ``inverse_dynamics(...).motion``, and ``'u'`` (k, n_u) if the inputs
    were not zero): :func:`joint_reactions` for natural-coordinate models,
    :func:`~cmbs.inverse.spatial_reactions.spatial_reactions` for spatial ones,
    :func:`~cmbs.inverse.tree_reactions.tree_reactions` for joint-coordinate ones,
    :func:`~cmbs.inverse.robot_reactions.robot_reactions` for robots.  The same keys, each value
    with a leading time axis ((k, 2) or (k, 3) for forces, (k,) for scalars)."""
    from cmbs.inverse.robot_reactions import robot_reactions
    from cmbs.inverse.spatial_reactions import spatial_reactions
    from cmbs.inverse.tree_reactions import tree_reactions
    from cmbs.model.robot import RobotEquations
    from cmbs.model.spatial import SpatialEquations

    if "lam" not in motion.extras:
        raise CmbsError("the trajectory has no 'lam' extra (multipliers); use inverse_dynamics' motion")
    lam = np.asarray(motion.extras["lam"], dtype=float)
    equations = base_equations(model)[0]
    if isinstance(equations, (NaturalEquations, SpatialEquations)):
        reactions = joint_reactions if isinstance(equations, NaturalEquations) else spatial_reactions
        per_time = [reactions(model, motion.q[i], motion.qd[i], motion.qdd[i], lam[i], motion.t[i])
                    for i in range(motion.t.size)]
    else:
        inputs = np.asarray(motion.extras.get("u", np.zeros((motion.t.size, model.n_u))), dtype=float)
        reactions = robot_reactions if isinstance(equations, RobotEquations) else tree_reactions
        per_time = [reactions(model, motion.q[i], motion.qd[i], motion.qdd[i], lam[i], inputs[i], motion.t[i])
                    for i in range(motion.t.size)]
    if not per_time:
        raise CmbsError("the trajectory is empty")
    return {key: {name: np.array([step[key][name] for step in per_time]) for name in per_time[0][key]}
            for key in per_time[0]}
