"""Joint reactions of spatial natural-coordinate models (cmbs.inverse.spatial_reactions) against
the Newton-Euler equations of each body, Newton's third law, and the planar reactions of a planar
mechanism built in space."""

import numpy as np
import pytest

import cmbs
from cmbs.inverse.reactions import joint_reactions
from cmbs.inverse.spatial_reactions import spatial_reactions
from cmbs.model.spatial import SpatialModelBuilder
from helpers import four_bar_builders

G = 9.81
GRAVITY = np.array([0.3, -1.0, -G])
BODIES = {   # name: (mass, com, inertia about it), ground axes at the start
    "arm": (2.0, np.array([0.3, 0.05, 0.1]), np.array([[0.02, 0.003, -0.001], [0.003, 0.03, 0.002],
                                                        [-0.001, 0.002, 0.04]])),
    "link": (1.2, np.array([0.6, 0.3, 0.05]), np.array([[0.01, -0.002, 0.0], [-0.002, 0.015, 0.001],
                                                         [0.0, 0.001, 0.012]])),
}
MOMENT = np.array([0.2, -0.1, 0.3])      # on the link, along its axes
FORCE = np.array([1.0, 0.5, -2.0])       # at the link's point Q, ground axes


def _two_revolutes():
    """An arm turning about the ground axis z at O; a link on it by a revolute joint (the shared
    point P and the shared axis w, non-orthogonal bases); a moment on the link, a force at Q."""
    b = SpatialModelBuilder("two-revolutes", gravity=tuple(GRAVITY))
    b.add_point("O", (0.0, 0.0, 0.0), fixed=True)
    b.add_vector("z", (0.0, 0.0, 1.0), fixed=True)
    b.add_vector("u", (1.0, 0.2, 0.0))
    b.add_point("P", (0.5, 0.4, 0.2))
    b.add_vector("w", (0.3, 1.0, 0.4))
    b.add_point("Q", (0.8, 0.5, 0.0))
    b.add_vector("n", (0.2, -0.3, 1.0))
    b.add_body("arm", origin="O", basis=["z", "u", "P"], mass=BODIES["arm"][0], com=BODIES["arm"][1],
               inertia=BODIES["arm"][2], vectors=["w"])
    b.add_body("link", origin="P", basis=["w", "Q", "n"], mass=BODIES["link"][0], com=BODIES["link"][1],
               inertia=BODIES["link"][2])
    b.add_moment("twist", body="link", moment=tuple(MOMENT), frame="body")
    b.add_force("pull", point="Q", force=tuple(FORCE))
    return b.build()


def _state(model, seed):
    """A consistent state: q on the constraints, q̇ in the null space of A, and q̈, λ of
    M q̈ + Aᵀλ = Q, A q̈ = γ solved here by numpy."""
    rng = np.random.default_rng(seed)
    q = cmbs.assemble(model, model.q0)
    A = model.jacobian(q)
    null = np.linalg.svd(A)[2][np.linalg.matrix_rank(A):].T
    qd = null @ rng.normal(size=null.shape[1])
    terms = model.evaluate(q, qd, 0.0)
    kkt = np.block([[terms.M, terms.A.T], [terms.A, np.zeros((model.m, model.m))]])
    solution = np.linalg.solve(kkt, np.concatenate([terms.Q, terms.gamma]))
    return q, qd, solution[:model.n], solution[model.n:]




