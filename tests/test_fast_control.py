"""Computed-torque control in the compiled RK4 loop gives the Python loop's closed-loop results
(same law, same steps), and runs that it cannot compile fall back to Python."""

import numpy as np
import pytest

import cmbs
from cmbs.control import PD, ActuatorFault, ComputedTorque, Reference, SensorNoise, ZeroOrderHold, mass_fault
from cmbs.control.compiled_torque import computed_torque_kernel
from cmbs.errors import CmbsError, SingularSystemError
from cmbs.motion import prescribe, read_motion
from cmbs.simulate import simulate
from helpers import arm_on_slider_motion, library_four_bar_variant

H = 1e-3


@pytest.fixture(scope="module")
def four_bar():
    """The undriven four-bar, its driven motion α(t) as reference, and a start 0.1 rad off it."""
    driven = cmbs.load("four-bar")
    motion = cmbs.kinematic_analysis(driven, np.linspace(0.0, 1.0, 1001))
    plant = driven.without_drivers()
    start = motion.q[0].copy()
    start[plant.coordinate_index("alpha")] += 0.1
    return plant, Reference(motion, ("alpha",)), cmbs.assemble(plant, start, fixed=["alpha"])


def closed_loop(plant, u, start, compiled, t_end=0.5, **options):
    return simulate(plant, t_end=t_end, integrator="rk4", dt=H, u=u, q0=start, qd0=np.zeros(plant.n),
                    compiled=compiled, **options)


