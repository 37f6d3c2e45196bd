"""Spatial natural coordinates (cmbs.model.spatial) against independent references: rigid-body
kinetic energy and gravity power, finite differences of Φ and A, the spherical pendulum in
spherical coordinates, the heavy symmetric top in Euler angles, and the planar four-bar."""

import numpy as np
import pytest
from scipy.integrate import simpson, solve_ivp

import cmbs
from cmbs.errors import ModelError
from cmbs.model.drivers import Table
from cmbs.model.spatial import SpatialModelBuilder
from helpers import four_bar_builders

G = 9.81


def _random_rotation(rng):
    Q, R = np.linalg.qr(rng.normal(size=(3, 3)))
    return Q * np.sign(np.diag(R))


def _rigid_velocities(model, origin, v_origin, omega):
    """q̇ of the rigid motion (velocity of ``origin``, angular velocity ω) of every element."""
    q = model.q0
    qd = np.zeros(model.n)
    o = model.q0[model.coordinate_index(f"{origin}.x"):][:3]
    for k in range(0, model.n, 3):
        position = q[k:k + 3]
        qd[k:k + 3] = (np.cross(omega, position) if model.coordinate_kinds[k] == "direction"
                       else v_origin + np.cross(omega, position - o))
    return qd


def _general_body(rng):
    """One body located by O, a further point P and two unit vectors u, w (not orthogonal), with a
    random centre of mass and inertia tensor."""
    b = SpatialModelBuilder("body", gravity=(0.3, -1.2, -G))
    b.add_point("O", rng.normal(size=3))
    b.add_point("P", rng.normal(size=3))
    b.add_vector("u", rng.normal(size=3))
    b.add_vector("w", rng.normal(size=3))
    moments = np.array([2.0, 3.0, 4.0])
    R = _random_rotation(rng)
    inertia = R @ np.diag(moments) @ R.T
    com = rng.normal(size=3)
    b.add_body("B", origin="O", basis=["P", "u", "w"], mass=2.5, com=com, inertia=inertia)
    return b.build(), 2.5, com, inertia


def test_body_kinetic_energy_and_gravity_power_are_the_rigid_body_formulas():
    """½ q̇ᵀ M q̇ = ½ m v_G² + ½ ωᵀ I_G ω and Qᵀ q̇ = m g·v_G for random rigid motions; A q̇ = 0."""
    rng = np.random.default_rng(3)
    model, mass, com, inertia = _general_body(rng)
    o = model.q0[:3]
    gravity = np.array(model.parameters["gravity"])
    terms = model.evaluate(model.q0, np.zeros(model.n))
    for _ in range(5):
        v_origin, omega = rng.normal(size=3), rng.normal(size=3)
        qd = _rigid_velocities(model, "O", v_origin, omega)
        v_com = v_origin + np.cross(omega, com - o)
        expected = 0.5 * mass * v_com @ v_com + 0.5 * omega @ inertia @ omega
        assert model.kinetic_energy(model.q0, qd) == pytest.approx(expected, rel=1e-12)
        assert terms.Q @ qd == pytest.approx(mass * gravity @ v_com, rel=1e-12)
        np.testing.assert_allclose(terms.A @ qd, 0.0, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(terms.M) > 0.0)


def _kitchen_sink():
    """Every element, body, row and load kind, with a spring."""
    b = SpatialModelBuilder("kitchen", gravity=(0.0, -G, 0.0))
    b.add_point("O", (0.0, 0.0, 0.0), fixed=True)
    b.add_vector("z", (0.0, 0.0, 1.0), fixed=True)
    b.add_point("A", (0.4, 0.1, 0.0))
    b.add_vector("u", (1.0, 0.2, 0.1))
    b.add_vector("v", (0.1, 1.0, -0.3))
    b.add_point("K", (0.3, 0.5, 0.2))
    b.add_vector("n", (0.3, -0.2, 1.0))
    b.add_vector("h", (0.6, 0.8, 0.0))
    b.add_point("B", (1.2, 0.3, 0.4))
    b.add_point("C", (1.0, -0.6, 0.9), mass=0.7)
    b.add_body("crank", origin="A", basis=["u", "v", "B"], mass=1.5, com=(0.7, 0.2, 0.2),
               inertia=np.diag([0.02, 0.03, 0.04]), points=["K"], vectors=["n", "h"])
    b.add_rod("link", "B", "C", mass=0.8, com=0.4, inertia=0.01)
    b.add_distance("tether", "O", "A")
    b.add_dot("plane", ("A", "O"), "z")
    b.add_dot("skew", "u", ("C", "B"))
    b.add_spring("spring", "O", "C", stiffness=40.0, rest_length=0.5)
    b.add_force("push", point="K", force=(1.0, -2.0, 0.5))
    b.add_angle("turn", reference=("A", "O"), vector="h", axis="z")
    b.add_point("S", np.array([0.3, 0.5, 0.2]) + 0.25 * np.array([0.3, -0.2, 1.0]) / np.sqrt(1.13), mass=0.3)
    b.add_slider("slide", point="S", origin="K", axis="n")
    b.add_driver("turn", "0.3 + 0.5*sin(2*t)", name="sway")
    b.add_rotational_spring("twist", angle="turn", stiffness=3.0, rest_angle=0.1)
    return b.build()


