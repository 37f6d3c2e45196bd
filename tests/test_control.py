"""Controllers: computed torque reproduces the designed error dynamics, PD with inverse-dynamics
feed-forward recovers from a wrong initial state, zero-order hold samples and holds."""

import math

import numpy as np
import pytest

import cmbs
from cmbs.control import PD, ComputedTorque, Reference, ZeroOrderHold
from cmbs.errors import CmbsError


@pytest.fixture(scope="module")
def four_bar():
    model = cmbs.load("four-bar")
    motion = cmbs.kinematic_analysis(model, np.linspace(0.0, 4.0, 801))
    free = model.without_drivers()
    start = free.q0.copy()
    start[free.coordinate_index("alpha")] += 0.1  # wrong initial state
    start = cmbs.assemble(free, start, fixed=["alpha"])
    return model, motion, free, start


def test_computed_torque_error_follows_the_designed_dynamics(four_bar):
    """ë + 20 ė + 100 e = 0 with e(0) = -0.1, ė(0) = 0: e(t) = -0.1 (1 + 10 t) exp(-10 t)."""
    model, motion, free, start = four_bar
    law = ComputedTorque(free, Reference(motion, ("alpha",)), kp=100.0, kd=20.0)
    run = cmbs.simulate(free, t_end=2.0, u=law, q0=start, qd0=np.zeros(free.n), rtol=1e-10, atol=1e-12, dt=0.01)
    error = motion["alpha"][:run.t.size * 2:2] - run["alpha"]
    designed = -0.1 * (1 + 10 * run.t) * np.exp(-10 * run.t)
    assert run.info["status"] == "success"
    assert np.abs(error - designed).max() < 1e-5


def test_pd_with_feed_forward_recovers_from_a_wrong_start(four_bar):
    model, motion, free, start = four_bar
    torque = cmbs.inverse_dynamics(model, motion).force("alpha")
    feed_forward = cmbs.SampledInput(motion.t, torque, "spline")
    law = PD(free, Reference(motion, ("alpha",)), kp=2000.0, kd=300.0, feed_forward=lambda t: feed_forward(t))
    run = cmbs.simulate(free, t_end=3.0, u=law, q0=start, qd0=np.zeros(free.n), rtol=1e-9, atol=1e-11, dt=0.01)
    error = np.abs(motion["alpha"][:run.t.size * 2:2] - run["alpha"])
    assert error[0] == pytest.approx(0.1)
    assert error[run.t >= 2.0].max() < 1e-3 * error[0]


def test_zero_order_hold_samples_and_holds():
    calls = []

    def law(t, q, qd):
        calls.append(t)
        return np.array([t])

    held = ZeroOrderHold(law, period=0.1)
    values = [held(t, None, None)[0] for t in (0.0, 0.05, 0.0999, 0.1, 0.17, 0.2)]
    assert values == [0.0, 0.0, 0.0, 0.1, 0.1, 0.2]
    assert len(calls) == 3


def test_controllers_need_actuators_on_the_reference_coordinates():
    model = cmbs.load("double-pendulum")
    motion = cmbs.kinematic_analysis(cmbs.load("four-bar"), np.linspace(0, 1, 11))
    with pytest.raises(CmbsError, match="no coordinate"):
        Reference(motion, ("theta1",))
    fake = cmbs.Trajectory(motion.t, np.zeros((11, 6)), np.zeros((11, 6)), np.zeros((11, 6)), model.coordinate_names)
    with pytest.raises(CmbsError, match="actuators cannot act"):
        PD(model, Reference(fake, ("theta1",)), kp=1.0, kd=1.0)
