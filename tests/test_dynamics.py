"""Forward dynamics: the six formulations agree with each other and with an independent
minimal-coordinate ODE, closed forms on the particle on a circle, redundant constraints,
measured orders of accuracy, energy conservation and Baumgarte's bounded drift."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import cmbs
from cmbs.dynamics import FORMULATIONS, formulation
from cmbs.errors import CmbsError, SingularSystemError
from cmbs.library.mechanisms import slider_crank_branch
from cmbs.model.natural import NaturalModelBuilder
from cmbs.simulate import simulate

ALL = list(FORMULATIONS)


def double_pendulum_reference(t_end, theta1, theta2):
    """Two uniform rods (1 m, 1 kg) in absolute angles φ1, φ2 from the x axis, Lagrange's
    equations written out by hand: M(φ) φ̈ + c sin(φ1-φ2) (φ̇2², -φ̇1²) = -∂V/∂φ."""
    g, c = 9.81, 0.5
    def rhs(t, y):
        p1, p2, w1, w2 = y
        s, co = math.sin(p1 - p2), math.cos(p1 - p2)
        M = np.array([[1 / 3 + 1, c * co], [c * co, 1 / 3]])
        f = np.array([-c * s * w2**2 - 1.5 * g * math.cos(p1), c * s * w1**2 - 0.5 * g * math.cos(p2)])
        return [w1, w2, *np.linalg.solve(M, f)]
    solution = solve_ivp(rhs, (0, t_end), [theta1, theta1 + theta2, 0, 0], rtol=1e-12, atol=1e-12)
    return solution.y[:, -1]


@pytest.mark.parametrize("name", ["double-pendulum", "four-bar"])
def test_all_formulations_agree(name):
    model = cmbs.load(name)
    if name == "four-bar":
        model = model.without_drivers()
    runs = {f: simulate(model, t_end=5.0, formulation=f, rtol=1e-10, atol=1e-12, dt=0.05) for f in ALL}
    reference = runs["lagrange"]
    for f, run in runs.items():
        assert run.info["status"] == "success", f
        assert np.abs(run.q - reference.q).max() <= 1e-6, f
    if name == "double-pendulum":
        phi1, phi2, _, _ = double_pendulum_reference(5.0, *model.q0[4:6])
        final = reference.q[-1]
        assert final[model.coordinate_index("theta1")] == pytest.approx(phi1, abs=1e-7)
        assert final[model.coordinate_index("theta1")] + final[model.coordinate_index("theta2")] == \
            pytest.approx(phi2, abs=1e-7)


@pytest.mark.parametrize("name", ALL)
def test_particle_on_circle_closed_form(name):
    """q̈ = tangential gravity - |v|²/r n, and λ from the normal balance m q̈·n + 2rλ = Q·n."""
    model = cmbs.load("particle-circle")
    theta, speed = 0.7, 1.3
    q = np.array([math.cos(theta), math.sin(theta)])
    qd = speed * np.array([-math.sin(theta), math.cos(theta)])
    solution = formulation(name).bind(model).accelerations(model.evaluate(q, qd, 0.0), q, qd, 0.0)
    tangent = np.array([-math.sin(theta), math.cos(theta)])
    gravity = np.array([0.0, -9.81])
    expected = (gravity @ tangent) * tangent - speed**2 * q
    tolerance = 1e-5 if name == "penalty" else 1e-10
    np.testing.assert_allclose(solution.qdd, expected, atol=tolerance)
    assert solution.lam[0] == pytest.approx((gravity @ q + speed**2) / 2.0, abs=tolerance)
    np.testing.assert_allclose(solution.constraint_force, -2 * q * solution.lam[0], atol=tolerance)


def redundant_four_bar():
    """The library four-bar (undriven) with its coupler constraint given twice."""
    b = NaturalModelBuilder("four-bar-redundant")
    b.add_point("A", 0.0, 0.0, fixed=True)
    b.add_point("B", 10.0, 0.0, fixed=True)
    base = cmbs.load("four-bar")
    p1, p2 = base.q0[0:2], base.q0[2:4]
    b.add_point("P1", *p1)
    b.add_point("P2", *p2)
    b.add_segment("crank", "A", "P1", mass=1.0, com=(1.0, 0.0), inertia=1 / 3, length=2.0)
    b.add_segment("coupler", "P1", "P2", mass=5.0, com=(5.0, 0.0), inertia=5 * 100 / 12, length=10.0)
    b.add_segment("coupler-again", "P1", "P2", mass=0.0, length=10.0)
    b.add_segment("rocker", "P2", "B", mass=3.0, com=(3.0, 0.0), inertia=9.0, length=6.0)
    b.add_angle("alpha", segment="crank")
    return b.build()


def test_redundant_constraints():
    plain, redundant = cmbs.load("four-bar").without_drivers(), redundant_four_bar()
    assert cmbs.constraint_report(redundant, redundant.q0).redundant
    reference = simulate(plain, t_end=2.0, formulation="lagrange", rtol=1e-10, atol=1e-12, dt=0.1)
    for name in ("projection", "udwadia-kalaba", "penalty"):
        run = simulate(redundant, t_end=2.0, formulation=name, rtol=1e-10, atol=1e-12, dt=0.1)
        assert run.info["status"] == "success"
        assert np.abs(run.q - reference.q).max() <= 1e-6, name
    failed = simulate(redundant, t_end=2.0, formulation="lagrange", dt=0.1)
    assert failed.info["status"] == "failed"
    assert "rank 4 < 5" in failed.info["message"] and "rigid coupler" in failed.info["message"]
    with pytest.raises(SingularSystemError, match="dependent: rigid coupler"):
        formulation("lagrange").bind(redundant).accelerations(redundant.evaluate(redundant.q0, redundant.qd0),
                                                               redundant.q0, redundant.qd0, 0.0)


@pytest.mark.parametrize("integrator, order, steps", [
    # trapezoidal: h = 0.02 is at the edge of the asymptotic range (the re-partition instants of its
    # matrix R move with h; 0.04 -> 0.02 measures from 0.2 to 3.4 for condition_growth 1.1 to 3)
    ("rk4", 4, (0.04, 0.02)), ("trapezoidal", 2, (0.01, 0.005)), ("backward-euler", 1, (0.004, 0.002)),
    ("generalized-alpha", 2, (0.02, 0.01)),
])
def test_order_of_accuracy(integrator, order, steps):
    model = cmbs.load("double-pendulum")
    reference = simulate(model, t_end=1.0, integrator="rk45", rtol=1e-13, atol=1e-14, dt=0.5).q[-1]
    errors = [np.abs(simulate(model, t_end=1.0, integrator=integrator, dt=h).q[-1] - reference).max() for h in steps]
    measured = math.log2(errors[0] / errors[1])
    assert measured == pytest.approx(order, abs=0.3)


def test_energy_conserved_to_the_tolerance():
    """The relative energy error of RK45 on the double pendulum follows the tolerance: below
    100 rtol (global error over 3 s of chaotic motion) and shrinking with it."""
    model = cmbs.load("double-pendulum")
    errors = []
    for tol in (1e-6, 1e-8, 1e-10):
        energy = simulate(model, t_end=3.0, rtol=tol, atol=tol * 1e-2)["energy"]
        errors.append(np.abs(energy - energy[0]).max() / abs(energy[0]))
        assert errors[-1] < 100 * tol
    assert errors[0] > 30 * errors[1] > 900 * errors[2]


def test_baumgarte_bounds_the_drift_that_lagrange_accumulates():
    """Thesis Figure 3.10: the rigid-bar constraint drifts with plain Lagrange multipliers at a
    loose tolerance and stays bounded with Baumgarte (ξ = 1, ω = 10)."""
    model = cmbs.load("four-bar").without_drivers()
    plain = simulate(model, t_end=10.0, formulation="lagrange", rtol=1e-4, atol=1e-6)
    stabilised = simulate(model, t_end=10.0, formulation="baumgarte", rtol=1e-4, atol=1e-6)
    drift = plain["constraint_error"]
    assert drift[-1] > 20 * stabilised["constraint_error"][len(drift) // 2:].max()
    assert drift[len(drift) // 2:].max() > drift[: len(drift) // 10].max()


def test_bad_options():
    model = cmbs.load("pendulum")
    with pytest.raises(CmbsError, match="unknown formulation 'lagrangian'"):
        simulate(model, t_end=1.0, formulation="lagrangian")
    with pytest.raises(CmbsError, match="unknown integrator"):
        simulate(model, t_end=1.0, integrator="euler")
    with pytest.raises(CmbsError, match="brings its own formulation"):
        simulate(model, t_end=1.0, integrator="backward-euler", formulation="projection")
    with pytest.raises(CmbsError, match="formulation 'baumgarte' has no option\\(s\\) alpha \\(options: xi, omega"):
        simulate(model, t_end=1.0, formulation="baumgarte", formulation_options={"alpha": 3})


def branch_deviation(run):
    """Largest |θ2 + 2θ1| (mod 2π): zero on the slider-crank's assembly branch θ2 = -2θ1."""
    return np.abs(np.angle(np.exp(1j * (run["theta2"] + 2 * run["theta1"])))).max()


