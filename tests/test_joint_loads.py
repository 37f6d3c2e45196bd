"""Force elements of joint-coordinate models: springs and dampers between points, point forces
(ground or link frame, constant or functions of time) and joint torques, against the same
mechanism in natural coordinates, finite differences of the potential energy and of the point
positions, and energy conservation."""

from __future__ import annotations

import math

import numpy as np
import pytest

import cmbs
from cmbs.dynamics import Lagrange
from cmbs.errors import ModelError
from cmbs.model.joints import JointModelBuilder
from cmbs.model.natural import NaturalModelBuilder

G = 9.81
THETA = (-math.pi / 4, math.pi / 4)


def joint_arm(*, springs=True, loads=True, damping=0.7, extra=None) -> cmbs.Model:
    """The two-link arm (1 m, 1 kg rods) in joint angles θ1 (absolute), θ2 (relative)."""
    b = JointModelBuilder("arm-joint", gravity=(0.0, -G))
    b.add_link("upper", parent=None, coordinate="theta1", length=1.0, mass=1.0, com=(0.5, 0.0), inertia=1 / 12,
               q0=THETA[0])
    b.add_link("lower", parent="upper", coordinate="theta2", origin=(1.0, 0.0), length=1.0, mass=1.0,
               com=(0.5, 0.0), inertia=1 / 12, q0=THETA[1])
    if springs:
        b.add_spring("anchor", (1.5, 0.5), "lower.end", stiffness=40.0, damping=damping, rest_length=0.6)
        b.add_spring("base", "upper.origin", "lower.end", stiffness=15.0)
    if loads:
        b.add_force("push", point="upper.end", fx="2*sin(3*t)", fz=1.5)
        b.add_torque("elbow", coordinate="theta2", torque="0.5*cos(t)")
    if extra:
        extra(b)
    return b.build()


def natural_arm(*, damping=0.7) -> cmbs.Model:
    """The same arm in natural coordinates with the same springs and loads."""
    p1 = np.array([math.cos(THETA[0]), math.sin(THETA[0])])
    p2 = p1 + [math.cos(sum(THETA)), math.sin(sum(THETA))]
    b = NaturalModelBuilder("arm-natural", gravity=(0.0, -G))
    b.add_point("O", 0.0, 0.0, fixed=True)
    b.add_point("A", 1.5, 0.5, fixed=True)
    b.add_point("P1", *p1)
    b.add_point("P2", *p2)
    for name, i, j in (("upper", "O", "P1"), ("lower", "P1", "P2")):
        b.add_segment(name, i, j, mass=1.0, com=(0.5, 0.0), inertia=1 / 12, length=1.0)
    b.add_angle("theta1", segment="upper", initial=THETA[0])
    b.add_angle("theta2", from_segment="upper", to_segment="lower", initial=THETA[1])
    b.add_spring("anchor", "P2", "A", stiffness=40.0, damping=damping, rest_length=0.6)
    b.add_spring("base", "O", "P2", stiffness=15.0)
    b.add_force("push", point="P1", fx="2*sin(3*t)", fz=1.5)
    b.add_torque("elbow", angle="theta2", torque="0.5*cos(t)")
    return b.build()


def natural_state(natural, joint, theta, theta_dot):
    """Natural q, q̇ of the joint state (positions from the joint model, velocities by
    velocity analysis with the angle rates fixed)."""
    points = dict(zip(joint.point_names, joint.point_positions(theta)))
    where = {"P1": "upper.end", "P2": "lower.end"}
    q = np.array([points[where[name.split(".")[0]]]["xz".index(name.split(".")[1])] if "." in name
                  else theta[int(name[5:]) - 1] for name in natural.coordinate_names])
    fixed = ["theta1", "theta2"]
    q = cmbs.assemble(natural, q, fixed=fixed)
    qd = np.zeros(natural.n)
    qd[natural.coordinate_indices(fixed)] = theta_dot
    return q, cmbs.velocities(natural, q, qd=qd, fixed=fixed)


