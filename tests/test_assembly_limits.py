"""Position analysis within coordinate limits (``Model.coordinate_limits``, a robot's joint limits
on request): :func:`cmbs.assemble` keeps the free coordinates within them, against the closed
form of a two-link arm reaching a point (its two solutions, elbow up and elbow down)."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

import cmbs
from cmbs.model.robot import Inertial, TreeJoint, TreeLink, build_robot, frame_placement
from cmbs.model.robot_targets import PoseDriver

#: upper arm and forearm lengths (m), and the point the forearm's end is driven to (x, z)
L1, L2, TARGET = 0.5, 0.4, (0.6, 0.3)


def _placement(x: float) -> np.ndarray:
    matrix = np.eye(4)
    matrix[0, 3] = x
    return matrix


def _arm(position: tuple[object, object, object] = (TARGET[0], 0.0, TARGET[1])) -> cmbs.Model:
    """A planar two-link arm in the plane x-z (joints about y: a turn θ carries x towards -z) whose
    forearm end is driven to ``position`` (default TARGET) by a pose driver."""
    def inertial(length):
        return Inertial(1.0, _placement(length / 2), np.diag([1e-3, 1e-2, 1e-2]))

    links = [TreeLink("base"), TreeLink("upper", inertial(L1)), TreeLink("fore", inertial(L2))]
    joints = [TreeJoint("shoulder", "revolute", "base", "upper", _placement(0.0), (0, 1, 0)),
              TreeJoint("elbow", "revolute", "upper", "fore", _placement(L1), (0, 1, 0))]
    driver = PoseDriver("tip", "fore", point=(L2, 0.0, 0.0), position=position)
    return build_robot("arm", links, joints, drivers=[driver])


def _closed_form(elbow_sign: float) -> np.ndarray:
    """(shoulder, elbow) reaching TARGET: cos θ2 = (d² - L1² - L2²) / (2 L1 L2), the sign chosen,
    θ1 = atan2(-z, x) - atan2(L2 sin θ2, L1 + L2 cos θ2)."""
    x, z = TARGET
    elbow = elbow_sign * math.acos((x * x + z * z - L1 * L1 - L2 * L2) / (2 * L1 * L2))
    return np.array([math.atan2(-z, x) - math.atan2(L2 * math.sin(elbow), L1 + L2 * math.cos(elbow)), elbow])


def _limits(elbow_low: float, elbow_high: float) -> tuple[np.ndarray, np.ndarray]:
    return np.array([-np.inf, elbow_low]), np.array([np.inf, elbow_high])


GUESS = np.array([0.5, -1.0])          # nearer the elbow-down solution


def test_without_limits_newton_reaches_the_solution_near_its_guess():
    np.testing.assert_allclose(cmbs.assemble(_arm(), GUESS), _closed_form(-1.0), atol=1e-10)


def test_limits_that_exclude_newton_s_solution_give_the_other_one():
    """The elbow limited to [0, π]: Newton's solution (elbow down) is refused and the bounded
    least squares from it reflected into the limits reaches the elbow-up solution, to 1e-10; the
    tool point is on the target."""
    model = _arm().replace(coordinate_limits=_limits(0.0, math.pi))
    q = cmbs.assemble(model, GUESS)
    np.testing.assert_allclose(q, _closed_form(1.0), atol=1e-10)
    rotation, origin = frame_placement(model, q, "fore")
    np.testing.assert_allclose(origin + rotation @ [L2, 0.0, 0.0], [TARGET[0], 0.0, TARGET[1]], atol=1e-12)


def test_limits_met_by_newton_s_solution_change_nothing():
    model = _arm().replace(coordinate_limits=_limits(-math.pi, 0.0))
    np.testing.assert_array_equal(cmbs.assemble(model, GUESS), cmbs.assemble(_arm(), GUESS))


def test_no_configuration_within_the_limits_is_a_one_line_error():
    """Neither solution has the elbow within [0.2, 0.5] rad: the error names the coordinate
    Newton's solution put beyond its limits, and the residual left within them."""
    model = _arm().replace(coordinate_limits=_limits(0.2, 0.5))
    with pytest.raises(cmbs.ConvergenceError) as error:
        cmbs.assemble(model, GUESS)
    message = str(error.value)
    assert "\n" not in message
    assert (f"no configuration within the coordinate limits at t=0: Newton's solution puts 'elbow' at "
            f"{_closed_form(-1.0)[1]:.6g}, beyond its limits [0.2, 0.5]; within the limits the smallest residual "
            "found is") in message
    assert error.value.constraint.startswith("tip.")


def test_a_held_coordinate_is_not_moved_into_its_limits():
    """Limits bound the coordinates assembly moves: the shoulder held at the elbow-down solution's
    value, outside its limits [0.5, 1], keeps it, and the elbow (unlimited) reaches that solution."""
    model = _arm().replace(coordinate_limits=(np.array([0.5, -np.inf]), np.array([1.0, np.inf])))
    solution = _closed_form(-1.0)
    q = cmbs.assemble(model, np.array([solution[0], -1.0]), fixed=["shoulder"])
    assert q[0] == solution[0] and not 0.5 <= q[0] <= 1.0
    np.testing.assert_allclose(q, solution, atol=1e-10)


def test_kinematic_analysis_stops_where_a_joint_reaches_its_limit():
    """The target turned about the shoulder at 1 rad/s (its distance kept): the shoulder angle
    falls as θ1(0) - t, so with the shoulder limited to [-1, 0.5] the motion stops at
    t = θ1(0) + 1 (to 1e-5 s), the error naming the joint and its limit."""
    radius, start = math.hypot(*TARGET), math.atan2(TARGET[1], TARGET[0])
    model = _arm((f"{radius!r}*cos({start!r} + t)", 0.0, f"{radius!r}*sin({start!r} + t)"))
    model = model.replace(q0=_closed_form(-1.0), coordinate_limits=(np.array([-1.0, -np.inf]), np.array([0.5, np.inf])))
    with pytest.raises(cmbs.ConvergenceError) as error:
        cmbs.kinematic_analysis(model, np.linspace(0.0, 2.0, 21))
    message = str(error.value)
    assert "the motion takes shoulder beyond its limit -1" in message
    stopped = float(message.split("beyond t=")[1].split(" ")[0])
    assert stopped == pytest.approx(_closed_form(-1.0)[0] + 1.0, abs=1e-5)


@pytest.mark.parametrize("limits, problem", [((np.zeros(3), np.ones(3)), "shape"),
                                             ((np.array([0.0, 1.0]), np.array([1.0, 0.5])), "lower > upper"),
                                             ((np.array([0.0, np.nan]), np.ones(2)), "NaN")])
def test_malformed_limits_are_refused(limits, problem):
    with pytest.raises(cmbs.ModelError, match="coordinate_limits must be two arrays"):
        _arm().replace(coordinate_limits=limits)


def test_limits_survive_replace_and_pickle_read_only():
    model = pickle.loads(pickle.dumps(_arm().replace(coordinate_limits=_limits(0.0, math.pi)).without_drivers()))
    lower, upper = model.coordinate_limits
    assert not lower.flags.writeable and not upper.flags.writeable
    np.testing.assert_array_equal(upper, [np.inf, math.pi])
