"""Joint reactions of spatial natural-coordinate models: forces at points and couples through unit
vectors (:mod:`cmbs.model.spatial`).

Convention of the library: ``M q̈ + Aᵀλ = Q``.  Work in extended coordinates x = (q, constants)
(fixed elements have zero acceleration).  A body (or rod) b owns some slots e (its origin, basis
and further elements), its element mass matrix M_e and gravity Q_e, and some rows (its rigid-body
products and further-element rows, :class:`~cmbs.model.spatial.FreeBody`).  As a free body

    M_e ẍ_e = Q_e + L_e + F_e - A_ownᵀ λ_own                                           (1)

where L_e is the generalized force of the moments applied to b, and F_e the generalized force
that everything else applies at b's elements: the neighbours that share them, the ground at its
fixed elements, the rows between bodies (scalar products, angles, slides, distances), springs,
applied point forces and point masses at its points.  Hence

    F_e = M_e ẍ_e - Q_e - L_e + A_ownᵀ λ_own.                                            (2)

Its own rows are internal: for a rigid motion δq_e (δr_P = δr + δθ × (P - O) at points,
δu = δθ × u at vectors) their forces do no work, so they add no net force or moment and (2)
splits the reaction between the elements without changing its resultant.  At a point P, F(b, P)
is a force at P.  At a unit vector u, the virtual work F(b, u)·δu = (u × F(b, u))·δθ is that of
the couple

    C(b, u) = u × F(b, u),                                                               (3)

perpendicular to u: a revolute joint (a shared point and axis u) transmits the force at the
point and the couple C(b, u), whose component along the axis is zero (a torque about the axis
enters through an angle coordinate's vectors).  Checks (tests/test_spatial_reactions.py):
Newton's third law at a point two bodies share; for each body Σ F + m g = m a_G and
Σ (P - G) × F(b, P) + Σ C(b, u) + applied moments = d/dt (I_G ω); a planar mechanism built in
space against the planar reactions.

A row two bodies would both own (the product of two elements they share, one row in the model:
:mod:`cmbs.model.spatial`) belongs to the first; its force at a shared vector is along the
vectors it relates, so the couples (3) do not depend on that choice.

Angle coordinates: the joint torque τ_θ = A[row, θ] λ_row (the couple about the axis on the
"vector" side, as in the plane, :mod:`cmbs.inverse.reactions`).  Slides: the force -λ (3,) the
line applies to the sliding point.
"""

from __future__ import annotations

import numpy as np

from cmbs.errors import CmbsError
from cmbs.inverse.reactions import extended_state
from cmbs.model.model import Model, base_equations
from cmbs.model.packing import unpack
from cmbs.model.spatial import _DOT, _LINEAR, _LINEAR_COEFFICIENTS, SpatialEquations


def _equations(model: Model) -> tuple[SpatialEquations, np.ndarray]:
    equations, rows = base_equations(model)
    if not isinstance(equations, SpatialEquations):
        raise CmbsError(f"model {model.name!r}: spatial joint reactions need a spatial natural-coordinate model")
    return equations, rows


def _row_data(equations: SpatialEquations) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The dot rows' element indices (k, 4), the further-element rows' (k, 8) and their
    coefficients (k, 3), from the packed kernel data."""
    int_sections, real_sections = unpack(equations.ints, equations.reals)
    return (int_sections[_DOT].reshape(-1, 4), int_sections[_LINEAR].reshape(-1, 8),
            real_sections[_LINEAR_COEFFICIENTS].reshape(-1, 3))


def _own_row_forces(row_data: tuple[np.ndarray, np.ndarray, np.ndarray], x: np.ndarray, lam: np.ndarray,
                    rows: np.ndarray) -> np.ndarray:
    """Σ A_rᵀ λ_r over ``rows`` (dot and further-element rows, :func:`_row_data`), in extended
    coordinates."""
    dots, linear, coefficients = row_data
    force = np.zeros(x.size)
    for row in rows:
        if row < dots.shape[0]:
            ah, at, bh, bt = dots[row]
            a, b = x[ah:ah + 3] - x[at:at + 3], x[bh:bh + 3] - x[bt:bt + 3]
            force[ah:ah + 3] += lam[row] * b
            force[at:at + 3] -= lam[row] * b
            force[bh:bh + 3] += lam[row] * a
            force[bt:bt + 3] -= lam[row] * a
            continue
        group, axis = divmod(row - dots.shape[0], 3)
        head, tail, *basis = linear[group]
        force[head + axis] += lam[row]
        force[tail + axis] -= lam[row]
        for k in range(3):
            force[basis[2 * k] + axis] -= coefficients[group, k] * lam[row]
            force[basis[2 * k + 1] + axis] += coefficients[group, k] * lam[row]
    return force


def spatial_reactions(model: Model, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, lam: np.ndarray,
                      t: float = 0.0) -> dict:
    """Reaction forces at every body's points and couples through its unit vectors, joint torques
    of angle coordinates and the forces of slides (module docstring, eq. 2-3).

    ``q``, ``qdd`` and ``lam`` (multipliers of all m rows, ``M q̈ + Aᵀλ = Q``) must be consistent;
    ``qd`` is accepted for a uniform signature (the reactions do not depend on it); ``t`` is the
    time of the applied moments.

    Returns
    -------
    dict with
        ``forces``: {(body, point): (3,) array} — the force the rest of the mechanism applies to
        the body (or rod) at that point;
        ``vector_couples``: {(body, vector): (3,) array} — the couple it applies through that unit
        vector, C = u × F(b, u);
        ``torques``: {angle: float} — τ_θ = A[row, θ] λ_row;
        ``sliders``: {slide: (3,) array} — the force of the line on the sliding point.
    """
    equations, rows = _equations(model)
    q, x, acceleration, lam = extended_state(model, equations, rows, q, qdd, lam)
    forces, couples = {}, {}
    row_data = _row_data(equations)
    for body in equations.free_bodies:
        extended = (body.slots[:, None] + np.arange(3)).ravel()
        own = _own_row_forces(row_data, x, lam, body.rows)[extended]
        moments = np.zeros(x.size)
        if body.name in equations.moment_bodies:
            moments[:equations.n] = equations.moment_loads(body.name, q, t)
        share = body.mass @ acceleration[extended] - body.gravity - moments[extended] + own
        for k, (element, kind) in enumerate(zip(body.elements, body.kinds)):
            F = share[3 * k:3 * k + 3]
            if kind == "point":
                forces[(body.name, element)] = F
            else:
                couples[(body.name, element)] = np.cross(x[body.slots[k]:body.slots[k] + 3], F)
    names = [""] * equations.m
    for k in np.flatnonzero(rows >= 0):
        names[rows[k]] = model.constraint_names[k]
    A = _base_jacobian(equations, q, t)
    torques, sliders = {}, {}
    for row, name in enumerate(names):
        kind, _, label = name.partition(" ")
        if kind == "angle":
            torques[label] = float(A[row, model.coordinate_index(label)] * lam[row])
        elif kind == "slider" and label.endswith(".x"):
            sliders[label[:-2]] = -lam[row:row + 3].copy()
    return {"forces": forces, "vector_couples": couples, "torques": torques, "sliders": sliders}


def _base_jacobian(equations: SpatialEquations, q: np.ndarray, t: float) -> np.ndarray:
    """A of the base equations at (q, t)."""
    terms = equations.new_terms()
    equations.evaluate(np.array(q, dtype=float), np.zeros(equations.n), t, np.zeros(0), terms)
    return terms.A.copy()