def test_the_same_arm_in_natural_and_joint_coordinates_moves_alike():
    """Springs, damper, a point force varying in time and a joint torque: the joint model's
    accelerations are the natural model's at the same states, and so are the spring energies."""
    joint, natural = joint_arm(), natural_arm()
    rng = np.random.default_rng(11)
    for t in (0.0, 0.4, 1.3):
        theta, theta_dot = rng.uniform(-math.pi, math.pi, 2), rng.normal(size=2)
        q, qd = natural_state(natural, joint, theta, theta_dot)
        joint_qdd = Lagrange().bind(joint).accelerations(joint.evaluate(theta, theta_dot, t), theta, theta_dot, t).qdd
        natural_qdd = Lagrange().bind(natural).accelerations(natural.evaluate(q, qd, t), q, qd, t).qdd
        np.testing.assert_allclose(natural_qdd[natural.coordinate_indices(["theta1", "theta2"])], joint_qdd,
                                   rtol=1e-9, atol=1e-9)
        assert joint.potential_energy(theta) == pytest.approx(natural.potential_energy(q), rel=1e-12, abs=1e-12)
    assert set(joint.work_sources) == set(natural.work_sources) == {"force 'push'", "torque 'elbow'",
                                                                      "damper 'anchor'"}


def _user_points(b):
    b.add_point("on-upper", link="upper", local=(0.3, 0.1))
    b.add_point("on-lower", link="lower", local=(0.7, -0.2))
    b.add_spring("across", "on-upper", "on-lower", stiffness=25.0)      # rest length: its length at q0


def test_conservative_forces_are_minus_the_gradient_of_the_potential():
    """Gravity and springs (between ground and link points, and between points of two links,
    off the link axes): Q(q, 0) = -∂V/∂q by central differences of V."""
    model = joint_arm(loads=False, damping=0.0, extra=_user_points)
    assert model.work_sources == ()
    rng = np.random.default_rng(5)
    for _ in range(4):
        q = rng.uniform(-math.pi, math.pi, 2)
        h = 1e-6
        gradient = [(model.potential_energy(q + h * e) - model.potential_energy(q - h * e)) / (2 * h)
                    for e in np.eye(2)]
        np.testing.assert_allclose(model.forces(q, np.zeros(2)), -np.array(gradient), rtol=1e-7, atol=1e-7)


def test_rest_length_defaults_to_the_length_at_q0():
    model = joint_arm(springs=False, loads=False, extra=_user_points)
    plain = joint_arm(springs=False, loads=False)
    assert model.potential_energy(model.q0) == pytest.approx(plain.potential_energy(plain.q0), abs=1e-14)
    np.testing.assert_allclose(model.forces(model.q0, np.zeros(2)), plain.forces(plain.q0, np.zeros(2)), atol=1e-12)


def test_a_link_frame_force_does_the_virtual_work_of_the_turning_force():
    """F = R(θ_lower) (fx, fz) at a point of the lower link (θ_lower = θ1 + θ2): Q_j = F·∂r/∂q_j,
    ∂r/∂q_j by central differences of the point's position; the torque adds T(t) to θ2."""
    def loads(b):
        b.add_point("grip", link="lower", local=(0.8, 0.15))
        b.add_force("follower", point="grip", fx="3*t", fz=-2.0, frame="link")
        b.add_torque("elbow", coordinate="theta2", torque="t^2")

    model = joint_arm(springs=False, loads=False, extra=loads)
    unloaded = joint_arm(springs=False, loads=False, extra=lambda b: b.add_point("grip", link="lower",
                                                                                  local=(0.8, 0.15)))
    grip = model.point_names.index("grip")
    rng = np.random.default_rng(8)
    for t in (0.3, 1.7):
        q, qd = rng.uniform(-math.pi, math.pi, 2), rng.normal(size=2)
        angle = q[0] + q[1]
        force = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]]) @ [3 * t, -2.0]
        h = 1e-6
        jacobian = np.column_stack([(model.point_positions(q + h * e)[grip] - model.point_positions(q - h * e)[grip])
                                    / (2 * h) for e in np.eye(2)])
        expected = jacobian.T @ force + [0.0, t * t]
        np.testing.assert_allclose(model.forces(q, qd, t) - unloaded.forces(q, qd, t), expected, rtol=1e-8,
                                   atol=1e-8)