@pytest.fixture(scope="module")
def slider_crank_runs():
    model = cmbs.load("slider-crank")
    runs = {name: simulate(model, t_end=10.0, formulation=name, rtol=1e-10, atol=1e-12, project=True, dt=0.01)
            for name in ("projection", "udwadia-kalaba", "lagrange")}
    runs["matrix-r"] = simulate(model, t_end=10.0, formulation="matrix-r", rtol=1e-10, atol=1e-12, dt=0.01)
    runs["generalized-alpha"] = simulate(model, t_end=10.0, integrator="generalized-alpha", dt=1e-3)
    return runs


@pytest.mark.parametrize("name", ["projection", "udwadia-kalaba", "matrix-r"])
def test_slider_crank_passes_its_singular_positions_or_says_where_it_left_its_branch(slider_crank_runs, name):
    """A run that passes the crossings stays on the branch θ2 = -2θ1; one whose velocity jumps
    there onto the other branch (the index-1 projection and Udwadia-Kalaba with the Moore-Penrose
    inverse used to, at 1.99 s, and said success) fails saying so, its outputs on the branch."""
    run = slider_crank_runs[name]
    if run.info["status"] == "success":
        assert run.t[-1] == pytest.approx(10.0)
        crossings = np.sum(np.diff(np.floor((run["theta1"] - np.pi / 2) / np.pi)) != 0)
        assert crossings >= 3  # the crank passes ±90° (B over O) several times
    else:
        assert run.info["message"].startswith("the velocity jumped by")
    assert branch_deviation(run) < 1e-8
    energy = run["energy"]
    assert np.abs(energy - energy[0]).max() / energy[0] <= 1e-6