def test_jacobian_gamma_and_spring_force_match_finite_differences():
    """Every row kind (dot, linear, angle, distance, slide, driver): A = Φ_q, Φ_t and γ = -(Ȧ q̇) - Φ_tt by central
    differences at a random state and time; the conservative forces (gravity, the spring, the
    rotational spring) are -∇V."""
    model = _kitchen_sink()
    rng = np.random.default_rng(5)
    q = model.q0 + 0.05 * rng.normal(size=model.n)
    qd = rng.normal(size=model.n)
    t, h = 0.37, 1e-6
    terms = model.evaluate(q, qd, t)
    numeric = np.column_stack([(model.constraints(q + h * e, t) - model.constraints(q - h * e, t)) / (2 * h)
                               for e in np.eye(model.n)])
    np.testing.assert_allclose(terms.A, numeric, atol=1e-8)
    phi_t = (model.constraints(q, t + h) - model.constraints(q, t - h)) / (2 * h)
    np.testing.assert_allclose(terms.phi_t, phi_t, atol=1e-8)
    a_dot = (model.jacobian(q + h * qd, t) - model.jacobian(q - h * qd, t)) / (2 * h)
    phi_tt = (model.constraints(q, t + 1e-4) - 2 * model.constraints(q, t) + model.constraints(q, t - 1e-4)) / 1e-8
    np.testing.assert_allclose(terms.gamma, -a_dot @ qd - phi_tt, atol=1e-6)
    assert abs(terms.gamma[-1] - (-0.5 * 4.0 * np.sin(2 * t))) < 1e-12        # the driver row: f''(t)
    # the conservative forces are -∇V (no damping; the constant force is added by hand)
    model_v = model.potential_energy
    gradient = np.array([(model_v(q + h * e) - model_v(q - h * e)) / (2 * h) for e in np.eye(model.n)])
    force = np.zeros(model.n)
    k = model.coordinate_index("K.x")
    force[k:k + 3] = (1.0, -2.0, 0.5)
    np.testing.assert_allclose(model.forces(q, np.zeros(model.n)), -gradient + force, atol=1e-6)
    assembled = cmbs.assemble(model)
    assert np.abs(model.constraints(assembled, 0.0)).max() < 1e-10
    assert assembled[model.coordinate_index("turn")] == pytest.approx(0.3, abs=1e-12)


def _spherical_pendulum(length=1.3, theta0=0.7, phi_rate=2.1, mass=0.8):
    b = SpatialModelBuilder("spherical-pendulum")
    b.add_point("O", (0.0, 0.0, 0.0), fixed=True)
    b.add_point("P", (length * np.sin(theta0), 0.0, -length * np.cos(theta0)), mass=mass)
    b.add_rod("rod", "O", "P", mass=0.0)
    model = b.build()
    qd0 = np.array([0.0, length * np.sin(theta0) * phi_rate, 0.0])
    return model, qd0


def _spherical_reference(times, length=1.3, theta0=0.7, phi_rate=2.1):
    """θ from the downward vertical, φ about it (Lagrange's equations in spherical coordinates)."""
    def rhs(t, y):
        theta, phi, theta_dot, phi_dot = y
        return [theta_dot, phi_dot, np.sin(theta) * np.cos(theta) * phi_dot**2 - G / length * np.sin(theta),
                -2.0 * theta_dot * phi_dot / np.tan(theta)]
    y = solve_ivp(rhs, (0.0, times[-1]), [theta0, 0.0, 0.0, phi_rate], t_eval=times, rtol=1e-12, atol=1e-12,
                  method="DOP853").y
    return length * np.stack([np.sin(y[0]) * np.cos(y[1]), np.sin(y[0]) * np.sin(y[1]), -np.cos(y[0])], axis=1)


@pytest.mark.parametrize("formulation", ["lagrange", "baumgarte", "projection", "udwadia-kalaba", "penalty"])
def test_spherical_pendulum_follows_the_spherical_coordinate_solution(formulation):
    model, qd0 = _spherical_pendulum()
    run = cmbs.simulate(model, t_end=2.0, dt=0.01, qd0=qd0, formulation=formulation, integrator="dop853",
                        rtol=1e-10, atol=1e-12)
    assert run.info["status"] == "success"
    reference = _spherical_reference(run.t)
    tolerance = 1e-4 if formulation == "penalty" else 1e-7
    np.testing.assert_allclose(run.q, reference, atol=tolerance)
    energy = model.energy_history(run.q, run.qd)
    assert np.ptp(energy) < 1e-6 * abs(energy[0]) + (1e-4 if formulation == "penalty" else 1e-8)