@pytest.mark.parametrize("seed", [1, 2, 3])
def test_each_body_obeys_newton_and_euler_under_its_reactions(seed):
    """Σ F(b, P) + m g (+ the force at Q on the link) = m a_G and, about G,
    Σ (P - G) × F(b, P) + Σ C(b, u) + applied moment = I_G α + ω × I_G ω, with ω, α from the
    body's rotation R = X X₀⁻¹; Newton's third law at the shared point P."""
    model = _two_revolutes()
    q, qd, qdd, lam = _state(model, seed)
    reactions = spatial_reactions(model, q, qd, qdd, lam)
    x0 = {name: model.q0[model.coordinate_index(f"{name}.x"):][:3] for name in ("u", "P", "w", "Q", "n")}
    x0.update(O=np.zeros(3), z=np.array([0.0, 0.0, 1.0]))

    def element(name, state):
        if name == "O":
            return np.zeros(3)
        if name == "z":
            return np.array([0.0, 0.0, 1.0]) if state is q else np.zeros(3)
        return state[model.coordinate_index(f"{name}.x"):][:3]

    bases = {"arm": ("O", [("z", None), ("u", None), ("P", "O")]),
             "link": ("P", [("w", None), ("Q", "P"), ("n", None)])}
    for body, (origin, basis) in bases.items():
        mass, com, inertia = BODIES[body]
        X0 = np.column_stack([x0[h] - (x0[t] if t else 0.0) for h, t in basis])
        X, Xd, Xdd = (np.column_stack([element(h, s) - (element(t, s) if t else 0.0) for h, t in basis])
                      for s in (q, qd, qdd))
        R, Rd, Rdd = X @ np.linalg.inv(X0), Xd @ np.linalg.inv(X0), Xdd @ np.linalg.inv(X0)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-10)
        Omega = Rd @ R.T
        omega = np.array([Omega[2, 1], Omega[0, 2], Omega[1, 0]])
        dOmega = Rdd @ R.T + Rd @ Rd.T
        alpha = 0.5 * np.array([dOmega[2, 1] - dOmega[1, 2], dOmega[0, 2] - dOmega[2, 0], dOmega[1, 0] - dOmega[0, 1]])
        c = com - x0[origin]
        r_G = element(origin, q) + R @ c
        a_G = element(origin, qdd) + Rdd @ c
        I_G = R @ inertia @ R.T
        points = {point: F for (name, point), F in reactions["forces"].items() if name == body}
        couples = {vector: C for (name, vector), C in reactions["vector_couples"].items() if name == body}
        applied_moment = R @ MOMENT if body == "link" else np.zeros(3)
        total = sum(points.values()) + mass * GRAVITY
        np.testing.assert_allclose(total, mass * a_G, atol=1e-9)
        moment = sum(np.cross(element(p, q) - r_G, F) for p, F in points.items()) + sum(couples.values())
        np.testing.assert_allclose(moment + applied_moment, I_G @ alpha + np.cross(omega, I_G @ omega), atol=1e-9)
        assert set(points) == {p for p in ("O", "P", "Q") if p == origin or any(h == p for h, _ in basis)}
    # the force at Q is the applied force: nothing else acts there
    np.testing.assert_allclose(reactions["forces"][("link", "Q")], FORCE, atol=1e-9)
    np.testing.assert_allclose(reactions["forces"][("arm", "P")] + reactions["forces"][("link", "P")], 0.0,
                               atol=1e-9)
    # the revolute joints transmit no couple about their axes
    for (body, vector), C in reactions["vector_couples"].items():
        if vector in ("z", "w"):
            axis = element(vector, q) if vector == "w" else np.array([0.0, 0.0, 1.0])
            assert abs(C @ axis) < 1e-9


def test_a_planar_four_bar_in_space_has_the_planar_pin_forces():
    """The driven four-bar O-A-B-C in the plane y = 0, planar and in space (rods with spherical
    ends, the crank and rocker kept in the plane by products with y): inverse dynamics of the
    same motion, and each rod's forces at its ends equal the planar segment's (x, z), with no y."""
    planar, spatial = four_bar_builders()
    for builder in (planar, spatial):
        builder.add_driver("A.x", "-0.5*sin(t)")
    planar, spatial = planar.build(), spatial.build()
    times = np.linspace(0.0, 1.0, 6)
    flat = cmbs.inverse_dynamics(planar, times).motion
    space = cmbs.inverse_dynamics(spatial, times).motion
    checked = 0
    for k in range(times.size):
        expected = joint_reactions(planar, flat.q[k], flat.qd[k], flat.qdd[k], flat.extras["lam"][k])["forces"]
        found = spatial_reactions(spatial, space.q[k], space.qd[k], space.qdd[k], space.extras["lam"][k])["forces"]
        for (bar, point), F in expected.items():
            np.testing.assert_allclose(found[(bar, point)][[0, 2]], F, atol=1e-9)
            assert abs(found[(bar, point)][1]) < 1e-9
            checked += 1
    assert checked == 6 * times.size


def test_cli_inverse_reports_the_reactions_of_a_spatial_mechanism(tmp_path, capsys):
    """`cmbs inverse ... --reactions` on the spatial slider-crank driven at 6 rad/s: the forces
    at the points, the couples through the rod's unit vectors and the slide's force, in the
    output and in the result file."""
    from cmbs.cli import main

    out = tmp_path / "reactions.npz"
    assert main(["inverse", "spatial-slider-crank", "--t-end", "0.5", "--dt", "0.1", "--motion", "crank_angle = 6*t",
                 "--reactions", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    for label in ("reaction rod@B", "reaction crank@A", "couple rod@e1", "slider force x_slider",
                  "joint torque crank_angle"):
        assert label in printed
    saved = cmbs.Trajectory.load(out)
    assert saved.extras["couple rod@e1"].shape == (6, 3)