def test_position_level_methods_keep_the_assembly_branch(slider_crank_runs):
    """Matrix R (dependent coordinates by Newton from the previous ones) and the index-3
    generalized-α (Φ(q_{n+1}) = 0 solved from a predictor) stay on θ2 = -2θ1; index-1 methods
    conserve energy but may leave it at a crossing (docs/formulations.md explains why)."""
    assert branch_deviation(slider_crank_runs["matrix-r"]) < 1e-8
    run = slider_crank_runs["generalized-alpha"]
    assert run.info["status"] == "success" and branch_deviation(run) < 1e-8
    assert np.abs(run["energy"] - run["energy"][0]).max() / run["energy"][0] < 1e-4  # numerical damping ρ∞ = 0.9


@pytest.mark.parametrize("name", ["matrix-r", "projection"])
def test_slider_crank_follows_its_branch_ode_through_the_singular_position(name):
    """With gravity the crank reaches 90° at 0.83 s.  On the branch θ2 = -2θ1 the mechanism is
    one smooth ODE in θ1 (cmbs.library.mechanisms.slider_crank_branch, regular at 90°): RK4 at
    1 ms stays within 1e-10 rad of it (measured 5e-12 for matrix R, 1.5e-12 for projection), and
    the branch ODE's energy m(θ1) θ̇1²/2 + g sin θ1 equals the model's at every time."""
    gravity = 9.81
    model = cmbs.load("slider-crank", gravity=gravity)
    run = simulate(model, t_end=1.0, formulation=name, integrator="rk4", dt=1e-3)
    rows = np.searchsorted(run.t, np.array([0.25, 0.5, 0.75, 0.82, 0.84, 1.0]) - 1e-9)
    theta, omega = slider_crank_branch(run.t[rows], gravity=gravity)
    assert run["theta1"][rows[3]] < np.pi / 2 < run["theta1"][rows[4]]
    np.testing.assert_allclose(run["theta1"][rows], theta, rtol=0, atol=1e-10)
    branch_energy = (2.0 / 3.0 + 2.0 * np.sin(theta) ** 2) * omega ** 2 / 2 + gravity * np.sin(theta)
    np.testing.assert_allclose(run["energy"][rows], branch_energy, rtol=1e-9)