def _heavy_top(theta0=0.4, spin=30.0, precession=0.5, mass=1.2, l=0.15, transverse=4e-3, axial=6e-3):
    """Symmetric top on a fixed point O: body axes u, v, w (w the symmetry axis) at Euler angles
    (φ, θ, ψ) = (0, θ0, 0) about z, x, z; centre of mass at l along w; inertia about the centre of
    mass diag(A', A', C) in the body axes."""
    R = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(theta0), -np.sin(theta0)], [0.0, np.sin(theta0), np.cos(theta0)]])
    u, v, w = R.T
    b = SpatialModelBuilder("heavy-top")
    b.add_point("O", (0.0, 0.0, 0.0), fixed=True)
    b.add_vector("u", u)
    b.add_vector("v", v)
    b.add_vector("w", w)
    b.add_body("top", origin="O", basis=["u", "v", "w"], mass=mass, com=l * w,
               inertia=R @ np.diag([transverse, transverse, axial]) @ R.T)
    model = b.build()
    omega = precession * np.array([0.0, 0.0, 1.0]) + spin * w
    qd0 = np.concatenate([np.cross(omega, u), np.cross(omega, v), np.cross(omega, w)])
    return model, qd0


def _heavy_top_reference(times, theta0=0.4, spin=30.0, precession=0.5, mass=1.2, l=0.15, transverse=4e-3,
                         axial=6e-3):
    """The symmetry axis w(t) from the Lagrangian of the heavy symmetric top in Euler angles z-x-z:
    L = ½A(θ̇² + φ̇² sin²θ) + ½C(ψ̇ + φ̇ cos θ)² - m g l cos θ, A about the fixed point."""
    A, C = transverse + mass * l * l, axial
    omega3 = spin + precession * np.cos(theta0)           # ψ̇ + φ̇ cos θ at the start (ψ̇ = spin)
    p_phi = A * precession * np.sin(theta0) ** 2 + C * omega3 * np.cos(theta0)

    def rhs(t, y):
        phi, theta, theta_dot = y
        phi_dot = (p_phi - C * omega3 * np.cos(theta)) / (A * np.sin(theta) ** 2)
        theta_ddot = (A * phi_dot**2 * np.sin(theta) * np.cos(theta) - C * omega3 * phi_dot * np.sin(theta)
                      + mass * G * l * np.sin(theta)) / A
        return [phi_dot, theta_dot, theta_ddot]
    phi, theta, _ = solve_ivp(rhs, (0.0, times[-1]), [0.0, theta0, 0.0], t_eval=times, rtol=1e-12, atol=1e-12,
                              method="DOP853").y
    return np.stack([np.sin(phi) * np.sin(theta), -np.cos(phi) * np.sin(theta), np.cos(theta)], axis=1)


@pytest.mark.parametrize("formulation", ["lagrange", "projection", "udwadia-kalaba"])
def test_heavy_top_axis_follows_the_euler_angle_solution(formulation):
    model, qd0 = _heavy_top()
    run = cmbs.simulate(model, t_end=2.0, dt=0.01, qd0=qd0, formulation=formulation, integrator="dop853",
                        rtol=1e-10, atol=1e-12)
    assert run.info["status"] == "success"
    w = run.q[:, model.coordinate_index("w.x"):][:, :3]
    np.testing.assert_allclose(w, _heavy_top_reference(run.t), atol=1e-7)
    energy = model.energy_history(run.q, run.qd)
    assert np.ptp(energy) < 1e-8 * np.abs(energy).max()


def test_four_bar_in_space_moves_as_the_planar_four_bar():
    """The crank-rocker in the plane y = 0: rods with spherical ends, the crank and the rocker
    kept in the plane by (A - O)·y = 0 and (B - C)·y = 0 — the same motion as the planar model,
    to 1e-9 m over 2 s."""
    flat, space = _four_bar_models(revolute_bodies=False)
    start = cmbs.velocities(flat, flat.q0, qd=np.array([-1.5, 0.0, 0.0, 0.0]), fixed=["A.x"])   # B follows A
    run_flat = cmbs.simulate(flat, t_end=2.0, dt=0.02, qd0=start, integrator="dop853", rtol=1e-11, atol=1e-12)
    qd_space = np.array([start[0], 0.0, start[1], start[2], 0.0, start[3]])
    run_space = cmbs.simulate(space, t_end=2.0, dt=0.02, qd0=qd_space, integrator="dop853", rtol=1e-11, atol=1e-12)
    assert [run.info["status"] for run in (run_flat, run_space)] == ["success", "success"]
    positions_flat = np.array([flat.point_positions(q) for q in run_flat.q])
    positions_space = np.array([space.point_positions(q) for q in run_space.q])
    np.testing.assert_allclose(positions_space[:, :, [0, 2]], positions_flat, atol=1e-9)   # measured 1.4e-11
    np.testing.assert_allclose(positions_space[:, :, 1], 0.0, atol=1e-12)
    assert np.ptp(positions_flat[:, 1, 0]) > 0.5        # the crank really turns


