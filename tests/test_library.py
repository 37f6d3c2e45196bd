"""The model library: every model loads assembled with the DOF its source gives."""

import numpy as np
import pytest

import cmbs
from cmbs.errors import ModelError
from cmbs.library import names


@pytest.mark.parametrize("name, parameters, n, dof", [
    ("particle-circle", {}, 2, 1),
    ("pendulum", {}, 2, 1),
    ("double-pendulum", {}, 6, 2),
    ("four-bar", {}, 5, 0),
    ("five-bar-robot", {}, 4, 2),
    ("chain", {"links": 7}, 14, 7),
    ("chain", {"links": 14, "closed": True}, 26, 12),
    ("slider-crank", {}, 6, 1),
    ("passive-manipulator", {}, 9, 3),
    ("human", {}, 38, 14),
    ("slider-crank-joint", {}, 2, 1),
    ("arm-on-slider", {}, 3, 2),
    ("passive-manipulator-joint", {}, 3, 3),
    ("two-link-arm", {}, 6, 2),
    ("two-link-arm-joint", {"tool": (0.8, 0.1)}, 2, 2),
    ("chaplygin-sleigh", {}, 3, 3),
    ("n-four-bar", {}, 6, 1),
    ("n-four-bar", {"N": 40}, 82, 1),
    ("spherical-pendulum", {}, 3, 2),
    ("heavy-top", {}, 12, 3),
    ("four-bar-3d", {}, 6, 1),
    ("bricard", {}, 24, 1),
    ("spatial-slider-crank", {}, 14, 1),
    ("flyball-governor", {}, 43, 4),
])
def test_library_models_assemble_with_their_dof(name, parameters, n, dof):
    model = cmbs.load(name, **parameters)
    assert model.n == n
    assert np.abs(model.constraints(model.q0, 0.0)).max(initial=0.0) < 1e-9
    assert np.abs(model.jacobian(model.q0) @ model.qd0 + model.constraints_t(model.q0)).max(initial=0.0) < 1e-9
    assert cmbs.constraint_report(model, model.q0).dof == dof
    assert model.source and model.description


def test_every_listed_model_loads():
    for name in names():
        assert cmbs.load(name).name


def test_four_bar_has_one_dof_without_its_driver():
    model = cmbs.load("four-bar")
    A = model.jacobian(model.q0)[~model.drivers]
    assert model.n - np.linalg.matrix_rank(A) == 1
    assert model.driver_names == ("crank",)


def test_human_model_structure():
    model = cmbs.load("human")
    assert (model.n, model.m) == (38, 24)
    assert sum(kind == "angle" for kind in model.coordinate_kinds) == 12
    assert len(model.point_names) == 13 and len(model.lines) == 12
    assert model.total_mass == pytest.approx(37.81 + 5.119 + 2 * (1.922 + 2.299 + 9.284 + 4.08 + 1.27), abs=1e-9)
    heights = dict(zip(model.point_names, model.point_positions(model.q0)[:, 1]))
    assert heights["head"] == pytest.approx(1.75, abs=1e-9)
    scaled = cmbs.load("human", body_mass=55.3, height=1.72)
    assert scaled.total_mass == pytest.approx(55.3, rel=1e-12)
    assert dict(zip(scaled.point_names, scaled.point_positions(scaled.q0)[:, 1]))["head"] == pytest.approx(1.72)


def test_library_parameter_errors():
    with pytest.raises(ModelError, match="has no parameter"):
        cmbs.load("chain", length=3)
    with pytest.raises(ModelError, match="positive integer"):
        cmbs.load("chain", links=0)
    with pytest.raises(ModelError, match="no library model or file 'nonesuch'"):
        cmbs.load("nonesuch")


@pytest.mark.parametrize("parameters, message", [
    ({"closed": "no"}, "parameter closed must be true or false, got 'no'"),
    ({"links": 3.0}, "parameter links must be a whole number, got 3.0"),
    ({"links": True}, "parameter links must be a whole number, got True"),
])
def test_library_parameters_have_their_defaults_kind(parameters, message):
    """A string where a flag is expected used to count as true (closed="no" closed the chain)."""
    with pytest.raises(ModelError, match=message):
        cmbs.load("chain", **parameters)


def test_simulate_takes_a_library_name_and_refuses_an_infinite_span():
    run = cmbs.simulate("pendulum", t_end=0.05, dt=0.01, integrator="rk4")
    assert run.info["status"] == "success" and run.t[-1] == pytest.approx(0.05)
    for bad in (float("inf"), float("nan"), "1", -1.0):
        with pytest.raises(cmbs.CmbsError, match="t_end must be a finite number > 0"):
            cmbs.simulate("pendulum", t_end=bad)
    with pytest.raises(cmbs.CmbsError, match="more than 10,000,000"):
        cmbs.simulate("pendulum", t_end=1e6, dt=1e-3)


def test_numpy_scalars_are_accepted_as_library_parameters():
    """A grid built with numpy gives np.int64 and np.float64 values: they are numbers too."""
    import numpy as np

    assert cmbs.load("chain", links=np.int64(4), closed=np.bool_(True)).name == "chain4-closed"
    assert cmbs.load("slider-crank", crank_speed=np.float64(1.5)).n > 0
