"""Rigid bodies with more than two points, forces at any point of a segment or body (ground or
body frame) and moments on segments and bodies, in natural coordinates, against closed forms
(compound pendulum, free body under a follower force), finite differences of the positions and
of the direction angle (virtual work), and the torque on an absolute angle coordinate."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import cmbs
from cmbs.control.faults import mass_fault
from cmbs.dynamics import FORMULATIONS, formulation
from cmbs.errors import ModelError
from cmbs.model.natural import NaturalModelBuilder
from helpers import check_constraint_derivatives
from test_natural import rigid_body_kinetic_energy

G = 9.81
MASS, INERTIA = 0.8, 0.013
COM = (0.15, 0.2)                 # [along, across] in the frame I -> J: off the line I-J


def pivoted_plate(**builder_options) -> cmbs.Model:
    """A plate I, J, K hanging from the ground pivot K (its third point, so the pin is carried
    by the body point rows); I -> J along +x, the centre of mass 0.2 m above that line."""
    b = NaturalModelBuilder("plate", **builder_options)
    b.add_point("I", -0.3, -0.5)
    b.add_point("J", 0.1, -0.5)
    b.add_point("K", 0.25, 0.1, fixed=True)
    b.add_body("plate", ["I", "J", "K"], mass=MASS, com=COM, inertia=INERTIA)
    return b.build()


def com_position(model, q, body="plate"):
    """r_G from the body's first two points, by the frame's definition (not the element matrices)."""
    data = {s.name: s for s in model.equations.segments}[body]
    P = dict(zip(model.point_names, model.point_positions(q)))
    ri, rj = P[data.points[0]], P[data.points[1]]
    e = (rj - ri) / np.linalg.norm(rj - ri)
    return ri + data.com[0] * e + data.com[1] * np.array([-e[1], e[0]])


def test_pivoted_plate_swings_as_the_compound_pendulum_closed_form():
    """θ̈ = -m g d sin θ / (I_G + m d²), θ the angle of K->G from the downward vertical, from
    rest at about 50 degrees, over 2 s (about 1.5 periods)."""
    model = pivoted_plate()
    pivot = np.array([0.25, 0.1])
    g0 = com_position(model, model.q0) - pivot
    d = float(np.linalg.norm(g0))
    theta0 = math.atan2(g0[0], -g0[1])
    assert abs(theta0) > 0.5
    inertia_pivot = INERTIA + MASS * d**2
    reference = solve_ivp(lambda t, y: [y[1], -MASS * G * d * math.sin(y[0]) / inertia_pivot], (0.0, 2.0),
                          [theta0, 0.0], rtol=1e-12, atol=1e-12, dense_output=True)
    run = cmbs.simulate(model, t_end=2.0, dt=0.05, integrator="dop853", rtol=1e-11, atol=1e-12)
    angles = []
    for q in run.q:
        r = com_position(model, q) - pivot
        angles.append(math.atan2(r[0], -r[1]))
    np.testing.assert_allclose(angles, reference.sol(run.t)[0], atol=1e-7)
    assert np.ptp(angles) > 1.5        # it really swings


def test_the_further_point_stays_rigid_and_energy_is_conserved():
    """Distances I-J, I-K, J-K of a free-falling, spinning plate (no fixed point) stay constant to
    1e-9 and T + V to 1e-9 relative, while its points move by metres."""
    b = NaturalModelBuilder("free plate")
    for name, x, z in (("I", 0.0, 0.0), ("J", 0.5, 0.1), ("K", 0.2, 0.6)):
        b.add_point(name, x, z)
    b.add_body("plate", ["I", "J", "K"], mass=2.0, com=(0.25, 0.2), inertia=0.06)
    model = b.build()
    qd0 = cmbs.velocities(model, model.q0, 0.0, qd=np.array([1.0, 2.0, -3.0, 1.0, 0.5, 0.0]))
    run = cmbs.simulate(model, t_end=1.0, dt=0.01, qd0=qd0, integrator="dop853", rtol=1e-11, atol=1e-12)
    P = np.array([model.point_positions(q) for q in run.q])
    for a, c in ((0, 1), (0, 2), (1, 2)):
        lengths = np.linalg.norm(P[:, c] - P[:, a], axis=1)
        assert np.ptp(lengths) < 1e-9
    assert np.linalg.norm(P[-1, 2] - P[0, 2]) > 3.0
    energies = [model.energy(q, qd) for q, qd in zip(run.q, run.qd)]
    assert np.ptp(energies) < 1e-9 * max(abs(energies[0]), 1.0)


def test_mass_matrix_is_positive_definite_and_gives_the_rigid_kinetic_energy():
    """The further point K carries no mass of its own, yet M is positive definite (the term
    μ|B_K q̇|²), and on velocities that keep the body rigid ½ q̇ᵀ M q̇ is ½ m v_G² + ½ I_G ω²."""
    model = pivoted_plate()
    assert np.linalg.eigvalsh(model.mass_matrix(model.q0)).min() > 1e-3
    b = NaturalModelBuilder("free plate")
    for name, x, z in (("I", 0.0, 0.0), ("J", 0.5, 0.1), ("K", 0.2, 0.6)):
        b.add_point(name, x, z)
    b.add_body("plate", ["I", "J", "K"], mass=2.0, com=(0.25, -0.2), inertia=0.06)
    free = b.build()
    rng = np.random.default_rng(4)
    for _ in range(5):
        qd = cmbs.velocities(free, free.q0, 0.0, qd=rng.normal(size=free.n))
        P = dict(zip(free.point_names, free.point_positions(free.q0)))
        V = {name: qd[2 * k:2 * k + 2] for k, name in enumerate(free.point_names)}
        expected = rigid_body_kinetic_energy(2.0, np.linalg.norm(P["J"] - P["I"]), (0.25, -0.2), 0.06, P["I"],
                                             P["J"], V["I"], V["J"])
        assert free.kinetic_energy(free.q0, qd) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("name", list(FORMULATIONS))
def test_every_formulation_gives_the_closed_form_acceleration(name):
    """At rest, the pivoted plate's angular acceleration is -m g d sin θ / (I_G + m d²) under
    every formulation (Udwadia-Kalaba and the projection need M⁻¹: the further point's term)."""
    model = pivoted_plate()
    q, qd = model.q0, np.zeros(model.n)
    qdd = formulation(name).bind(model).accelerations(model.evaluate(q, qd, 0.0), q, qd, 0.0).qdd
    d, dd = q[2:4] - q[0:2], qdd[2:4] - qdd[0:2]
    alpha = (d[0] * dd[1] - d[1] * dd[0]) / (d @ d)
    r = com_position(model, q) - np.array([0.25, 0.1])
    expected = -MASS * G * r[0] / (INERTIA + MASS * (r @ r))   # m g d sin θ = m g r_x
    tolerance = 1e-5 if name == "penalty" else 1e-9
    assert alpha == pytest.approx(expected, rel=tolerance)


def test_constraint_derivatives_of_body_point_rows():
    """A and γ of the body point rows (and of a body joined to a segment at a further point)
    against finite differences along random smooth motions."""
    b = NaturalModelBuilder("linkage")
    b.add_point("O", 0.0, 0.0, fixed=True)
    b.add_point("A", 0.6, 0.2)
    b.add_point("B", 0.9, -0.3)
    b.add_point("C", 0.3, -0.4)
    b.add_point("D", 1.3, -0.5)
    b.add_segment("crank", "O", "A", mass=1.0, com=(0.3, 0.0), inertia=0.03)
    b.add_body("plate", ["A", "B", "C"], mass=1.5, com=(0.2, -0.1), inertia=0.02)
    b.add_segment("link", "C", "D", mass=0.5, com=(0.5, 0.0), inertia=0.04)
    model = b.build()
    assert [name for name in model.constraint_names if name.startswith("body")] == ["body plate: C.x",
                                                                                    "body plate: C.z"]
    check_constraint_derivatives(model, np.random.default_rng(8), samples=4)


def body_loads_model(frame):
    b = NaturalModelBuilder("loaded", gravity=(0.0, 0.0))
    for name, x, z in (("I", 0.1, 0.2), ("J", 0.6, 0.5), ("K", 0.2, 0.8)):
        b.add_point(name, x, z)
    b.add_body("plate", ["I", "J", "K"], mass=2.0, com=(0.25, 0.1), inertia=0.06)
    b.add_force("push", segment="plate", at=(0.4, -0.3), frame=frame, fx="1 + 0.5*t", fz=-2.0)
    b.add_moment("twist", segment="plate", moment="0.7*cos(t)")
    return b.build()


@pytest.mark.parametrize("frame", ["ground", "body"])
def test_segment_force_and_moment_are_their_virtual_work(frame):
    """Q = F·∂r_P/∂q + τ ∂θ/∂q at states off the constraints too, with r_P = r_I + (a e + b R90 e)
    scaled by the body length along d = r_J - r_I, θ = atan2(d_z, d_x), and F in the body frame
    turning with e = d/|d| (finite differences of those formulas, not of the model)."""
    model = body_loads_model(frame)
    length = math.hypot(0.5, 0.3)
    rng = np.random.default_rng(2)
    t = 0.8
    for _ in range(3):
        q = model.q0 + 0.05 * rng.normal(size=model.n)

        def point(q):
            ri, rj = q[0:2], q[2:4]
            d = (rj - ri) / length
            return ri + 0.4 * d - 0.3 * np.array([-d[1], d[0]])

        def angle(q):
            return math.atan2(q[3] - q[1], q[2] - q[0])

        h = 1e-6
        steps = np.eye(model.n) * h
        dr = np.array([(point(q + s) - point(q - s)) / (2 * h) for s in steps])        # (n, 2)
        dtheta = np.array([(angle(q + s) - angle(q - s)) / (2 * h) for s in steps])
        force = np.array([1 + 0.5 * t, -2.0])
        if frame == "body":
            e = (q[2:4] - q[0:2]) / np.linalg.norm(q[2:4] - q[0:2])
            force = force[0] * e + force[1] * np.array([-e[1], e[0]])
        expected = dr @ force + 0.7 * math.cos(t) * dtheta
        np.testing.assert_allclose(model.forces(q, np.zeros(model.n), t), expected, atol=1e-8)


def test_follower_force_and_moment_on_a_free_body_by_hand():
    """Weightless free plate at rest, a body-frame force at (0.4, -0.3) and a moment: a_G = F/m and
    α = ((p - c) × F_body + τ)/I_G (hand computation in the body frame); a body-frame force
    through the centre of mass keeps the plate from turning and accelerates it along its own
    axis: after 1 s r_G moved ½ (F/m) t²."""
    model = body_loads_model("body")
    q, qd, t = model.q0, np.zeros(model.n), 0.0
    qdd = formulation("lagrange").bind(model).accelerations(model.evaluate(q, qd, t), q, qd, t).qdd
    d = q[2:4] - q[0:2]
    e = d / np.linalg.norm(d)
    n = np.array([-e[1], e[0]])
    L = np.linalg.norm(d)
    a_i, a_j = qdd[0:2], qdd[2:4]
    a_g = a_i + (0.25 * (a_j - a_i) + 0.1 * np.array([-(a_j - a_i)[1], (a_j - a_i)[0]])) / L
    force_body = np.array([1.0, -2.0])
    np.testing.assert_allclose(a_g, (force_body[0] * e + force_body[1] * n) / 2.0, atol=1e-12)
    lever = np.array([0.4 - 0.25, -0.3 - 0.1])
    alpha = (d[0] * (a_j - a_i)[1] - d[1] * (a_j - a_i)[0]) / L**2
    torque = lever[0] * force_body[1] - lever[1] * force_body[0] + 0.7
    assert alpha == pytest.approx(torque / 0.06, rel=1e-12)

    b = NaturalModelBuilder("through com", gravity=(0.0, 0.0))
    for name, x, z in (("I", 0.1, 0.2), ("J", 0.6, 0.5), ("K", 0.2, 0.8)):
        b.add_point(name, x, z)
    b.add_body("plate", ["I", "J", "K"], mass=2.0, com=(0.25, 0.1), inertia=0.06)
    b.add_force("thrust", segment="plate", at=(0.25, 0.1), frame="body", fx=3.0, fz=1.0)
    straight = b.build()
    run = cmbs.simulate(straight, t_end=1.0, dt=0.1, integrator="dop853", rtol=1e-11, atol=1e-12)
    start, end = com_position(straight, run.q[0]), com_position(straight, run.q[-1])
    np.testing.assert_allclose(end - start, 0.5 * (3.0 * e + 1.0 * n) / 2.0, atol=1e-9)
    np.testing.assert_allclose(run.q[-1][2:4] - run.q[-1][0:2], d, atol=1e-9)        # no rotation


def test_moment_on_a_segment_moves_it_as_the_torque_on_its_absolute_angle():
    """A pendulum driven by T(t) = 2 sin 3t: as a moment on the segment, and as a torque on an
    absolute angle coordinate of the same segment (the existing entry): the same motion."""
    def pendulum(moment):
        b = NaturalModelBuilder("driven pendulum")
        b.add_point("O", 0.0, 0.0, fixed=True)
        b.add_point("P", 0.6, -0.8)
        b.add_segment("rod", "O", "P", mass=1.2, com=(0.4, 0.05), inertia=0.09)
        if moment:
            b.add_moment("drive", segment="rod", moment="2*sin(3*t)")
        else:
            b.add_angle("theta", segment="rod")
            b.add_torque("drive", angle="theta", torque="2*sin(3*t)")
        return b.build()

    by_moment, by_torque = pendulum(True), pendulum(False)
    runs = [cmbs.simulate(model, t_end=2.0, dt=0.05, integrator="dop853", rtol=1e-11, atol=1e-12)
            for model in (by_moment, by_torque)]
    np.testing.assert_allclose(runs[0].q[:, :2], runs[1].q[:, :2], atol=1e-8)
    assert np.ptp(runs[0].q[:, 0]) > 0.1
    assert by_moment.work_sources == ("moment 'drive'",)


def test_loads_are_work_sources_unless_zero():
    model = body_loads_model("body")
    assert model.work_sources == ("force 'push'", "moment 'twist'")
    b = NaturalModelBuilder("idle")
    b.add_point("O", 0.0, 0.0, fixed=True)
    b.add_point("P", 1.0, 0.0)
    b.add_segment("rod", "O", "P", mass=1.0, com=(0.5, 0.0), inertia=0.1)
    b.add_force("none", segment="rod", at=(0.5, 0.0), frame="body")
    b.add_moment("nothing", segment="rod", moment=0.0)
    assert b.build().work_sources == ()


def test_mass_fault_on_a_body_is_the_heavier_body():
    """cmbs.control.mass_fault scales a body's mass and inertia: the same accelerations as the
    body built with those values (M differs only by the further point's term, which does not
    act on rigid motions)."""
    faulty = mass_fault(pivoted_plate(), "plate", factor=1.5)
    b = NaturalModelBuilder("heavy")
    b.add_point("I", -0.3, -0.5)
    b.add_point("J", 0.1, -0.5)
    b.add_point("K", 0.25, 0.1, fixed=True)
    b.add_body("plate", ["I", "J", "K"], mass=1.5 * MASS, com=COM, inertia=1.5 * INERTIA)
    heavy = b.build()
    solve = formulation("lagrange")
    q = heavy.q0
    qd = cmbs.velocities(heavy, q, 0.0, qd=np.array([0.3, -0.2, 0.1, 0.4]))
    expected = solve.bind(heavy).accelerations(heavy.evaluate(q, qd, 0.0), q, qd, 0.0).qdd
    got = solve.bind(faulty).accelerations(faulty.evaluate(q, qd, 0.0), q, qd, 0.0).qdd
    np.testing.assert_allclose(got, expected, atol=1e-10)
    assert dict(heavy.segment_masses) == {"plate": pytest.approx(1.2)}


def test_local_positions_given_place_the_further_points():
    """With 'local' and 'length', the drawn positions are guesses: assembly puts K at (along,
    across) = (0.3, -0.4) of the frame I -> J, whatever its drawn position."""
    b = NaturalModelBuilder("drawn roughly")
    b.add_point("I", 0.0, 0.0, fixed=True)
    b.add_point("J", 0.0, -0.98)
    b.add_point("K", 0.35, -0.3)
    b.add_body("plate", ["I", "J", "K"], mass=1.0, com=(0.5, 0.0), inertia=0.1, length=1.0,
               local={"K": (0.3, -0.4)})
    model = b.build()
    q = cmbs.assemble(model)
    P = dict(zip(model.point_names, model.point_positions(q)))
    e = P["J"] - P["I"]
    assert np.linalg.norm(e) == pytest.approx(1.0, abs=1e-10)
    offset = P["K"] - P["I"]
    assert (offset @ e, e[0] * offset[1] - e[1] * offset[0]) == pytest.approx((0.3, -0.4), abs=1e-10)
    assert model.lines == ((0, 1), (1, 2), (2, 0))


@pytest.mark.parametrize("call, message", [
    (lambda b: b.add_body("t", ["A"], mass=1.0, com=(0, 0), inertia=1.0),
     r"bodies.t: a body needs at least two points \(its frame\), got \['A'\]"),
    (lambda b: b.add_body("t", "ABC", mass=1.0, com=(0, 0), inertia=1.0),
     r"bodies.t: points must be a list of point names, got 'ABC'"),
    (lambda b: b.add_body("t", ["A", "B", "A"], mass=1.0, com=(0, 0), inertia=1.0),
     r"bodies.t: point\(s\) 'A' listed twice"),
    (lambda b: b.add_body("t", ["A", "B", "C"], mass=-1.0, com=(0, 0), inertia=1.0),
     r"bodies.t: mass must be >= 0, got -1.0"),
    (lambda b: b.add_body("t", ["A", "B", "C"], mass=1.0, com=(0, 0), inertia=-1.0),
     r"bodies.t: inertia must be >= 0, got -1.0"),
    (lambda b: b.add_body("t", ["A", "B", "C"], mass=1.0),
     r"bodies.t: a body with mass needs 'com'"),
    (lambda b: b.add_body("t", ["A", "B", "C"], mass=1.0, com=(0, 0), inertia=1.0, local={"A": (0, 0)}),
     r"bodies.t: local is for the body's further points \(C\), not 'A'"),
    (lambda b: b.add_body("rod", ["A", "B", "C"], mass=1.0, com=(0, 0), inertia=1.0),
     r"bodies.rod: name 'rod' is already a segment"),
    (lambda b: b.add_force("f", segment="rod", at=(0.1, 0.0), frame="local"),
     r"forces.f: frame must be one of 'ground', 'body', got 'local'"),
    (lambda b: b.add_force("f", point="A", segment="rod", at=(0.1, 0.0)),
     r"forces.f: give either 'point' \(a basic point, ground frame\) or 'segment' and 'at', not both"),
    (lambda b: b.add_force("f", point="B", frame="body"),
     r"forces.f: a force at a basic point is in the ground frame, got frame='body'; for the frame of a segment "
     r"give 'segment' and 'at' instead of 'point'"),
    (lambda b: b.add_force("f", segment="rod"),
     r"forces.f: a force on a segment needs 'segment' \(a name\) and 'at'"),
    (lambda b: b.add_force("f", fx=1.0),
     r"forces.f: give 'point' \(a basic point\), or 'segment' and 'at'"),
])
def test_builder_rejects_bad_bodies_and_loads(call, message):
    b = NaturalModelBuilder("bad")
    for name in "ABC":
        b.add_point(name, float(ord(name) - 65), 0.0)
    b.add_segment("rod", "A", "B", mass=1.0, com=(0.5, 0.0), inertia=0.1)
    with pytest.raises(ModelError, match=message):
        call(b)


@pytest.mark.parametrize("call, message", [
    (lambda b: b.add_body("t", ["A", "B", "Q"], mass=1.0, com=(0, 0), inertia=1.0),
     r"bodies.t: unknown point 'Q'"),
    (lambda b: b.add_force("f", segment="plat", at=(0.1, 0.0)), r"forces.f: unknown segment 'plat'"),
    (lambda b: b.add_moment("m", segment="plat", moment=1.0), r"moments.m: unknown segment 'plat'"),
    (lambda b: b.add_body("t", ["A", "D", "C"], mass=1.0, com=(0, 0), inertia=1.0),
     r"bodies.t: its points 'A' and 'D' coincide: length is 0"),
    (lambda b: b.add_body("t", ["A", "D", "C"], mass=1.0, com=(0, 0), inertia=1.0, length=1.0),
     r"bodies.t: its points 'A' and 'D' are at the same initial position, so the frame that places 'C' is "
     r"undefined: give local.C"),
])
def test_build_rejects_bad_names_and_frames(call, message):
    b = NaturalModelBuilder("bad")
    for name, x in (("A", 0.0), ("B", 1.0), ("C", 2.0), ("D", 0.0)):
        b.add_point(name, x, 0.0)
    b.add_segment("rod", "A", "B", mass=1.0, com=(0.5, 0.0), inertia=0.1)
    call(b)
    with pytest.raises(ModelError, match=message):
        b.build()


BODY_FILE = """
[points]
O = { x = 0.0, z = 0.0, fixed = true }
J = { x = 0.4, z = -0.1 }
K = { x = 0.1, z = -0.5 }

[bodies.plate]
points = ["O", "J", "K"]
mass = 0.9
com = [0.2, -0.15]
inertia = 0.011

[forces.push]
segment = "plate"
at = [0.3, -0.2]
frame = "body"
fx = "0.5*sin(t)"
fz = 0.25

[moments.twist]
segment = "plate"
moment = { t = [0.0, 1.0, 2.0], value = [0.0, 0.2, 0.0], interpolation = "linear" }
"""


def test_file_bodies_and_loads_equal_the_builder(tmp_path):
    path = tmp_path / "plate.toml"
    path.write_text(BODY_FILE)
    from_file = cmbs.load(path)
    b = NaturalModelBuilder("plate")
    b.add_point("O", 0.0, 0.0, fixed=True)
    b.add_point("J", 0.4, -0.1)
    b.add_point("K", 0.1, -0.5)
    b.add_body("plate", ["O", "J", "K"], mass=0.9, com=(0.2, -0.15), inertia=0.011)
    b.add_force("push", segment="plate", at=(0.3, -0.2), frame="body", fx="0.5*sin(t)", fz=0.25)
    b.add_moment("twist", segment="plate", moment=cmbs.model.drivers.Table(np.array([0.0, 1.0, 2.0]),
                                                                           np.array([0.0, 0.2, 0.0]), "linear"))
    built = b.build()
    assert from_file.constraint_names == built.constraint_names
    assert from_file.lines == built.lines and from_file.work_sources == built.work_sources
    rng = np.random.default_rng(1)
    for t in (0.3, 1.4):
        q, qd = from_file.q0 + 0.05 * rng.normal(size=built.n), rng.normal(size=built.n)
        a, c = from_file.evaluate(q, qd, t), built.evaluate(q, qd, t)
        for term in ("M", "Q", "phi", "A", "gamma"):
            np.testing.assert_array_equal(getattr(a, term), getattr(c, term))
    assert cmbs.constraint_report(from_file, from_file.q0).dof == 1


@pytest.mark.parametrize("change, message", [
    (('points = ["O", "J", "K"]', 'points = ["O"]'),
     r"plate\.toml: bodies.plate: a body needs at least two points \(its frame\), got \['O'\]"),
    (('points = ["O", "J", "K"]', 'points = ["O", "J", "X"]'), r"plate\.toml: bodies.plate: unknown point 'X'"),
    (('points = ["O", "J", "K"]', 'points = "O"'), r"plate\.toml: bodies.plate: points must be a list of point"),
    (("mass = 0.9", "mass = -0.9"), r"plate\.toml: bodies.plate: mass must be >= 0, got -0.9"),
    (("inertia = 0.011", "inertia = -1"), r"plate\.toml: bodies.plate: inertia must be >= 0, got -1"),
    (("inertia = 0.011", "inertia = 0.011\nlocal = { K = [0.1] }"),
     r"plate\.toml: bodies.plate.local: K must be a list of two finite numbers, got \[0.1\]"),
    (("inertia = 0.011", "inertia = 0.011\nlocal = { J = [0.1, 0.0] }"),
     r"plate\.toml: bodies.plate: local is for the body's further points \(K\), not 'J'"),
    (("inertia = 0.011", "inertia = 0.011\nlocal = 3"),
     r"plate\.toml: bodies.plate.local: expected a table of keys, got 3"),
    (('frame = "body"', 'frame = "local"'),
     r"plate\.toml: forces.push: frame must be one of 'ground', 'body', got 'local'"),
    (("at = [0.3, -0.2]", "at = [0.3]"), r"plate\.toml: forces.push: at must be a list of two finite numbers"),
    (('segment = "plate"\nat', 'segment = "plat"\nat'), r"plate\.toml: forces.push: unknown segment 'plat'"),
    (('moment = {', 'momnet = {'), r"plate\.toml: moments.twist: unknown key\(s\) 'momnet'"),
    (('fx = "0.5*sin(t)"', 'fx = "0.5*sin(t"'), r"plate\.toml: forces.push.fx: missing '\)'"),
])
def test_file_errors_name_file_entry_and_value(tmp_path, change, message):
    old, new = change
    assert old in BODY_FILE
    path = tmp_path / "plate.toml"
    path.write_text(BODY_FILE.replace(old, new, 1))
    with pytest.raises(ModelError, match=message) as error:
        cmbs.load(path)
    assert "\n" not in str(error.value)


def test_assembly_failure_in_a_body_names_the_body(tmp_path):
    """A pin that cannot close inside a body's rows is reported as bodies.NAME (not segments)."""
    text = BODY_FILE.replace('K = { x = 0.1, z = -0.5 }', 'K = { x = 0.1, z = -0.5 }\nW = { x = 3.0, z = 0.0, '
                                                           'fixed = true }')
    text = text.replace('points = ["O", "J", "K"]', 'points = ["O", "J", "K", "W"]\nlength = 0.5\n'
                                                    'local = { W = [0.0, 0.3] }')
    path = tmp_path / "plate.toml"
    path.write_text(text)
    with pytest.raises(ModelError, match=r"plate\.toml: bodies\.plate: cannot be assembled"):
        cmbs.load(path)


def test_undriven_model_still_evaluates_segment_forces_and_moments():
    """Model.without_drivers drops the time functions only the drivers used, not those of the
    segment forces and moments: its Q equals that of the same model built without the driver."""
    def build(driven):
        b = NaturalModelBuilder("loaded", gravity=(0.0, 0.0))
        for name, x, z in (("I", 0.1, 0.2), ("J", 0.6, 0.5), ("K", 0.2, 0.8)):
            b.add_point(name, x, z)
        b.add_body("plate", ["I", "J", "K"], mass=2.0, com=(0.25, 0.1), inertia=0.06)
        b.add_force("push", segment="plate", at=(0.4, -0.3), frame="body", fx="1 + 0.5*t", fz=-2.0)
        b.add_moment("twist", segment="plate", moment="0.7*cos(t)")
        if driven:
            b.add_driver("K.x", "0.2 + 0.1*sin(t)")
        return b.build()

    undriven, plain = build(True).without_drivers(), build(False)
    q = plain.q0 + 0.01
    for t in (0.0, 0.7):
        Q = undriven.evaluate(q, np.zeros(plain.n), t).Q
        np.testing.assert_array_equal(Q, plain.evaluate(q, np.zeros(plain.n), t).Q)
        assert np.abs(Q).max() > 0.5