def _four_bar_models(revolute_bodies: bool):
    """The crank-rocker of tests/helpers.py's four_bar_builders, planar and in space, built."""
    planar, spatial = four_bar_builders(revolute_bodies)
    return planar.build(), spatial.build()


@pytest.mark.parametrize("formulation", ["projection", "udwadia-kalaba"])
def test_four_bar_of_revolute_bodies_in_space_moves_as_the_planar_four_bar(formulation):
    """Revolute joints by shared points and a shared axis: 15 coordinates, 15 rows of rank 14
    (the third 'in the plane' condition follows from the other two), one degree of freedom;
    the formulations that take redundant constraints give the planar motion."""
    flat, space = _four_bar_models(revolute_bodies=True)
    report = cmbs.constraint_report(space, space.q0)
    assert (space.n, space.m, report.rank, report.dof) == (15, 15, 14, 1)
    assert len(report.redundant) == 1
    start = cmbs.velocities(flat, flat.q0, qd=np.array([-1.5, 0.0, 0.0, 0.0]), fixed=["A.x"])
    run_flat = cmbs.simulate(flat, t_end=2.0, dt=0.02, qd0=start, integrator="dop853", rtol=1e-11, atol=1e-12)
    qd_space = cmbs.velocities(space, space.q0, qd=np.concatenate([[start[0], 0.0, start[1]], np.zeros(12)]),
                               fixed=["A.x", "A.y", "A.z"])
    run_space = cmbs.simulate(space, t_end=2.0, dt=0.02, qd0=qd_space, formulation=formulation,
                              integrator="dop853", rtol=1e-11, atol=1e-12)
    assert run_space.info["status"] == "success"
    positions_flat = np.array([flat.point_positions(q) for q in run_flat.q])
    positions_space = np.array([space.point_positions(q) for q in run_space.q])
    np.testing.assert_allclose(positions_space[:, :, [0, 2]], positions_flat, atol=1e-9)   # measured 1.4e-11
    np.testing.assert_allclose(positions_space[:, :, 1], 0.0, atol=1e-12)


def test_assembly_puts_a_perturbed_top_back_on_its_constraints():
    model, _ = _heavy_top()
    rng = np.random.default_rng(2)
    q = cmbs.assemble(model, model.q0 + 0.02 * rng.normal(size=model.n))
    # assemble's criterion: |Φ_i| < 1e-12 ‖A_i‖ L, L = 1 m (the top has a single point)
    assert np.all(np.abs(model.constraints(q)) < 1e-12 * np.linalg.norm(model.jacobian(q), axis=1))
    u, v, w = q[0:3], q[3:6], q[6:9]
    np.testing.assert_allclose(np.column_stack([u, v, w]).T @ np.column_stack([u, v, w]), np.eye(3), atol=3e-12)
    assert np.linalg.det(np.column_stack([u, v, w])) > 0.0


@pytest.mark.parametrize("mistake, message", [
    (lambda b: b.add_body("B", origin="O", basis=["P", "u", "w"], mass=1.0, com=(0, 0, 0), inertia=np.eye(3)),
     "coplanar"),
    (lambda b: b.add_body("B", origin="O", basis=["P", "u", "uu"], mass=1.0, com=(0, 0, 0), inertia=np.eye(3)),
     "no point or vector 'uu'"),
    (lambda b: b.add_body("B", origin="O", basis=["P", "u", "v"], mass=1.0, com=(0, 0, 0),
                          inertia=np.diag([1.0, 1.0, 3.0])), "not that of a body"),
    (lambda b: b.add_rod("R", "O", "u", mass=1.0), "'u' is a vector, not a point"),
    (lambda b: b.add_vector("zero", (0, 0, 0)), "must not be zero"),
])
def test_modelling_mistakes_are_named(mistake, message):
    b = SpatialModelBuilder("mistakes")
    b.add_point("O", (0.0, 0.0, 0.0))
    b.add_point("P", (1.0, 0.0, 0.0))
    b.add_vector("u", (0.0, 1.0, 0.0))
    b.add_vector("w", (1.0, 1.0, 0.0))         # in the plane of P - O and u
    b.add_vector("v", (0.0, 0.0, 1.0))
    with pytest.raises(ModelError, match=message):
        mistake(b)
        b.build()


