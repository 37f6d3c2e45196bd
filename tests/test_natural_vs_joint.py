"""The same mechanism in natural and in joint coordinates: equal point positions, kinetic and
potential energy for matching states, and equal joint accelerations from the same torques."""

import math

import numpy as np
import pytest

import cmbs
from cmbs.dynamics import Lagrange


def natural_state(natural, joint, theta, theta_dot):
    """Natural coordinates and velocities of the configuration with joint angles ``theta``:
    point positions from the joint model's kinematics, velocities by central differences
    (exact to O(h²)), angles copied (both models measure them the same way)."""
    def coordinates(angles):
        points = dict(zip(joint.point_names, joint.point_positions(angles)))
        q = np.zeros(natural.n)
        for k, name in enumerate(natural.coordinate_names):
            if name.startswith("theta"):
                q[k] = angles[int(name[5:]) - 1]
            else:
                point, axis = name.split(".")
                q[k] = points[NATURAL_TO_JOINT[natural.name][point]]["xz".index(axis)]
        return q

    h = 1e-6
    q = coordinates(theta)
    qd = (coordinates(theta + h * theta_dot) - coordinates(theta - h * theta_dot)) / (2 * h)
    return q, qd


NATURAL_TO_JOINT = {
    "slider-crank": {"A": "crank.end", "C": "rod.end"},
    "passive-manipulator": {"P1": "link1.end", "P2": "link2.end", "P3": "link3.end"},
    "two-link-arm": {"P1": "upper.end", "P2": "lower.end"},
}
PAIRS = [("slider-crank", "slider-crank-joint"), ("passive-manipulator", "passive-manipulator-joint"),
         ("two-link-arm", "two-link-arm-joint")]


@pytest.mark.parametrize("natural_name, joint_name", PAIRS)
def test_same_positions_and_energies(natural_name, joint_name):
    natural, joint = cmbs.load(natural_name, gravity=9.81), cmbs.load(joint_name, gravity=9.81)
    rng = np.random.default_rng(2)
    for _ in range(5):
        theta, theta_dot = rng.uniform(-math.pi, math.pi, joint.n), rng.normal(size=joint.n)
        q, qd = natural_state(natural, joint, theta, theta_dot)
        natural_points = dict(zip(natural.point_names, natural.point_positions(q)))
        joint_points = dict(zip(joint.point_names, joint.point_positions(theta)))
        for point, joint_point in NATURAL_TO_JOINT[natural_name].items():
            np.testing.assert_allclose(natural_points[point], joint_points[joint_point], atol=1e-12)
        assert natural.kinetic_energy(q, qd) == pytest.approx(joint.kinetic_energy(theta, theta_dot), rel=1e-8)
        assert natural.potential_energy(q) == pytest.approx(joint.potential_energy(theta), rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("natural_name, joint_name", PAIRS)
def test_same_accelerations_under_the_same_torques(natural_name, joint_name):
    natural, joint = cmbs.load(natural_name, gravity=9.81), cmbs.load(joint_name, gravity=9.81)
    rng = np.random.default_rng(4)
    theta = cmbs.assemble(joint, joint.q0 + 0.2 * rng.normal(size=joint.n), fixed=["theta1"])
    theta_dot = cmbs.velocities(joint, theta, qd=rng.normal(size=joint.n), fixed=["theta1"])
    q, qd = natural_state(natural, joint, theta, theta_dot)
    q = cmbs.assemble(natural, q, fixed=[f"theta{k + 1}" for k in range(joint.n)])
    qd = cmbs.velocities(natural, q, qd=qd, fixed=[f"theta{k + 1}" for k in range(joint.n)])
    u = rng.normal(size=joint.n_u)
    joint_qdd = Lagrange().bind(joint).accelerations(joint.evaluate(theta, theta_dot, 0.0, u), theta, theta_dot, 0.0).qdd
    natural_qdd = Lagrange().bind(natural).accelerations(natural.evaluate(q, qd, 0.0, u), q, qd, 0.0).qdd
    angles = natural.coordinate_indices([f"theta{k + 1}" for k in range(joint.n)])
    np.testing.assert_allclose(natural_qdd[angles], joint_qdd, rtol=1e-8, atol=1e-9)


def test_arm_on_slider_endpoint_is_on_the_slider():
    model = cmbs.load("arm-on-slider")
    points = dict(zip(model.point_names, model.point_positions(model.q0)))
    np.testing.assert_allclose(points["link3.end"], [0.45, 0.5], atol=1e-9)
    assert cmbs.constraint_report(model, model.q0).dof == 2
