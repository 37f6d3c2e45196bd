"""Aghili's projected inverse dynamics: minimum-norm torque, weighted norm, passive joints and
the decoupling condition."""

import math

import numpy as np
import pytest

import cmbs
from cmbs.dynamics import Lagrange
from cmbs.inverse.projected import ControllabilityError, is_decoupled, passive_joint_torque, pidc_torque


def consistent_state(model, rng, independent):
    qd = cmbs.velocities(model, model.q0, qd=rng.normal(size=model.n), fixed=independent)
    qdd = cmbs.accelerations(model, model.q0, qd, qdd=rng.normal(size=model.n), fixed=independent)
    return model.q0, qd, qdd


def produced_acceleration(model, q, qd, tau):
    return Lagrange().bind(model).accelerations(model.evaluate(q, qd, 0.0, tau), q, qd, 0.0).qdd


def test_pidc_is_the_minimum_norm_torque():
    model = cmbs.load("arm-on-slider")  # 3 motors, 2 DOF: actuation is redundant
    rng = np.random.default_rng(1)
    q, qd, qdd = consistent_state(model, rng, ["theta2", "theta3"])
    tau = pidc_torque(model, q, qd, qdd)
    A = model.jacobian(q)
    assert np.abs(A @ tau).max() < 1e-10 * np.abs(tau).max()  # orthogonal to the constraint directions
    np.testing.assert_allclose(produced_acceleration(model, q, qd, tau), qdd, atol=1e-9)
    for _ in range(20):  # every other torque with the same acceleration is longer
        other = tau + A.T @ rng.normal(size=model.m)
        np.testing.assert_allclose(produced_acceleration(model, q, qd, other), qdd, atol=1e-9)
        assert np.linalg.norm(other) >= np.linalg.norm(tau)


def test_weighted_pidc_minimises_the_weighted_norm():
    model = cmbs.load("arm-on-slider")
    rng = np.random.default_rng(2)
    q, qd, qdd = consistent_state(model, rng, ["theta2", "theta3"])
    weight = np.diag([1.0, 5.0, 0.2])
    tau = pidc_torque(model, q, qd, qdd, weight=weight)
    np.testing.assert_allclose(produced_acceleration(model, q, qd, tau), qdd, atol=1e-9)
    A = model.jacobian(q)
    plain = pidc_torque(model, q, qd, qdd)
    measure = lambda x: np.linalg.norm(np.linalg.solve(weight, x))
    assert measure(tau) < measure(plain)
    for _ in range(20):
        assert measure(tau + A.T @ rng.normal(size=model.m)) >= measure(tau)


def test_passive_joint_gets_no_torque_where_controllable():
    model = cmbs.load("slider-crank-joint")
    rng = np.random.default_rng(3)
    q, qd, qdd = consistent_state(model, rng, ["theta1"])
    tau = passive_joint_torque(model, q, qd, qdd, actuated=["theta1"])
    assert abs(tau[1]) < 1e-9 * abs(tau[0])
    np.testing.assert_allclose(produced_acceleration(model, q, qd, tau), qdd, atol=1e-8)


def test_passive_joint_uncontrollable_at_the_singular_position():
    model = cmbs.load("slider-crank-joint")
    q = np.array([math.pi / 2, -math.pi])
    assert abs(model.constraints(q)[0]) < 1e-12 and np.abs(model.jacobian(q)).max() < 1e-12
    qd = np.zeros(2)
    qdd = np.array([1.0, -2.0])  # consistent: A = 0 and γ = 0 here
    with pytest.raises(ControllabilityError, match="theta2 cannot be left unactuated"):
        passive_joint_torque(model, q, qd, qdd, actuated=["theta1"])


def test_decoupling_condition():
    assert is_decoupled(cmbs.load("particle-circle"), np.array([0.6, 0.8]))  # M = m I
    assert not is_decoupled(cmbs.load("arm-on-slider"), cmbs.load("arm-on-slider").q0)


def test_inconsistent_acceleration_is_refused():
    model = cmbs.load("slider-crank-joint")
    with pytest.raises(cmbs.CmbsError, match="violates the constraints"):
        pidc_torque(model, model.q0, model.qd0, np.array([1.0, 1.0]))