def test_the_figure_and_the_animation_draw_a_spatial_mechanism_in_3d(tmp_path):
    from PIL import Image

    from cmbs.animate import animate
    from cmbs.plotting import plot_simulation, save_figure

    model = cmbs.load("heavy-top")
    run = cmbs.simulate(model, t_end=0.5, dt=0.01)
    figure = plot_simulation(run, model=model)
    mechanism = [axis for axis in figure.axes if axis.get_title() == "mechanism (x, y, z)"]
    assert len(mechanism) == 1 and mechanism[0].name == "3d"
    assert save_figure(figure, tmp_path / "top.png").stat().st_size > 0
    path = animate(model, run, tmp_path / "top.gif", fps=20, trail="tip")
    with Image.open(path) as image:
        frames = []
        for k in range(image.n_frames):
            image.seek(k)
            frames.append(np.asarray(image.convert("L"), dtype=float))
    assert len(frames) == 11                            # 0.5 s at 20 frames per second, both ends
    assert np.abs(frames[-1] - frames[0]).max() > 100   # the top has moved between the first and last frame


def test_library_four_bar_3d_moves_as_the_planar_library_four_bar():
    planar = cmbs.load("four-bar").without_drivers()
    space = cmbs.load("four-bar-3d")
    runs = [cmbs.simulate(model, t_end=2.0, dt=0.02, integrator="dop853", rtol=1e-11, atol=1e-12)
            for model in (planar, space)]
    assert [run.info["status"] for run in runs] == ["success", "success"]
    flat = np.array([planar.point_positions(q) for q in runs[0].q])
    positions = np.array([space.point_positions(q) for q in runs[1].q])
    assert space.point_names == planar.point_names
    np.testing.assert_allclose(positions[:, :, [0, 2]], flat, atol=1e-7)
    assert np.ptp(flat[:, 2, 0]) > 0.5                  # P1 really moves


@pytest.mark.parametrize("name", ["spherical-pendulum", "heavy-top"])
def test_library_spatial_models_conserve_energy_and_their_first_integrals(name):
    """Energy and the angular momentum about the vertical through the fixed point (and for the
    top, about its axis) stay constant over 2 s."""
    model = cmbs.load(name)
    run = cmbs.simulate(model, t_end=2.0, dt=0.01, integrator="dop853", rtol=1e-10, atol=1e-12)
    assert run.info["status"] == "success"
    energy = model.energy_history(run.q, run.qd)
    assert np.ptp(energy) < 1e-7 * np.abs(energy).max()
    if name == "spherical-pendulum":
        p, v = run.q, run.qd
        vertical = p[:, 0] * v[:, 1] - p[:, 1] * v[:, 0]
        spins = [vertical]
    else:
        index = model.coordinate_index
        u, v, w = (run.q[:, index(f"{e}.x"):index(f"{e}.x") + 3] for e in "uvw")
        du, dv, dw = (run.qd[:, index(f"{e}.x"):index(f"{e}.x") + 3] for e in "uvw")
        # ω from the rates of the body axes: ω = ½ Σ e × ė
        omega = 0.5 * (np.cross(u, du) + np.cross(v, dv) + np.cross(w, dw))
        parameters = model.parameters
        transverse = parameters["transverse_inertia"] + parameters["mass"] * parameters["com_height"] ** 2
        axial = parameters["axial_inertia"]
        omega_axis = np.sum(omega * w, axis=1)
        momentum = transverse * (omega - omega_axis[:, None] * w) + axial * omega_axis[:, None] * w
        spins = [momentum[:, 2], omega_axis]
    for value in spins:
        assert np.ptp(value) < 1e-7 * np.abs(value).max()


def test_the_example_of_docs_spatial_builds_the_top_it_describes():
    from pathlib import Path

    text = (Path(__file__).parent.parent / "docs" / "spatial.md").read_text()
    code = text.split("```python\n", 1)[1].split("```", 1)[0]
    namespace: dict = {}
    exec(compile(code, "docs/spatial.md", "exec"), namespace)
    model = namespace["model"]
    report = cmbs.constraint_report(model, model.q0)
    assert (model.n, model.m, report.dof) == (12, 9, 3)


@pytest.mark.parametrize("formulation", ["projection", "udwadia-kalaba"])
def test_bricard_mechanism_follows_exudyn_through_its_redundant_constraints(formulation):
    """IFToMM A04: P3 over 10 s within 1e-6 m of Exudyn's solution at h = 1e-4 (tests/data, from
    benchmarks/bench_bricard.py; the two differ by 1e-5 m at Exudyn's h = 1e-3 and 1e-7 m at
    1e-4, its second-order convergence), energy kept, 1 DOF with 1 redundant row (Grübler's count: 0 DOF)."""
    from pathlib import Path

    reference = np.loadtxt(Path(__file__).parent / "data" / "bricard-exudyn-p3.csv", delimiter=",")
    model = cmbs.load("bricard")
    report = cmbs.constraint_report(model, model.q0)
    assert (model.n, model.m, report.rank, report.dof, len(report.redundant)) == (24, 24, 23, 1, 1)
    run = cmbs.simulate(model, t_end=10.0, dt=0.05, formulation=formulation, integrator="dop853", rtol=1e-10,
                        atol=1e-12)
    assert run.info["status"] == "success"
    np.testing.assert_allclose(run.t, reference[:, 0], atol=1e-12)
    index = model.coordinate_index("P3.x")
    assert np.abs(run.q[:, index:index + 3] - reference[:, 1:]).max() < 1e-6
    assert np.ptp(reference[:, 2]) > 0.7                    # P3 really swings (down to y = -1.73 m)
    energy = model.energy_history(run.q, run.qd)
    assert np.ptp(energy) < 1e-8 * np.abs(energy).max()


