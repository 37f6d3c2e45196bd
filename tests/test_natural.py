"""Natural-coordinate models: mass matrix against rigid-body kinetic energy, A and γ against
finite differences for every constraint kind, forces against potentials and power, the angle
constraint at every quadrant, and a pendulum's motion against its closed-form period."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import cmbs
from cmbs.errors import ModelError
from cmbs.model.natural import NaturalModelBuilder, element_mass_matrix
from helpers import check_constraint_derivatives, kitchen_sink


def rigid_body_kinetic_energy(mass, length, com, inertia, ri, rj, vi, vj):
    """½ m |v_G|² + ½ I_G ω² from the two points' motion (independent of the element matrix)."""
    d, dv = rj - ri, vj - vi
    omega = (d[0] * dv[1] - d[1] * dv[0]) / length**2
    de = dv / length
    dn = np.array([-de[1], de[0]])
    v_g = vi + com[0] * de + com[1] * dn
    return 0.5 * mass * v_g @ v_g + 0.5 * inertia * omega**2


def test_element_mass_matrix_equals_rigid_body_kinetic_energy():
    rng = np.random.default_rng(1)
    for _ in range(50):
        mass, length = rng.uniform(0.1, 10), rng.uniform(0.1, 3)
        com = (rng.uniform(-1, 2) * length, rng.uniform(-0.5, 0.5) * length)
        inertia = rng.uniform(0.0, 1.0) * mass * length**2
        angle = rng.uniform(-np.pi, np.pi)
        ri = rng.normal(size=2)
        rj = ri + length * np.array([np.cos(angle), np.sin(angle)])
        # rigid velocities: vj - vi perpendicular to rj - ri
        vi = rng.normal(size=2)
        omega = rng.normal()
        vj = vi + omega * np.array([-(rj - ri)[1], (rj - ri)[0]])
        qd = np.concatenate([vi, vj])
        M = element_mass_matrix(mass, length, com, inertia)
        expected = rigid_body_kinetic_energy(mass, length, com, inertia, ri, rj, vi, vj)
        assert 0.5 * qd @ M @ qd == pytest.approx(expected, rel=1e-12)
        assert np.allclose(M, M.T)


@pytest.mark.parametrize("name, parameters", [
    ("particle-circle", {}), ("pendulum", {}), ("double-pendulum", {}), ("four-bar", {}),
    ("chain", {"links": 5}), ("chain", {"links": 6, "closed": True}), ("slider-crank", {}),
    ("passive-manipulator", {}), ("human", {}), ("slider-crank-joint", {}), ("arm-on-slider", {}),
    ("passive-manipulator-joint", {}), ("two-link-arm", {}), ("two-link-arm-joint", {}),
])
def test_library_model_derivatives(name, parameters):
    model = cmbs.load(name, **parameters)
    check_constraint_derivatives(model, np.random.default_rng(7))


def test_every_constraint_kind_derivatives():
    model = kitchen_sink()
    kinds = {name.split(" ")[0] for name in model.constraint_names}
    assert {"rigid", "distance", "angle", "slider"} <= kinds
    assert model.drivers.sum() == 3
    check_constraint_derivatives(model, np.random.default_rng(3), samples=5)


def test_constant_mass_matrix_matches_kinetic_energy_of_all_segments():
    """Global M assembled from elements = sum of the segments' rigid-body kinetic energies."""
    model = kitchen_sink()
    q = cmbs.assemble(model)
    qd = cmbs.velocities(model, q, 0.0, qd=np.zeros(model.n))
    assert np.abs(qd).max() > 0.05  # the drivers move the mechanism
    P = dict(zip(model.point_names, model.point_positions(q)))
    h = 1e-6
    V = dict(zip(model.point_names, (model.point_positions(q + h * qd) - model.point_positions(q - h * qd)) / (2 * h)))
    segments = {"crank": ("O", "A", 1.0, (0.5, 0.05), 0.1), "rod": ("A", "B", 2.0, (0.6, -0.02), 0.2),
                "block": ("B", "Bb", 0.7, (0.15, 0.0), 0.01), "hanger": ("D", "E", 0.4, (0.3, 0.1), 0.02)}
    expected = sum(rigid_body_kinetic_energy(m, np.linalg.norm(P[j] - P[i]), com, inertia, P[i], P[j], V[i], V[j])
                   for i, j, m, com, inertia in segments.values())
    expected += 0.5 * 0.5 * V["F"] @ V["F"]
    assert model.kinetic_energy(q, qd) == pytest.approx(expected, rel=1e-8)


