"""Kinematics: assembly, velocity and acceleration analysis against the four-bar's closed-form
position solution, rank/DOF/redundancy, and singular configurations along a motion."""

import math

import numpy as np
import pytest

import cmbs
from cmbs.errors import ConvergenceError, ModelError
from cmbs.model.natural import NaturalModelBuilder
from helpers import first_derivative_fd, second_derivative_fd


def four_bar_points(t):
    """Closed form of the library four-bar: crank 2 m from A=(0,0), rocker 6 m from B=(10,0),
    coupler 10 m, upper branch; alpha(t) = (π/4) sin(πt - π/2)."""
    alpha = math.pi / 4 * math.sin(math.pi * t - math.pi / 2)
    p1 = 2.0 * np.array([math.cos(alpha), math.sin(alpha)])
    b = np.array([10.0, 0.0])
    d = np.linalg.norm(b - p1)
    a = (10.0**2 - 6.0**2 + d**2) / (2 * d)
    h = math.sqrt(10.0**2 - a**2)
    e = (b - p1) / d
    p2 = p1 + a * e + h * np.array([-e[1], e[0]])
    return np.array([*p1, *p2, alpha])


def test_four_bar_kinematic_analysis_matches_closed_form():
    model = cmbs.load("four-bar")
    times = np.linspace(0.0, 2.0, 81)
    motion = cmbs.kinematic_analysis(model, times)
    assert motion.names == ("P1.x", "P1.z", "P2.x", "P2.z", "alpha")
    for k in (0, 17, 40, 63, 80):
        t = times[k]
        np.testing.assert_allclose(motion.q[k], four_bar_points(t), atol=1e-9)
        np.testing.assert_allclose(motion.qd[k], first_derivative_fd(four_bar_points, t), atol=1e-7)
        np.testing.assert_allclose(motion.qdd[k], second_derivative_fd(four_bar_points, t), atol=2e-5)


def test_assembly_from_a_rough_guess_and_with_fixed_coordinates():
    model = cmbs.load("four-bar")
    q = cmbs.assemble(model, model.q0 + np.array([0.3, -0.2, 0.5, 0.4, 0.0]), 0.0)
    np.testing.assert_allclose(q, four_bar_points(0.0), atol=1e-10)
    undriven = cmbs.load("double-pendulum")
    guess = undriven.q0.copy()
    guess[undriven.coordinate_index("theta1")] = -0.5
    q = cmbs.assemble(undriven, guess, fixed=["theta1", "theta2"])
    assert q[undriven.coordinate_index("theta1")] == -0.5
    np.testing.assert_allclose(undriven.point_positions(q)[1], [math.cos(-0.5), math.sin(-0.5)], atol=1e-10)


def test_impossible_geometry_names_the_constraint():
    b = NaturalModelBuilder("open")
    b.add_point("A", 0.0, 0.0, fixed=True)
    b.add_point("B", 10.0, 0.0, fixed=True)
    b.add_point("P", 1.0, 1.0)
    b.add_segment("left", "A", "P", mass=1.0, com=(0.5, 0), inertia=0.1, length=2.0)
    b.add_segment("right", "P", "B", mass=1.0, com=(0.5, 0), inertia=0.1, length=3.0)
    with pytest.raises(ConvergenceError, match=r"did not converge in 30 Newton iterations.*constraint 'rigid"):
        cmbs.assemble(b.build(), max_iterations=30)


def test_velocity_and_acceleration_analysis_satisfy_the_constraints():
    model = cmbs.load("double-pendulum")
    qd_guess = np.zeros(model.n)
    qd_guess[model.coordinate_index("theta1")] = 0.7
    qd_guess[model.coordinate_index("theta2")] = -1.3
    qd = cmbs.velocities(model, model.q0, qd=qd_guess, fixed=["theta1", "theta2"])
    assert qd[model.coordinate_index("theta1")] == 0.7
    np.testing.assert_allclose(model.jacobian(model.q0) @ qd, 0.0, atol=1e-12)
    # point P1 velocity of a rod rotating at 0.7 rad/s
    p1 = model.point_positions(model.q0)[1]
    np.testing.assert_allclose(qd[:2], 0.7 * np.array([-p1[1], p1[0]]), atol=1e-12)
    qdd = cmbs.accelerations(model, model.q0, qd, fixed=["theta1", "theta2"])
    np.testing.assert_allclose(model.jacobian(model.q0) @ qdd, model.gamma(model.q0, qd), atol=1e-12)
    np.testing.assert_allclose(qdd[:2], -0.7**2 * p1, atol=1e-12)  # centripetal