def test_a_moment_on_a_body_has_the_power_of_the_moment_and_spins_the_top_up():
    """Qᵀq̇ = M·ω for rigid motions of a general body (non-orthogonal basis, a point difference
    in it); and a moment about the vertical on the top without gravity raises its angular
    momentum about the vertical at the moment's rate, the other components staying zero."""
    rng = np.random.default_rng(8)
    b = SpatialModelBuilder("pushed", gravity=(0.0, 0.0, 0.0))
    b.add_point("O", rng.normal(size=3))
    b.add_point("P", rng.normal(size=3))
    b.add_vector("u", rng.normal(size=3))
    b.add_vector("w", rng.normal(size=3))
    b.add_body("B", origin="O", basis=["P", "u", "w"], mass=1.5, com=rng.normal(size=3), inertia=np.eye(3))
    moment = np.array([0.3, -1.1, 0.7])
    b.add_moment("turn", body="B", moment=moment)
    model = b.build()
    assert "moment 'turn'" in model.work_sources
    Q = model.forces(model.q0, np.zeros(model.n))
    for _ in range(4):
        omega = rng.normal(size=3)
        qd = _rigid_velocities(model, "O", rng.normal(size=3), omega)
        assert Q @ qd == pytest.approx(moment @ omega, rel=1e-12)

    top = SpatialModelBuilder("spun", gravity=(0.0, 0.0, 0.0))
    top.add_point("O", (0.0, 0.0, 0.0), fixed=True)
    for name, direction in (("u", (1.0, 0.0, 0.0)), ("v", (0.0, 0.6, 0.8)), ("w", (0.0, -0.8, 0.6))):
        top.add_vector(name, direction)
    top.add_body("top", origin="O", basis=["u", "v", "w"], mass=1.0, com=(0.0, -0.08, 0.06),
                 inertia=np.diag([4e-3, 5e-3, 6e-3]))
    top.add_moment("drive", body="top", moment=(0.0, 0.0, 0.02))
    spun = top.build()
    run = cmbs.simulate(spun, t_end=1.0, dt=0.05, integrator="dop853", rtol=1e-11, atol=1e-12)
    u, v, w = (run.q[:, 3 * k:3 * k + 3] for k in range(3))
    du, dv, dw = (run.qd[:, 3 * k:3 * k + 3] for k in range(3))
    omega = 0.5 * (np.cross(u, du) + np.cross(v, dv) + np.cross(w, dw))
    # angular momentum about the fixed point: Σ over the body of r × ṙ dm = I_O ω, I_O in ground axes;
    # R turns the start (where com and inertia are given in ground axes) into the state at t
    com_initial = np.array([0.0, -0.08, 0.06])
    start = np.column_stack([u[0], v[0], w[0]])
    momentum = []
    for k in range(len(run.t)):
        R = np.column_stack([u[k], v[k], w[k]]) @ start.T
        com = R @ com_initial
        inertia = R @ np.diag([4e-3, 5e-3, 6e-3]) @ R.T + 1.0 * (com @ com * np.eye(3) - np.outer(com, com))
        momentum.append(inertia @ omega[k])
    np.testing.assert_allclose(np.array(momentum), np.outer(run.t, [0.0, 0.0, 0.02]), atol=1e-9)


