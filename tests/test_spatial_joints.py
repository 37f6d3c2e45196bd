"""Joint kinds of spatial natural coordinates (cmbs.model.spatial, module docstring's table):
each has the freedoms of the joint, and moves as closed-form solutions say."""

import numpy as np
import pytest

import cmbs
from cmbs.model.spatial import SpatialModelBuilder

G = 9.81
INERTIA = np.diag([0.02, 0.03, 0.04])


def _ground(b: SpatialModelBuilder) -> None:
    b.add_point("O", (0.0, 0.0, 0.0), fixed=True)
    for name, axis in (("ex", (1, 0, 0)), ("ey", (0, 1, 0)), ("ez", (0, 0, 1))):
        b.add_vector(name, axis, fixed=True)


def _free_body(b: SpatialModelBuilder, origin_fixed: bool = False) -> None:
    """Body B at origin P = O (fixed: a spherical joint) with free unit vectors u, v, w."""
    if not origin_fixed:
        b.add_point("P", (0.0, 0.0, 0.0))
    b.add_vector("u", (1, 0, 0))
    b.add_vector("v", (0, 1, 0))
    b.add_vector("w", (0, 0, 1))
    b.add_body("B", origin="O" if origin_fixed else "P", basis=["u", "v", "w"], mass=1.0, com=(0.1, 0.2, 0.3),
               inertia=INERTIA)


def _spherical(b):
    _free_body(b, origin_fixed=True)


def _revolute(b):
    b.add_vector("u", (1, 0, 0))
    b.add_vector("v", (0, 1, 0))
    b.add_body("B", origin="O", basis=["ez", "u", "v"], mass=1.0, com=(0.1, 0.2, 0.3), inertia=INERTIA)


def _universal(b):
    _free_body(b, origin_fixed=True)
    b.add_dot("cross", "ez", "u", value=0.0)


def _cylindrical(b):
    b.add_point("P", (0.0, 0.0, 0.0))
    b.add_vector("u", (1, 0, 0))
    b.add_vector("v", (0, 1, 0))
    b.add_body("B", origin="P", basis=["ez", "u", "v"], mass=1.0, com=(0.1, 0.2, 0.3), inertia=INERTIA)
    b.add_slider("s", point="P", origin="O", axis="ez")


def _prismatic(b):
    b.add_point("P", (0.0, 0.0, 0.0))
    b.add_body("B", origin="P", basis=["ez", "ex", "ey"], mass=1.0, com=(0.1, 0.2, 0.3), inertia=INERTIA)
    b.add_slider("s", point="P", origin="O", axis="ez")


def _planar(b):
    b.add_point("P", (0.0, 0.0, 0.0))
    b.add_vector("u", (1, 0, 0))
    b.add_vector("v", (0, 1, 0))
    b.add_body("B", origin="P", basis=["ez", "u", "v"], mass=1.0, com=(0.1, 0.2, 0.3), inertia=INERTIA)
    b.add_dot("in plane", ("P", "O"), "ez", value=0.0)


def _point_on_line(b):
    _free_body(b)
    b.add_slider("s", point="P", origin="O", axis="ex")


def _point_in_plane(b):
    _free_body(b)
    b.add_dot("in plane", ("P", "O"), "ez", value=0.0)


def _weld(b):
    _free_body(b, origin_fixed=True)
    b.add_body("C", origin="O", basis=["u", "v", "w"], mass=2.0, com=(-0.1, 0.0, 0.2), inertia=2 * INERTIA)


@pytest.mark.parametrize("joint, freedoms", [
    (_spherical, 3), (_revolute, 1), (_universal, 2), (_cylindrical, 2), (_prismatic, 1), (_planar, 3),
    (_point_on_line, 4), (_point_in_plane, 5), (_weld, 3)])
def test_each_joint_kind_leaves_the_freedoms_of_the_joint(joint, freedoms):
    """A body joined to the ground (the weld: two bodies welded, on a spherical joint): the
    coordinates less the rank of A are the joint's degrees of freedom, and every row is
    independent (a product shared by two bodies is one row)."""
    b = SpatialModelBuilder(joint.__name__.strip("_"))
    _ground(b)
    joint(b)
    model = b.build()
    A = model.jacobian(model.q0)
    rank = np.linalg.matrix_rank(A, tol=1e-10)
    assert model.n - rank == freedoms
    assert rank == A.shape[0]


def _bead_on_spinning_rod(omega: float, r0: float, rate0: float):
    """A rod body A turning about the ground axis z at the driven rate ω; a body B (mass at its
    origin S) slides along it by a prismatic joint: A and B share the unit vectors u (along the
    rod) and v, and S is on the line through O along u."""
    b = SpatialModelBuilder("bead", gravity=(0.0, 0.0, -G))
    _ground(b)
    b.add_vector("u", (1, 0, 0))
    b.add_vector("v", (0, 1, 0))
    b.add_body("rod", origin="O", basis=["ez", "u", "v"], mass=0.5, com=(0.3, 0.0, 0.0),
               inertia=np.diag([1e-4, 0.015, 0.015]))
    b.add_angle("turn", reference="ex", vector="u", axis="ez")
    b.add_driver("turn", f"{omega}*t")
    b.add_point("S", (r0, 0.0, 0.0))
    b.add_point("Q", (r0, 0.0, 0.1))
    b.add_body("bead", origin="S", basis=["u", "v", "Q"], mass=0.2, com=(r0, 0.0, 0.0), inertia=np.diag([1e-4] * 3))
    b.add_slider("s", point="S", origin="O", axis="u")
    model = b.build()
    qd = np.zeros(model.n)
    for name, value in (("u.y", omega), ("v.x", -omega), ("turn", omega), ("S.x", rate0), ("S.y", omega * r0),
                        ("Q.x", rate0), ("Q.y", omega * r0), ("s", rate0)):
        qd[model.coordinate_index(name)] = value
    return model, qd