def assert_same_run(fast_run, python_run):
    assert fast_run.info["compiled"] and "compiled" not in python_run.info
    assert fast_run.info["status"] == python_run.info["status"] == "success"
    np.testing.assert_array_equal(fast_run.t, python_run.t)
    np.testing.assert_allclose(fast_run.q, python_run.q, rtol=0, atol=1e-11)
    np.testing.assert_allclose(fast_run.qd, python_run.qd, rtol=0, atol=1e-10)
    np.testing.assert_allclose(fast_run.qdd, python_run.qdd, rtol=1e-10, atol=1e-9)
    for key in ("u", "lam", "constraint_force"):
        np.testing.assert_allclose(fast_run[key], python_run[key], rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(fast_run["energy"], python_run["energy"], rtol=0, atol=1e-10)
    np.testing.assert_allclose(fast_run["velocity_constraint_error"], python_run["velocity_constraint_error"],
                               rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize("formulation", ["lagrange", "baumgarte", "projection", "matrix-r"])
def test_compiled_computed_torque_equals_the_python_law_on_the_four_bar(four_bar, formulation):
    plant, reference, start = four_bar
    law = ComputedTorque(plant, reference, kp=100.0, kd=20.0)
    fast_run, python_run = (closed_loop(plant, law, start, flag, formulation=formulation) for flag in (True, False))
    assert_same_run(fast_run, python_run)
    error = reference.motion["alpha"][:fast_run.t.size] - fast_run["alpha"]
    designed = -0.1 * (1 + 10 * fast_run.t) * np.exp(-10 * fast_run.t)  # ë + 20ė + 100e = 0
    assert np.abs(error - designed).max() < 1e-5


def test_compiled_computed_torque_is_chosen_automatically(four_bar):
    plant, reference, start = four_bar
    run = closed_loop(plant, ComputedTorque(plant, reference, kp=100.0, kd=20.0), start, None, t_end=0.01)
    assert run.info["compiled"] and run.info["status"] == "success"


def test_compiled_computed_torque_on_a_joint_model():
    """The slider-crank in joint coordinates tracking θ1(t) of a prescribed motion."""
    model = cmbs.load("slider-crank-joint", gravity=9.81)
    driven = prescribe(model, read_motion("theta1 = pi/4 + 0.5*sin(2*t)", model))
    reference = Reference(cmbs.kinematic_analysis(driven, np.linspace(0.0, 1.0, 1001)), ("theta1",))
    start = model.q0.copy()
    start[0] += 0.1
    start = cmbs.assemble(model, start, fixed=["theta1"])
    law = ComputedTorque(model, reference, kp=100.0, kd=20.0)
    fast_run, python_run = (closed_loop(model, law, start, flag) for flag in (True, False))
    assert_same_run(fast_run, python_run)
    assert abs(fast_run["theta1"][-1] - reference.motion["theta1"][500]) < 0.1 * 0.05


def test_compiled_computed_torque_with_two_coordinates_in_any_order():
    """Two tracked coordinates (spline columns, gains per coordinate) on the arm on a slider; the
    law does not depend on the order in which the reference names them."""
    arm, motion = arm_on_slider_motion()
    start = arm.q0.copy()
    start[1] += 0.05
    start = cmbs.assemble(arm, start, fixed=["theta2", "theta3"])
    laws = [ComputedTorque(arm, Reference(motion, ("theta2", "theta3")), kp=[100.0, 400.0], kd=[20.0, 40.0]),
            ComputedTorque(arm, Reference(motion, ("theta3", "theta2")), kp=[400.0, 100.0], kd=[40.0, 20.0])]
    state = (start + 0.01, np.full(arm.n, 0.1))
    np.testing.assert_allclose(laws[0](0.3, *state), laws[1](0.3, *state), rtol=1e-12, atol=1e-12)
    for law in laws:
        assert_same_run(*(closed_loop(arm, law, start, flag, t_end=0.3) for flag in (True, False)))


def test_compiled_law_on_its_own_model(four_bar):
    """A controller whose model is not the plant (coupler 10 % heavier): the law evaluates its own
    model, the dynamics the plant's."""
    plant, reference, start = four_bar
    nominal = library_four_bar_variant("four-bar heavier coupler", coupler_mass=5.5, actuator=True)
    assert nominal.coordinate_names == plant.coordinate_names
    law = ComputedTorque(nominal, reference, kp=100.0, kd=20.0)
    fast_run, python_run = (closed_loop(plant, law, start, flag, t_end=0.3) for flag in (True, False))
    assert_same_run(fast_run, python_run)
    exact = closed_loop(plant, ComputedTorque(plant, reference, kp=100.0, kd=20.0), start, True, t_end=0.3)
    assert np.abs(fast_run["u"] - exact["u"]).max() > 1.0  # the model error shows in the torque


@pytest.mark.parametrize("formulation", ["lagrange", "baumgarte"])
def test_compiled_sampled_computed_torque_equals_the_python_hold(four_bar, formulation):
    """A digital controller sampled every step (ZeroOrderHold with period dt) as the Python loop runs it."""
    plant, reference, start = four_bar

    def held() -> ZeroOrderHold:
        return ZeroOrderHold(ComputedTorque(plant, reference, kp=100.0, kd=20.0), period=H)

    fast_run, python_run = (closed_loop(plant, held(), start, flag, formulation=formulation) for flag in (True, False))
    assert_same_run(fast_run, python_run)
    continuous = closed_loop(plant, ComputedTorque(plant, reference, kp=100.0, kd=20.0), start, True,
                             formulation=formulation)
    assert np.abs(fast_run.q - continuous.q).max() > 1e-8  # the input is held, not re-evaluated at every stage


def test_compiled_law_gives_nan_inputs_where_the_python_law_fails(four_bar):
    """At q = 0 every bar of the four-bar has zero length: A_d is singular (the Python law says
    so, the compiled one gives NaN inputs, which end a compiled run as non-finite)."""
    plant, reference, _ = four_bar
    law = ComputedTorque(plant, reference, kp=100.0, kd=20.0)
    zeros = np.zeros(plant.n)
    with pytest.raises(SingularSystemError, match="dependent block A_d is singular"):
        law(0.1, zeros, zeros)
    kernel = computed_torque_kernel(law, held=False)
    u = np.zeros(plant.n_u)
    kernel.apply(kernel, 0, 0, zeros, zeros, 0.1, u)
    assert np.isnan(u).all()


def test_runs_the_compiled_loop_cannot_take_fall_back_to_python(four_bar):
    plant, reference, start = four_bar
    law = ComputedTorque(plant, reference, kp=100.0, kd=20.0)
    cases = [(plant, ActuatorFault(law, offset=5.0)), (plant, SensorNoise(law, position=1e-3, seed=1)),
             (mass_fault(plant, "coupler", factor=1.025), law), (plant, ZeroOrderHold(law, period=2 * H)),
             (plant, ZeroOrderHold(PD(plant, reference, kp=100.0, kd=20.0), period=H))]
    model = cmbs.load("slider-crank-joint")
    driven = prescribe(model, read_motion("theta1 = pi/4 + 0.5*sin(2*t)", model))
    wrapped = driven.without_drivers()  # the same equations behind a Python row-subset wrapper
    cases.append((wrapped, ComputedTorque(wrapped, Reference(cmbs.kinematic_analysis(driven, np.linspace(0, 1, 11)),
                                                             ("theta1",)), kp=100.0, kd=20.0)))
    for case_plant, u in cases:
        run = simulate(case_plant, t_end=0.01, integrator="rk4", dt=H, u=u)
        assert "compiled" not in run.info and run.info["status"] == "success"
        with pytest.raises(CmbsError, match="compiled loop cannot run"):
            simulate(case_plant, t_end=0.01, integrator="rk4", dt=H, u=u, compiled=True)