def test_conservative_forces_are_minus_gradient_of_potential():
    model = kitchen_sink(drivers=False, loads=False)
    b_model = kitchen_sink(drivers=False, loads=True)
    rng = np.random.default_rng(5)
    for candidate in (model, b_model):
        q = candidate.q0 + 0.05 * rng.normal(size=candidate.n)
        h = 1e-6
        gradient = np.array([(candidate.potential_energy(q + h * e) - candidate.potential_energy(q - h * e)) / (2 * h)
                             for e in np.eye(candidate.n)])
        Q = candidate.forces(q, np.zeros(candidate.n), 0.0)
        if candidate is b_model:
            # remove the non-conservative time loads: push (E) and motor (psi), known at t = 0
            Q[candidate.coordinate_index("E.x")] -= 0.5
            Q[candidate.coordinate_index("E.z")] -= -1.0
        np.testing.assert_allclose(Q, -gradient, atol=1e-6)


def test_damper_power_and_inputs():
    model = kitchen_sink(drivers=False)
    rng = np.random.default_rng(11)
    q = model.q0 + 0.02 * rng.normal(size=model.n)
    qd = rng.normal(size=model.n)
    P = dict(zip(model.point_names, model.point_positions(q)))
    A_i, E_i = [model.coordinate_index(f"{p}.{a}") for p in ("A",) for a in "xz"], \
        [model.coordinate_index(f"{p}.{a}") for p in ("E",) for a in "xz"]
    e = (P["E"] - P["A"]) / np.linalg.norm(P["E"] - P["A"])
    rate = e @ (qd[E_i] - qd[A_i])
    power = qd @ (model.forces(q, qd, 0.3) - model.forces(q, np.zeros(model.n), 0.3))
    assert power == pytest.approx(-2.0 * rate**2, rel=1e-10)
    u = np.array([0.7, -1.1])
    dQ = model.forces(q, qd, 0.3, u) - model.forces(q, qd, 0.3)
    expected = np.zeros(model.n)
    expected[model.coordinate_index("phi")] = 1.5 * 0.7
    expected[model.coordinate_index("s")] = -1.1
    np.testing.assert_allclose(dQ, expected, atol=1e-14)
    t = 0.4
    dQt = model.forces(q, qd, t) - model.forces(q, qd, 0.0)
    assert dQt[model.coordinate_index("psi")] == pytest.approx(2 * math.sin(3 * t))
    assert dQt[model.coordinate_index("E.x")] == pytest.approx(0.5 * (math.cos(t) - 1.0))


@pytest.mark.parametrize("degrees", [-180, -135, -90, -45, 0, 30, 89.9, 90, 120, 179.5])
def test_angle_coordinate_is_well_conditioned_at_every_angle(degrees):
    theta = math.radians(degrees)
    b = NaturalModelBuilder("rotor")
    b.add_point("O", 0.0, 0.0, fixed=True)
    b.add_point("P", 2.0 * math.cos(theta), 2.0 * math.sin(theta))
    b.add_segment("bar", "O", "P", mass=1.0, com=(1.0, 0.0), inertia=0.3)
    b.add_angle("a", segment="bar", initial=theta + 0.05)
    model = b.build()
    q = cmbs.assemble(model, fixed=["P.x", "P.z"])
    assert math.remainder(q[2] - theta, 2 * math.pi) == pytest.approx(0.0, abs=1e-10)
    dphi = model.jacobian(q)[1, 2]
    assert dphi == pytest.approx(-2.0, rel=1e-9)  # -|u||v| cos(θ-φ), |u| = 1 (x axis), |v| = 2


