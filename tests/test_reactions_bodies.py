"""Joint reactions (cmbs.inverse.reactions) of bodies with further points and of segments loaded
by forces at inner points and by moments: Newton's third law at a pin on a body's further point,
and Newton-Euler of every segment and body with the applied loads, at a moving state solved by
Lagrange multipliers (a_G and α from q̈ by the frame's definition)."""

import numpy as np
import pytest

import cmbs
from cmbs.dynamics import formulation
from cmbs.inverse.reactions import joint_reactions

G = 9.81
T = 0.7
# name: (points, mass, com, inertia)
PARTS = {"crank": (("A", "P1"), 1.0, (0.5, 0.05), 0.1),
         "coupler": (("P1", "P2", "C"), 3.0, (1.6, 0.5), 1.2),
         "rocker": (("P2", "B"), 1.5, (1.0, 0.0), 0.5),
         "bob": (("C", "E"), 0.8, (0.3, 0.0), 0.02)}


def loaded_linkage() -> cmbs.Model:
    """A four-bar A-P1-P2-B whose coupler is a triangular plate with a pendulum C-E hanging from
    its third point C; a moment on the crank, a follower force on the coupler, a ground-frame
    force on the bob's middle."""
    b = cmbs.NaturalModelBuilder("loaded linkage")
    for name, x, z, fixed in (("A", 0.0, 0.0, True), ("B", 4.0, 0.0, True), ("P1", 0.0, 1.0, False),
                              ("P2", 3.6, 2.0, False), ("C", 2.0, 3.0, False), ("E", 2.3, 2.2, False)):
        b.add_point(name, x, z, fixed=fixed)
    for name, (points, mass, com, inertia) in PARTS.items():
        if len(points) == 2:
            b.add_segment(name, *points, mass=mass, com=com, inertia=inertia)
        else:
            b.add_body(name, list(points), mass=mass, com=com, inertia=inertia)
    b.add_moment("motor", segment="crank", moment="3*sin(t)")
    b.add_force("thrust", segment="coupler", at=(2.5, -0.4), frame="body", fx=2.0, fz="1 + t")
    b.add_force("wind", segment="bob", at=(0.4, 0.0), fx=-1.5, fz=0.5)
    return b.build()


def cross(a, b):
    return a[0] * b[1] - a[1] * b[0]


def state(model):
    q = cmbs.assemble(model)
    qd = cmbs.velocities(model, q, T, qd=np.random.default_rng(3).normal(size=model.n))
    solution = formulation("lagrange").bind(model).accelerations(model.evaluate(q, qd, T), q, qd, T)
    return q, qd, solution.qdd, solution.lam


def test_third_law_at_a_further_point_of_a_body():
    model = loaded_linkage()
    q, qd, qdd, lam = state(model)
    forces = joint_reactions(model, q, qd, qdd, lam, T)["forces"]
    scale = np.abs(forces[("bob", "C")]).max()
    assert scale > 1.0
    np.testing.assert_allclose(forces[("coupler", "C")] + forces[("bob", "C")], 0.0, atol=1e-12 * scale)
    np.testing.assert_allclose(forces[("crank", "P1")] + forces[("coupler", "P1")], 0.0, atol=1e-12 * scale)
    np.testing.assert_allclose(forces[("coupler", "P2")] + forces[("rocker", "P2")], 0.0, atol=1e-12 * scale)


def applied(name, r_i, r_j, length):
    """(force, its point, moment): the loads of :func:`loaded_linkage` on a part, by hand."""
    e = (r_j - r_i) / length
    n = np.array([-e[1], e[0]])
    if name == "crank":
        return np.zeros(2), r_i, 3 * np.sin(T)
    if name == "coupler":
        return 2.0 * e + (1 + T) * n, r_i + 2.5 * e - 0.4 * n, 0.0
    if name == "bob":
        return np.array([-1.5, 0.5]), r_i + 0.4 * e, 0.0
    return np.zeros(2), r_i, 0.0


@pytest.mark.parametrize("name", list(PARTS))
def test_newton_euler_of_every_part_with_its_loads(name):
    """m a_G = Σ_P F(s, P) + m g + F_applied and I_G α = Σ_P (r_P - r_G) × F(s, P) + couple +
    (r_F - r_G) × F_applied + moment, with every point P of a body."""
    model = loaded_linkage()
    q, qd, qdd, lam = state(model)
    reactions = joint_reactions(model, q, qd, qdd, lam, T)
    points, mass, com, inertia = PARTS[name]
    r = dict(zip(model.point_names, model.point_positions(q)))
    a = {point: np.zeros(2) for point in model.point_names}
    a.update({point: qdd[2 * k:2 * k + 2] for k, point in enumerate(p for p in model.point_names
                                                                     if p not in ("A", "B"))})
    d, dd = r[points[1]] - r[points[0]], a[points[1]] - a[points[0]]
    length = np.linalg.norm(d)
    normal, ddn = np.array([-d[1], d[0]]), np.array([-dd[1], dd[0]])
    r_G = r[points[0]] + (com[0] * d + com[1] * normal) / length
    a_G = a[points[0]] + (com[0] * dd + com[1] * ddn) / length
    alpha = cross(d, dd) / length**2
    force, at, moment = applied(name, r[points[0]], r[points[1]], length)
    F = {point: reactions["forces"][(name, point)] for point in points}
    total = sum(F.values()) + mass * np.array([0.0, -G]) + force
    scale = max(np.abs(f).max() for f in F.values())
    np.testing.assert_allclose(total, mass * a_G, atol=1e-11 * scale)
    torque = (sum(cross(r[point] - r_G, F[point]) for point in points) + reactions["couples"][name]
              + cross(at - r_G, force) + moment)
    assert torque == pytest.approx(inertia * alpha, abs=1e-11 * scale * length)
    # the inertia terms are 10⁵ times the tolerances: dynamics, not statics, is checked
    assert np.linalg.norm(mass * a_G) > 1e-6 * scale and abs(inertia * alpha) > 1e-6 * scale * length