def test_kinematic_analysis_needs_a_fully_driven_model():
    with pytest.raises(ModelError, match="1 degree\\(s\\) of freedom"):
        cmbs.kinematic_analysis(cmbs.load("pendulum"), np.linspace(0, 1, 5))


def parallelogram_with_redundant_bar():
    """Parallelogram four-bar with a fifth bar parallel to crank and rocker (a classic
    over-constrained linkage): 6 coordinates, 6 constraints, 1 DOF, one redundant row."""
    b = NaturalModelBuilder("parallelogram")
    for name, x, z in (("A", 0, 0), ("D", 2, 0), ("E", 1, 0.5)):
        b.add_point(name, x, z, fixed=True)
    for name, x, z in (("B", 0.6, 0.8), ("C", 2.6, 0.8), ("F", 1.6, 1.3)):
        b.add_point(name, x, z)
    for name, i, j in (("crank", "A", "B"), ("rocker", "D", "C"), ("coupler", "B", "C"), ("bf", "B", "F"),
                       ("cf", "C", "F"), ("extra", "E", "F")):
        b.add_segment(name, i, j, mass=1.0, com=(0.5, 0.0), inertia=0.1)
    return b.build()


def test_redundant_constraint_is_reported():
    model = parallelogram_with_redundant_bar()
    report = cmbs.constraint_report(model, model.q0)
    assert (report.n, report.m, report.rank, report.dof) == (6, 6, 5, 1)
    assert len(report.redundant) == 1
    # removing the named redundant row leaves a full-rank set of 5 rows
    keep = [k for k, name in enumerate(model.constraint_names) if name != report.redundant[0]]
    assert np.linalg.matrix_rank(model.jacobian(model.q0)[keep]) == 5


def driven_slider_crank():
    b = NaturalModelBuilder("driven-slider-crank")
    b.add_point("O", 0.0, 0.0, fixed=True)
    b.add_point("A", math.cos(math.pi / 4), math.sin(math.pi / 4))
    b.add_point("C", 2 * math.cos(math.pi / 4), 0.0)
    b.add_segment("crank", "O", "A", mass=1.0, com=(0.5, 0), inertia=1 / 12, length=1.0)
    b.add_segment("rod", "A", "C", mass=1.0, com=(0.5, 0), inertia=1 / 12, length=1.0)
    b.add_slider("slider", point="C", through=(0.0, 0.0), direction=(1.0, 0.0))
    b.add_angle("theta1", segment="crank")
    b.add_angle("theta2", from_segment="crank", to_segment="rod")
    b.add_driver("theta1", "pi/4 + t")
    return b.build()


def test_slider_crank_rank_drops_at_ninety_degrees():
    model = cmbs.load("slider-crank")
    assert cmbs.constraint_report(model, model.q0).dof == 1
    singular = model.q0.copy()
    names = model.coordinate_names
    singular[[names.index("A.x"), names.index("A.z"), names.index("C.x"), names.index("C.z")]] = [0, 1, 0, 0]
    singular[names.index("theta1")], singular[names.index("theta2")] = math.pi / 2, -math.pi
    assert np.abs(model.constraints(singular)).max() < 1e-12
    assert cmbs.constraint_report(model, singular).dof == 2


def test_singular_configuration_found_along_a_motion():
    model = driven_slider_crank()
    motion = cmbs.kinematic_analysis(model, np.linspace(0.0, 1.5, 151))
    found = cmbs.singular_configurations(model, motion)
    assert len(found) == 1
    assert found[0].t == pytest.approx(math.pi / 4, abs=1e-6)
    assert (found[0].rank, found[0].nominal_rank) == (5, 6)
    regular = cmbs.kinematic_analysis(model, np.linspace(0.0, 0.6, 61))
    assert cmbs.singular_configurations(model, regular) == []