@pytest.mark.parametrize("times", [[], [0.5, 0.25], [-0.1, 0.5], [0.0, float("nan")]])
def test_branch_reference_refuses_times_it_cannot_integrate_to(times):
    with pytest.raises(CmbsError, match="times must be a non-empty, non-decreasing sequence"):
        slider_crank_branch(times, gravity=9.81)


def test_trapezoidal_rule_keeps_second_order_through_the_singular_position():
    """The implicit trapezoidal rule in matrix R's independent coordinates, 1 s through the
    crossing at 0.83 s, against the branch ODE: the error falls about 16-fold from h = 1 ms to
    0.25 ms (measured 2.8e-6 -> 1.3e-7 rad).  Its dependent velocities are always recovered: it
    integrates z and ż only (keeping its previous ḋ near the crossing stalled it at 3.6e-6)."""
    gravity = 9.81
    model = cmbs.load("slider-crank", gravity=gravity)
    reference = slider_crank_branch(np.array([1.0]), gravity=gravity)[0][0]
    errors = [abs(simulate(model, t_end=1.0, integrator="trapezoidal", dt=dt)["theta1"][-1] - reference)
              for dt in (1e-3, 2.5e-4)]
    assert errors[1] < 2e-7 and 10.0 < errors[0] / errors[1] < 30.0


def test_matrix_r_keeps_its_number_of_dependent_coordinates_at_a_singular_position():
    """At θ1 = 90° (C over O) the slider-crank's A loses rank; a re-partition there must still
    choose the 5 dependent coordinates found at the start, not release a constraint."""
    model = cmbs.load("slider-crank")
    solver = formulation("matrix-r").bind(model)
    assert solver.partition.dependent.size == 5
    q = dict(zip(model.coordinate_names, model.q0))
    q.update({"A.x": 0.0, "A.z": 1.0, "C.x": 0.0, "theta1": math.pi / 2, "theta2": -math.pi})
    A = model.jacobian(np.array([q[name] for name in model.coordinate_names]), 0.0)
    assert np.linalg.matrix_rank(A) == 4
    solver.repartition(A)
    assert solver.partition.dependent.size == 5 and solver.partition.rows.size == 5


def test_partition_condition_closed_form_on_the_pendulum():
    """The pendulum (x, z) with x dependent: A = [2x, 2z], A_d = [2x] (condition 1 everywhere);
    κ₂ = ‖A‖₂/|2x| = L/|x| and κ₁ = max(|2x|, |2z|)/|2x|."""
    from cmbs.dynamics.matrix_r import partition_condition

    model = cmbs.load("pendulum")
    for angle in (0.0, -0.7, -1.5, -1.57):
        q = np.array([math.cos(angle), math.sin(angle)])
        A = model.jacobian(q, 0.0)
        np.testing.assert_allclose(A, [2 * q], rtol=1e-14)
        assert partition_condition(A, np.array([0]), 2) == pytest.approx(1.0 / abs(q[0]), rel=1e-12)
        assert partition_condition(A, np.array([0]), 1) == pytest.approx(max(abs(q)) / abs(q[0]), rel=1e-12)
    assert partition_condition(np.array([[0.0, 2.0]]), np.array([0]), 2) == np.inf


def test_partition_condition_bounds_the_dependent_block_condition():
    """κ_p ≥ cond_p(A_d), with equality when A_r has no independent columns (A_d = A_r); and
    κ_p = ‖A_r‖_p ‖A_d⁻¹‖_p from numpy's norms and inverse."""
    from cmbs.dynamics.matrix_r import partition_condition

    generator = np.random.default_rng(11)
    dependent = np.array([1, 2, 4])
    for _ in range(5):
        A_rows = generator.normal(size=(3, 6))
        block = A_rows[:, dependent]
        for norm in (1, 2):
            kappa = partition_condition(A_rows, dependent, norm)
            expected = np.linalg.norm(A_rows, norm) * np.linalg.norm(np.linalg.inv(block), norm)
            assert kappa == pytest.approx(expected, rel=1e-10)
            assert kappa >= np.linalg.cond(block, norm) * (1 - 1e-12)
            assert partition_condition(block, np.arange(3), norm) == pytest.approx(np.linalg.cond(block, norm),
                                                                                    rel=1e-12)


