"""Joint reactions of joint-coordinate models (cmbs.inverse.tree_reactions), checked against the
natural-coordinate reactions of the same mechanism, the Lagrangian driver forces, and the
momentum balance of the whole system by finite differences."""

import numpy as np
import pytest

import cmbs
from cmbs.errors import CmbsError
from cmbs.inverse import joint_reaction_history
from cmbs.inverse.reactions import joint_reactions
from cmbs.inverse.tree_reactions import tree_reactions
from cmbs.model.joints import JointModelBuilder
from cmbs.motion import prescribe, read_motion

ANGLES = ["theta1", "theta2", "theta3"]


def test_same_pin_forces_as_the_natural_coordinate_model():
    joint = cmbs.load("passive-manipulator-joint", gravity=9.81)
    natural = cmbs.load("passive-manipulator", gravity=9.81)
    rng = np.random.default_rng(4)
    for _ in range(3):
        theta, rate, u = rng.uniform(-2, 2, 3), rng.normal(size=3), rng.normal(scale=20.0, size=2)
        terms = joint.evaluate(theta, rate, 0.0, u)
        theta_dd = np.linalg.solve(terms.M, terms.Q)
        result = tree_reactions(joint, theta, rate, theta_dd, np.zeros(0), u)

        points = joint.point_positions(theta)     # link ends = natural points P1, P2, P3
        q = np.concatenate([points[1], points[3], points[5], theta])
        np.testing.assert_allclose(natural.constraints(q, 0.0), 0.0, atol=1e-12)
        qd = np.zeros(natural.n)
        qd[natural.coordinate_indices(ANGLES)] = rate
        qd = cmbs.velocities(natural, q, qd=qd, fixed=ANGLES)
        acc = cmbs.Lagrange().bind(natural).accelerations(natural.evaluate(q, qd, 0.0, u), q, qd, 0.0)
        np.testing.assert_allclose(acc.qdd[natural.coordinate_indices(ANGLES)], theta_dd, atol=1e-9)
        reference = joint_reactions(natural, q, qd, acc.qdd, acc.lam)["forces"]
        scale = max(np.abs(f).max() for f in reference.values())
        for link, point in (("link1", "O"), ("link2", "P1"), ("link3", "P2")):
            np.testing.assert_allclose(result["forces"][link], reference[(link, point)], atol=1e-9 * scale)
        # motor torques: the actuators on θ1, θ2, nothing on the passive θ3
        np.testing.assert_allclose([result["joint_forces"][a] for a in ANGLES], [u[0], u[1], 0.0],
                                   atol=1e-9 * scale)


def _telescope(gravity: float = 9.81):
    """A revolute arm carrying a prismatic slide and a revolute tip link closed onto a wall."""
    builder = JointModelBuilder("telescope", gravity=(0.0, -gravity))
    builder.add_link("arm", parent=None, coordinate="a", length=1.0, mass=2.0, com=(0.5, 0.0), inertia=0.2, q0=0.6)
    builder.add_link("slide", parent="arm", joint="prismatic", coordinate="s", origin=(0.3, 0.0), length=0.6,
                     mass=1.5, com=(0.3, 0.05), inertia=0.05, q0=0.4)
    builder.add_link("tip", parent="slide", coordinate="b", origin=(0.6, 0.0), length=0.5, mass=0.7,
                     com=(0.25, 0.0), inertia=0.015, q0=-1.9)
    builder.add_closure("wall", point="tip.end", to=(1.2, 0.0), directions="x")
    return builder.build()


def test_newton_euler_joint_forces_equal_the_lagrangian_driver_forces_with_a_prismatic_joint():
    model = prescribe(_telescope(), read_motion("a = 0.6 + 0.3*sin(2*t); s = 0.4 + 0.1*sin(3*t)", _telescope()))
    times = np.linspace(0.0, 1.5, 16)
    ida = cmbs.inverse_dynamics(model, times)
    reactions = joint_reaction_history(model, ida.motion)
    assert np.abs(ida.force("s")).max() > 1.0 and np.abs(ida.force("a")).max() > 1.0
    np.testing.assert_allclose(reactions["joint_forces"]["a"], ida.force("a"), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(reactions["joint_forces"]["s"], ida.force("s"), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(reactions["joint_forces"]["b"], 0.0, atol=1e-9)   # the tip joint is free


def test_momentum_balance_of_the_whole_mechanism_by_finite_differences():
    """Ground force on the first link + closure force + weight = d/dt of the total momentum."""
    base = _telescope()
    model = prescribe(base, read_motion("a = 0.6 + 0.3*sin(2*t); s = 0.4 + 0.1*sin(3*t)", base))
    h = 1e-3
    times = np.arange(0.0, 0.6 + h / 2, h)
    ida = cmbs.inverse_dynamics(model, times)
    reactions = joint_reaction_history(model, ida.motion)
    layout = base.equations.layout()
    centres = []
    for q in ida.motion.q:     # centres of mass from the link frames given by the point positions
        points = model.point_positions(q)
        frames = [(points[2 * k], points[2 * k + 1] - points[2 * k]) for k in range(3)]
        centre = np.zeros(2)
        for k, (origin, axis) in enumerate(frames):
            axis = axis / np.linalg.norm(axis)
            normal = np.array([-axis[1], axis[0]])
            centre += layout.mass[k] * (origin + layout.com[k][0] * axis + layout.com[k][1] * normal)
        centres.append(centre)
    momentum_rate = np.diff(np.array(centres), 2, axis=0) / h**2             # Σ m a_G at times[1:-1]
    ground = reactions["forces"]["arm"][1:-1]
    wall = np.outer(reactions["closures"]["wall"][1:-1], [1.0, 0.0])
    weight = layout.mass.sum() * layout.gravity
    assert np.abs(ground).max() > 10.0
    np.testing.assert_allclose(ground + wall + weight, momentum_rate, atol=1e-4 * np.abs(ground).max())


def test_natural_models_and_bad_multipliers_are_refused_clearly():
    model = _telescope()
    with pytest.raises(CmbsError, match="lam has shape"):
        tree_reactions(model, model.q0, model.qd0, np.zeros(model.n), np.zeros(5))
    with pytest.raises(CmbsError, match="joint-coordinate model"):
        natural = cmbs.load("pendulum")
        tree_reactions(natural, natural.q0, natural.qd0, np.zeros(natural.n), np.zeros(natural.m))