def test_springs_without_dampers_conserve_energy_and_run_compiled():
    """The loop runs compiled (no Python input law for a spring), T + V is conserved, and the
    compiled loop gives the Python loop's numbers."""
    model = joint_arm(loads=False, damping=0.0, extra=_user_points)
    run = cmbs.simulate(model, t_end=2.0, integrator="rk4", dt=1e-3)
    assert run.info["compiled"] is True and "Python loop" not in run.info.get("note", "")
    assert run.info["energy_drift"] < 1e-8
    python = cmbs.simulate(model, t_end=2.0, integrator="rk4", dt=1e-3, compiled=False)
    np.testing.assert_allclose(run.q, python.q, rtol=0, atol=1e-10)
    adaptive = cmbs.simulate(model, t_end=2.0, rtol=1e-10, atol=1e-12)
    assert adaptive.info["energy_drift"] < 1e-7


def test_a_time_dependent_force_runs_compiled_and_a_damper_is_a_work_source():
    model = joint_arm()
    run = cmbs.simulate(model, t_end=0.5, integrator="rk4", dt=1e-3)
    assert run.info["compiled"] is True and run.info["status"] == "success"
    assert "energy_drift" not in run.info


@pytest.mark.parametrize("build, message", [
    (lambda b: b.add_spring("s", "upper.end", "upper.end", stiffness=1.0), "spring 's'.*both ends are 'upper.end'"),
    (lambda b: b.add_spring("s", (0, 0), (1, 0), stiffness=1.0), "spring 's'.*both ends are on the ground"),
    (lambda b: b.add_spring("s", "upper.end", (0, 0), stiffness=-1.0), "spring 's'.*stiffness and damping must be >= 0"),
    (lambda b: b.add_spring("s", "upper.end", "lower.tip", stiffness=1.0),
     "spring 's'.*unknown point 'lower.tip'"),
    (lambda b: b.add_spring("s", "upper.origin", (0.0, 0.0), stiffness=1.0), "spring 's'.*ends coincide at q0"),
    (lambda b: b.add_force("f", point="upper.end", fx=1.0, frame="body"), "force 'f'.*frame must be 'ground' or 'link'"),
    (lambda b: b.add_force("f", point="nowhere", fx=1.0), "force 'f'.*unknown point 'nowhere'"),
    (lambda b: b.add_torque("m", coordinate="theta3", torque=1.0), "torque 'm'.*unknown coordinate 'theta3'"),
    (lambda b: b.add_torque("m", coordinate="theta1", torque="sin("), "torque 'm'"),
])
def test_bad_force_elements_are_named(build, message):
    with pytest.raises(ModelError, match=message):
        joint_arm(springs=False, loads=False, extra=build)


def test_joint_reactions_take_the_springs_and_forces():
    """Newton-Euler with the springs, damper and point force applied at their points gives each
    joint's generalized force as the Lagrangian equations have it: here no actuator, so the
    elbow torque T(t) = 0.5 cos t on θ2 and nothing on θ1."""
    from cmbs.inverse.tree_reactions import tree_reactions

    model = joint_arm(extra=_user_points)
    rng = np.random.default_rng(3)
    for t in (0.2, 1.1):
        q, qd = rng.uniform(-math.pi, math.pi, 2), rng.normal(size=2)
        terms = model.evaluate(q, qd, t)
        qdd = np.linalg.solve(terms.M, terms.Q)
        joint_forces = tree_reactions(model, q, qd, qdd, np.zeros(0), t=t)["joint_forces"]
        assert joint_forces["theta1"] == pytest.approx(0.0, abs=1e-10)
        assert joint_forces["theta2"] == pytest.approx(0.5 * math.cos(t), abs=1e-10)