@pytest.mark.parametrize("formulation", ["lagrange", "projection"])
def test_a_prismatic_joint_between_moving_bodies_slides_a_bead_along_a_spinning_rod(formulation):
    """Bead on a rod spinning at constant ω: r̈ = ω² r, so r(t) = r₀ cosh ωt + (ṙ₀/ω) sinh ωt,
    while the bead keeps its orientation on the rod (Q stays above S)."""
    omega, r0, rate0 = 2.0, 0.2, 0.1
    model, qd = _bead_on_spinning_rod(omega, r0, rate0)
    assert np.abs(model.jacobian(model.q0) @ qd - (-model.evaluate(model.q0, qd, 0.0).phi_t)).max() < 1e-12
    run = cmbs.simulate(model, t_end=1.0, dt=0.05, qd0=qd, formulation=formulation, integrator="dop853",
                        rtol=1e-11, atol=1e-12)
    assert run.info["status"] == "success"
    r = r0 * np.cosh(omega * run.t) + rate0 / omega * np.sinh(omega * run.t)
    np.testing.assert_allclose(run["s"], r, rtol=1e-8)
    np.testing.assert_allclose(np.hypot(run["S.x"], run["S.y"]), r, rtol=1e-8)
    np.testing.assert_allclose(np.arctan2(run["S.y"], run["S.x"]), omega * run.t, atol=1e-8)
    np.testing.assert_allclose(run["Q.z"] - run["S.z"], 0.1, atol=1e-9)


def test_a_cylindrical_joint_slides_under_gravity_and_keeps_its_spin():
    """A body on a vertical cylindrical joint (shared ground axis z, its origin sliding on it)
    falls freely along the axis, s = -½ g t², and spins at its constant start rate about it."""
    b = SpatialModelBuilder("cylinder", gravity=(0.0, 0.0, -G))
    _ground(b)
    _cylindrical(b)
    b.add_angle("spin", reference="ex", vector="u", axis="ez")
    model = b.build()
    spin = 3.0
    qd = np.zeros(model.n)
    for name, value in (("u.y", spin), ("v.x", -spin), ("spin", spin)):
        qd[model.coordinate_index(name)] = value
    run = cmbs.simulate(model, t_end=1.0, dt=0.05, qd0=qd, integrator="dop853", rtol=1e-11, atol=1e-12)
    assert run.info["status"] == "success"
    np.testing.assert_allclose(run["s"], -0.5 * G * run.t**2, atol=1e-9)
    np.testing.assert_allclose(run["P.z"], -0.5 * G * run.t**2, atol=1e-9)
    np.testing.assert_allclose(np.unwrap(run["spin"]), spin * run.t, atol=1e-8)


@pytest.mark.parametrize("formulation", ["projection", "matrix-r"])
def test_the_library_slider_crank_built_in_space_follows_its_planar_branch(formulation):
    """Aghili's slider-crank (cmbs.load("slider-crank", gravity=9.81): equal 1 m, 1 kg crank and
    rod, massless slider on the x axis) in the plane y = 0 of space: a rod O-A kept across the
    ground axis y, a rod A-C, and C on the x axis by a slide.  Starting at 45°, 2 rad/s, the crank
    reaches the singular position 90° at 0.83 s; on the branch θ2 = -2θ1 its angle follows the
    reduced equation (cmbs.library.mechanisms.slider_crank_branch) to 1e-10 rad with RK4 at 1 ms,
    as the planar model does (tests/test_dynamics.py)."""
    from cmbs.library.mechanisms import slider_crank_branch

    theta, omega = np.radians(45.0), 2.0
    b = SpatialModelBuilder("slider-crank-3d", gravity=(0.0, 0.0, -G))
    b.add_point("O", (0.0, 0.0, 0.0), fixed=True)
    b.add_vector("y", (0.0, 1.0, 0.0), fixed=True)
    b.add_vector("x", (1.0, 0.0, 0.0), fixed=True)
    b.add_point("A", (np.cos(theta), 0.0, np.sin(theta)))
    b.add_point("C", (2.0 * np.cos(theta), 0.0, 0.0))
    b.add_rod("crank", "O", "A", mass=1.0, inertia=1.0 / 12.0)
    b.add_rod("rod", "A", "C", mass=1.0, inertia=1.0 / 12.0)
    b.add_dot("crank in plane", ("A", "O"), "y", value=0.0)
    b.add_slider("slider", point="C", origin="O", axis="x")
    model = b.build()
    qd = np.zeros(model.n)
    for name, value in (("A.x", -omega * np.sin(theta)), ("A.z", omega * np.cos(theta)),
                        ("C.x", -2.0 * omega * np.sin(theta)), ("slider", -2.0 * omega * np.sin(theta))):
        qd[model.coordinate_index(name)] = value
    run = cmbs.simulate(model, t_end=1.0, dt=1e-3, qd0=qd, formulation=formulation, integrator="rk4")
    assert run.info["status"] == "success"
    rows = np.searchsorted(run.t, np.array([0.25, 0.5, 0.75, 0.82, 0.84, 1.0]) - 1e-9)
    angle, _ = slider_crank_branch(run.t[rows], gravity=G)
    crank = np.arctan2(run["A.z"], run["A.x"])[rows]
    assert crank[3] < np.pi / 2 < crank[4]
    np.testing.assert_allclose(crank, angle, rtol=0, atol=1e-10)
    np.testing.assert_allclose(run["slider"][rows], 2.0 * np.cos(angle), rtol=0, atol=1e-10)