@pytest.mark.parametrize("compiled", [None, False])
def test_matrix_r_swings_the_pendulum_under_its_pivot(compiled):
    """Released horizontal, the pendulum's first partition (x dependent) degrades as it swings
    down, though its 1 × 1 A_d keeps condition 1: re-partitioning on κ carries it through
    (with cond(A_d) as the test the recovery failed at t = 0.48 s).  Three swings at 1 ms agree
    with Lagrange at 25 µs (measured 5.8e-10) and conserve energy."""
    model = cmbs.load("pendulum")
    run = simulate(model, t_end=5.0, integrator="rk4", dt=1e-3, formulation="matrix-r", compiled=compiled)
    reference = simulate(model, t_end=5.0, integrator="rk4", dt=2.5e-5)
    assert run.info["status"] == "success"
    assert np.abs(run.q[-1] - reference.q[-1]).max() < 1e-8
    energy = run["energy"]
    assert np.abs(energy - energy[0]).max() < 1e-8
    assert np.count_nonzero(np.diff(np.sign(run["P.x"]))) >= 5     # passes under the pivot


def test_plain_lagrange_stops_at_the_singular_position(slider_crank_runs):
    run = slider_crank_runs["lagrange"]
    assert run.info["status"] == "failed" and run.t[-1] < 10.0
    assert "singular configuration" in run.info["message"] and "Use formulation 'projection'" in run.info["message"]
    theta = run["theta1"][-1]
    assert abs(math.cos(theta)) < 0.05  # it stopped next to θ1 = ±90°


@pytest.mark.parametrize("options", [{"inertia": "symmetric"}, {"inertia": "parameterised"},
                                     {"inertia": "parameterised", "mu": 0.3}])
def test_projection_inertia_variants_agree(options):
    model = cmbs.load("double-pendulum")
    rng = np.random.default_rng(8)
    qd = cmbs.velocities(model, model.q0, qd=rng.normal(size=model.n))
    terms = model.evaluate(model.q0, qd, 0.0)
    standard = formulation("projection").bind(model).accelerations(terms, model.q0, qd, 0.0)
    variant = formulation("projection", **options).bind(model).accelerations(terms, model.q0, qd, 0.0)
    np.testing.assert_allclose(variant.qdd, standard.qdd, atol=1e-10)
    np.testing.assert_allclose(variant.lam, standard.lam, atol=1e-9)


def test_augmented_lagrangian_removes_the_penalty_error():
    model = cmbs.load("four-bar").without_drivers()
    rng = np.random.default_rng(9)
    qd = cmbs.velocities(model, model.q0, qd=rng.normal(size=model.n))
    terms = model.evaluate(model.q0, qd, 0.0)
    exact = formulation("baumgarte").bind(model).accelerations(terms, model.q0, qd, 0.0)
    plain = formulation("penalty", alpha=1e4, iterations=0).bind(model).accelerations(terms, model.q0, qd, 0.0)
    augmented = formulation("penalty", alpha=1e4, iterations=50).bind(model).accelerations(terms, model.q0, qd, 0.0)
    # the penalty system is Baumgarte's with μΩ, Ω² ↔ ξω, ω² (here equal: 1·10 and 10²)
    assert np.abs(plain.qdd - exact.qdd).max() > 1e-4
    np.testing.assert_allclose(augmented.qdd, exact.qdd, atol=1e-9)
    np.testing.assert_allclose(augmented.lam, exact.lam, rtol=1e-7, atol=1e-7)


def test_sampled_inputs_drive_the_model():
    """A torque given as samples (linear and spline) gives the motion of the same torque as a function."""
    from cmbs.inputs import SampledInput

    model = cmbs.load("slider-crank-joint", crank_speed=0.0)
    times = np.linspace(0.0, 1.0, 201)
    torque = np.column_stack([np.sin(3 * times), np.zeros_like(times)])
    exact = simulate(model, t_end=1.0, u=lambda t, q, qd: np.array([math.sin(3 * t), 0.0]), rtol=1e-10, atol=1e-12)
    for interpolation, tolerance in (("linear", 1e-4), ("spline", 1e-8)):
        run = simulate(model, t_end=1.0, u=SampledInput(times, torque, interpolation), rtol=1e-10, atol=1e-12)
        assert np.abs(run.q - exact.q).max() < tolerance
        np.testing.assert_allclose(run["u"][:, 0], np.sin(3 * run.t), atol=1e-4)