def test_driven_spatial_four_bar_needs_the_planar_torque():
    """The library four-bar's crank angle driven by (π/4) sin(πt - π/2), built in space with an
    angle coordinate (from the ground's x axis to the crank about -y, the planar angle's sense)
    and the same driver: kinematic analysis and inverse dynamics give the planar model's
    motion and crank torque."""
    planar = cmbs.load("four-bar")
    start = dict(zip(planar.point_names, planar.point_positions(planar.q0)))
    b = SpatialModelBuilder("four-bar-driven-3d", gravity=(0.0, 0.0, -9.81))
    for name in ("A", "B", "P1", "P2"):
        x, z = start[name]
        b.add_point(name, (x, 0.0, z), fixed=name in ("A", "B"))
    b.add_vector("y", (0.0, 1.0, 0.0), fixed=True)
    b.add_vector("x", (1.0, 0.0, 0.0), fixed=True)
    b.add_vector("down-y", (0.0, -1.0, 0.0), fixed=True)
    for name, i, j, mass in (("crank", "A", "P1", 1.0), ("coupler", "P1", "P2", 5.0), ("rocker", "P2", "B", 3.0)):
        b.add_rod(name, i, j, mass=mass)
    b.add_dot("crank axis", ("P1", "A"), "y")
    b.add_dot("rocker axis", ("P2", "B"), "y")
    b.add_angle("alpha", reference="x", vector=("P1", "A"), axis="down-y")
    b.add_driver("alpha", "(pi/4) * sin(2*(pi/2)*t - pi/2)", name="crank")
    b.add_actuator("torque", coordinate="alpha")
    space = b.build()
    space = space.replace(q0=cmbs.assemble(space))
    assert space.q0[space.coordinate_index("alpha")] == pytest.approx(planar.q0[planar.coordinate_index("alpha")],
                                                                       abs=1e-10)
    times = np.linspace(0.0, 2.0, 41)
    flat, spatial = (cmbs.inverse_dynamics(model, times) for model in (planar, space))
    np.testing.assert_allclose([space.point_positions(q)[:, [0, 2]] for q in spatial.motion.q],
                               [planar.point_positions(q) for q in flat.motion.q], atol=1e-9)
    torque_flat, torque_space = flat.force("alpha"), spatial.force("alpha")
    assert np.ptp(torque_flat) > 10.0                       # a real torque history
    np.testing.assert_allclose(torque_space, torque_flat, atol=1e-8 * np.abs(torque_flat).max())


def test_a_jack_on_a_distance_coordinate_pushes_along_the_line():
    """A linear actuator on the distance s between a fixed point and a free point mass (no
    gravity): the input u is a force u along the line, so the mass moves as x(t) = x0 + ½ (u/m) t²."""
    b = SpatialModelBuilder("jack", gravity=(0.0, 0.0, 0.0))
    b.add_point("O", (0.0, 0.0, 0.0), fixed=True)
    b.add_point("P", (0.6, 0.0, 0.8), mass=2.0)
    b.add_distance("s", "O", "P")
    b.add_actuator("jack", coordinate="s", gain=1.5)
    model = b.build()
    assert model.q0[model.coordinate_index("s")] == pytest.approx(1.0)
    run = cmbs.simulate(model, t_end=1.0, dt=0.1, u=np.array([2.0]), integrator="dop853", rtol=1e-11, atol=1e-12)
    assert run.info["status"] == "success"
    travel = 0.5 * (1.5 * 2.0 / 2.0) * run.t**2
    np.testing.assert_allclose(run["P.x"], 0.6 + 0.6 * travel, atol=1e-9)
    np.testing.assert_allclose(run["P.z"], 0.8 + 0.8 * travel, atol=1e-9)
    np.testing.assert_allclose(run["s"], 1.0 + travel, atol=1e-9)



def _general_free_body(rng, name):
    b = SpatialModelBuilder(name, gravity=(0.0, 0.0, 0.0))
    b.add_point("O", rng.normal(size=3))
    b.add_point("P", rng.normal(size=3))
    b.add_vector("u", rng.normal(size=3))
    b.add_vector("w", rng.normal(size=3))
    b.add_body("B", origin="O", basis=["P", "u", "w"], mass=1.5, com=rng.normal(size=3), inertia=np.eye(3))
    return b


def _turned(model, R):
    """q of the model's start turned by the rotation R about the ground origin, and the q̇ of the
    rigid motion with angular velocity ω about it (a function of ω)."""
    q = model.q0.copy()
    for k in range(0, model.n, 3):
        q[k:k + 3] = R @ model.q0[k:k + 3]
    return q, lambda omega: np.concatenate([np.cross(omega, q[k:k + 3]) for k in range(0, model.n, 3)])


@pytest.mark.parametrize("frame", ["ground", "body"])
def test_forces_and_moments_vary_in_time_along_the_ground_or_the_body_axes(frame):
    """A force at P and a moment on a general body (non-orthogonal basis), components functions
    of time: at a random rigid rotation R of the start, the force's generalized force is f (ground
    axes) or R f (body axes, a follower force) at P and nothing elsewhere, and the moment's power
    for every rigid motion is m·ω or (R m)·ω."""
    rng = np.random.default_rng(11)
    pushed = _general_free_body(rng, "pushed")
    pushed.add_force("thrust", point="P", force=("2*t", -0.4, 3.0), body="B" if frame == "body" else None)
    turned = _general_free_body(np.random.default_rng(11), "turned")
    turned.add_moment("twist", body="B", moment=(0.3, "-1.1*cos(t)", 0.7), frame=frame)
    pushed, turned = pushed.build(), turned.build()
    t = 0.6
    f, m = np.array([2 * t, -0.4, 3.0]), np.array([0.3, -1.1 * np.cos(t), 0.7])
    p = pushed.coordinate_index("P.x")
    for _ in range(3):
        R = _random_rotation(rng)
        expected_f, expected_m = (R @ f, R @ m) if frame == "body" else (f, m)
        q, rigid = _turned(pushed, R)
        Q = pushed.evaluate(q, np.zeros(pushed.n), t).Q
        np.testing.assert_allclose(Q[p:p + 3], expected_f, atol=1e-12)
        assert np.abs(np.delete(Q, np.s_[p:p + 3])).max() == 0.0
        q, rigid = _turned(turned, R)
        Q = turned.evaluate(q, np.zeros(turned.n), t).Q
        for _ in range(3):
            omega = rng.normal(size=3)
            assert Q @ rigid(omega) == pytest.approx(expected_m @ omega, rel=1e-11)