def test_pendulum_small_oscillation_period():
    """Index-1 integration of the compound pendulum: period 2π√(I_O/(m g d)), energy conserved."""
    b = NaturalModelBuilder("pendulum")
    b.add_point("O", 0.0, 0.0, fixed=True)
    amplitude = math.radians(2.0)
    b.add_point("P", math.sin(amplitude), -math.cos(amplitude))
    b.add_segment("rod", "O", "P", mass=2.0, com=(0.5, 0.0), inertia=2.0 / 12.0, length=1.0)
    model = b.build()
    terms = model.new_terms()

    def rhs(t, y):
        q, qd = y[:2], y[2:]
        model.evaluate(q, qd, t, out=terms)
        K = np.block([[terms.M, terms.A.T], [terms.A, np.zeros((1, 1))]])
        return np.concatenate([qd, np.linalg.solve(K, np.concatenate([terms.Q, terms.gamma]))[:2]])

    period = 2 * math.pi * math.sqrt((2.0 / 3.0) / (2.0 * 9.81 * 0.5))
    y0 = np.concatenate([model.q0, np.zeros(2)])
    crossings = solve_ivp(rhs, (0, 3 * period), y0, rtol=1e-11, atol=1e-12,
                          events=lambda t, y: y[0], dense_output=True)
    times = crossings.t_events[0]
    measured = times[2] - times[0]
    # finite amplitude 2°: T = T0 (1 + θ0²/16 + ...)
    assert measured == pytest.approx(period * (1 + amplitude**2 / 16), rel=1e-6)
    energies = [model.energy(y[:2], y[2:]) for y in crossings.y.T]
    assert np.ptp(energies) < 1e-8


def test_builder_rejects_bad_entries():
    b = NaturalModelBuilder("bad")
    b.add_point("O", 0.0, 0.0, fixed=True)
    with pytest.raises(ModelError, match="duplicate name 'O'"):
        b.add_point("O", 1.0, 0.0)
    with pytest.raises(ModelError, match=r"segments.s: mass must be >= 0"):
        b.add_segment("s", "O", "P", mass=-1.0, com=(0, 0), inertia=1.0)
    with pytest.raises(ModelError, match="needs 'com'"):
        b.add_segment("s", "O", "P", mass=1.0)
    with pytest.raises(ModelError, match="inertia must be >= 0"):
        b.add_segment("s", "O", "P", mass=1.0, com=(0, 0), inertia=-2.0)
    with pytest.raises(ModelError, match="length must be > 0"):
        b.add_segment("s", "O", "P", mass=1.0, com=(0, 0), inertia=1.0, length=0.0)
    with pytest.raises(ModelError, match="must be finite"):
        b.add_point("Q", float("nan"), 0.0)
    b.add_segment("s", "O", "P", mass=1.0, com=(0.5, 0), inertia=0.1)
    with pytest.raises(ModelError, match=r"segments.s: unknown point 'P'"):
        b.build()
    b.add_point("P", 1.0, 0.0)
    b.add_point("Z", 3.0, 0.0)
    b.add_distance("d", "P", "Z")
    with pytest.raises(ModelError, match="no mass moves with point.*Z"):
        b.build()


def test_builder_rejects_a_spring_between_coincident_points():
    """A pendulum folded back onto its pivot: the spring from the pivot to the tip has no
    direction at the start (its initial length is rounding, 1.2e-16 m)."""
    b = NaturalModelBuilder("folded")
    b.add_point("O", 0.0, 0.0, fixed=True)
    b.add_point("P", 1.0, 0.0)
    b.add_point("T", 1.0 + math.cos(math.pi), math.sin(math.pi))
    b.add_segment("s", "O", "P", mass=1.0, com=(0.5, 0.0), inertia=0.1)
    b.add_segment("r", "P", "T", mass=1.0, com=(0.5, 0.0), inertia=0.1)
    b.add_spring("k", "O", "T", stiffness=10.0, rest_length=0.5)
    with pytest.raises(ModelError, match=r"springs.k: initial length .* \(nearly\) coincident"):
        b.build()



@pytest.mark.parametrize("name", ["four-bar", "human", "chain", "kitchen-sink (springs)", "slider-crank-joint"])
def test_vectorised_energy_history_equals_the_energy_row_by_row(name):
    model = kitchen_sink() if name.startswith("kitchen") else cmbs.load(name)
    rng = np.random.default_rng(3)
    q = model.q0 + 0.1 * rng.normal(size=(7, model.n))
    qd = rng.normal(size=(7, model.n))
    expected = [model.energy(a, b) for a, b in zip(q, qd)]
    np.testing.assert_allclose(model.energy_history(q, qd), expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(model.without_drivers().energy_history(q, qd), expected, rtol=1e-12, atol=1e-12)