def test_udwadia_kalaba_equals_the_symmetric_square_root_form():
    """Nicoara eq. (7)-(12) written with M^{1/2} by eigen-decomposition, ideal and non-ideal terms."""
    from cmbs.dynamics import UdwadiaKalaba

    model = cmbs.load("slider-crank-joint", gravity=9.81)
    rng = np.random.default_rng(12)
    q, qd = model.q0, model.qd0
    c = rng.normal(size=model.n)
    terms = model.evaluate(q, qd, 0.0)
    M, Q, A, gamma = terms.M, terms.Q, terms.A, terms.gamma
    values, vectors = np.linalg.eigh(M)
    inverse_root = (vectors / np.sqrt(values)) @ vectors.T
    a = np.linalg.solve(M, Q)
    B = A @ inverse_root
    B_pinv = np.linalg.pinv(B)
    expected = a + inverse_root @ B_pinv @ (gamma - A @ a) \
        + inverse_root @ (np.eye(model.n) - B_pinv @ B) @ inverse_root @ c
    solution = UdwadiaKalaba(nonideal=lambda t, q, qd: c).bind(model).accelerations(terms, q, qd, 0.0)
    np.testing.assert_allclose(solution.qdd, expected, atol=1e-12)


def test_penalty_passes_the_slider_crank_singular_positions():
    """Aghili's slider-crank with gravity crosses its singular position (crank at 90°) at 0.83 s
    and again later: the default penalty (scaled α, augmented Lagrangian stopping where the
    acceleration equations have no exact solution) stays on the branch θ2 = -2θ1 of the smooth
    reference ODE; the plain penalty with α = 1e7 drifts off by centiradians and says so."""
    from cmbs.library.mechanisms import slider_crank_branch

    model = cmbs.load("slider-crank", gravity=9.81)
    run = simulate(model, t_end=3.0, integrator="rk4", dt=1e-3, formulation="penalty")
    theta1, _ = slider_crank_branch(run.t, gravity=9.81)
    assert run.info["status"] == "success" and run.t[-1] == pytest.approx(3.0)
    assert np.abs(run["theta1"] - theta1).max() < 1e-8
    soft = simulate(model, t_end=3.0, integrator="rk4", dt=1e-3, formulation="penalty",
                    formulation_options={"alpha": 1e7, "iterations": 0})
    assert np.abs(soft["theta1"] - theta1).max() > 1e-2
    assert "penalty: the constraint accelerations missed the exact ones" in soft.info["note"]


@pytest.mark.parametrize("name, options, problem", [
    ("projection", {"threshold": "abc"}, "threshold must be a number >= 0, got 'abc'"),
    ("penalty", {"alpha": -5}, "alpha must be a number > 0"),
    ("penalty", {"iterations": 2.5}, "iterations must be an integer >= 0"),
    ("matrix-r", {"condition_growth": 1}, "condition_growth must be a number > 1"),
    ("baumgarte", {"omega": float("nan")}, "omega must be a number >= 0"),
    ("projection", {"mu": 0}, "mu must be a number > 0"),
])
def test_formulation_options_are_checked(name, options, problem):
    with pytest.raises(CmbsError, match=problem):
        formulation(name, **options)


def test_rk4_with_an_odd_final_time_runs_the_python_loop():
    model = cmbs.load("pendulum")
    run = simulate(model, t_end=1.0, integrator="rk4", dt=0.3)
    assert run.info["status"] == "success" and "compiled" not in run.info
    np.testing.assert_allclose(run.t, [0.0, 0.3, 0.6, 0.9, 1.0])


def test_projection_holds_at_every_output_instant():
    """project=True with an adaptive integrator: the output instants fall between steps and are
    interpolated; they are projected too, so every recorded |Φ| is below the projection tolerance
    (it reached 9e-5 at outputs while the projected steps were at 1e-14)."""
    model = cmbs.load("four-bar").without_drivers()
    run = simulate(model, t_end=20.0, project=True, dt=0.01)
    assert run.info["status"] == "success"
    assert run["constraint_error"].max() <= 1e-10
    assert run["velocity_constraint_error"].max() <= 1e-10
    free = simulate(model, t_end=20.0, dt=0.01)
    assert free["constraint_error"].max() > 1e-6       # without projection the drift is visible