def test_a_time_varying_force_pushes_a_point_mass_as_integrated_by_hand():
    """A point mass m pushed by f_z = 2 t and a tabled f_x (linear from 1 N to 3 N over 1 s):
    z = z₀ + t³/(3m), x = x₀ + (t²/2 + t³/3)/m."""
    b = SpatialModelBuilder("pushed", gravity=(0.0, 0.0, 0.0))
    b.add_point("P", (0.1, 0.2, 0.3), mass=2.0)
    b.add_force("push", point="P", force=(Table(np.array([0.0, 1.0]), np.array([1.0, 3.0]), "linear"), 0.0, "2*t"))
    model = b.build()
    assert "force 'push'" in model.work_sources
    run = cmbs.simulate(model, t_end=1.0, dt=0.1, integrator="dop853", rtol=1e-12, atol=1e-12)
    assert run.info["status"] == "success"
    np.testing.assert_allclose(run["P.z"], 0.3 + run.t**3 / 6.0, atol=1e-10)
    np.testing.assert_allclose(run["P.x"], 0.1 + (run.t**2 / 2 + run.t**3 / 3) / 2.0, atol=1e-10)
    np.testing.assert_allclose(run["P.y"], 0.2, atol=1e-12)


def test_a_rotational_spring_damper_on_a_revolute_joint_is_a_torsional_oscillator():
    """A body turning about the ground axis z (inertia I about it), a rotational spring-damper
    k, c on its angle: θ(t) = e^(-ζω t) (θ₀ cos ω_d t + (ζω θ₀/ω_d) sin ω_d t) from rest; without
    damping T + V is kept, with it the energy falls by the damper's work ∫ c θ̇² dt."""
    inertia, k, c, theta0 = 0.05, 2.0, 0.04, 0.6
    for damping in (0.0, c):
        b = SpatialModelBuilder("torsion", gravity=(0.0, 0.0, -G))
        b.add_point("O", (0.0, 0.0, 0.0), fixed=True)
        b.add_vector("z", (0.0, 0.0, 1.0), fixed=True)
        b.add_vector("x", (1.0, 0.0, 0.0), fixed=True)
        b.add_vector("u", (np.cos(theta0), np.sin(theta0), 0.0))
        b.add_vector("v", (-np.sin(theta0), np.cos(theta0), 0.0))
        b.add_body("disc", origin="O", basis=["z", "u", "v"], mass=1.0, com=(0.0, 0.0, 0.0),
                   inertia=np.diag([0.5 * inertia, 0.5 * inertia, inertia]))
        b.add_angle("theta", reference="x", vector="u", axis="z")
        b.add_rotational_spring("twist", angle="theta", stiffness=k, damping=damping, rest_angle=0.0)
        model = b.build()
        run = cmbs.simulate(model, t_end=2.0, dt=0.005, integrator="dop853", rtol=1e-11, atol=1e-12)
        assert run.info["status"] == "success"
        omega = np.sqrt(k / inertia)
        zeta = damping / (2.0 * np.sqrt(k * inertia))
        omega_d = omega * np.sqrt(1.0 - zeta**2)
        expected = np.exp(-zeta * omega * run.t) * (theta0 * np.cos(omega_d * run.t)
                                                     + zeta * omega * theta0 / omega_d * np.sin(omega_d * run.t))
        np.testing.assert_allclose(run["theta"], expected, atol=1e-8)
        energy = model.energy_history(run.q, run.qd)
        if damping == 0.0:
            assert np.ptp(energy) < 1e-9 * energy.max()
            assert energy[0] == pytest.approx(0.5 * k * theta0**2, rel=1e-12)
        else:
            assert "rotational spring 'twist'" in model.work_sources
            dissipated = simpson(damping * run.velocity("theta") ** 2, x=run.t)
            assert energy[0] - energy[-1] == pytest.approx(dissipated, rel=1e-6)
            assert dissipated > 0.5 * energy[0]
