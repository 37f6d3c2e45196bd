"""Closed-chain robots: the library's five-bar parallel manipulator (``five-bar-robot``: a URDF
and a robot file closing it by a ``line`` closure), and the workspace of an input coordinate
(:func:`cmbs.workspace.workspace`, ``cmbs workspace``) with its limits and singular
configurations against closed forms: a crank-rocker four-bar's dead centres (Grashof) and the
five-bar's type-2 singularities.

Simulations run in the Python loop (compiled=False; the compiled robot loops are tested in
tests/test_robot.py and tests/test_robot_dynamics.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import cmbs
from cmbs.model.robot import frame_placement
from cmbs.workspace import workspace
from test_robot_closures import write_four_bar

#: the five-bar's dimensions (five-bar-robot.urdf): motors at x = ∓D/2, proximal L1, distal L2
D, L1, L2 = 0.2, 0.3, 0.25


@pytest.fixture(scope="module")
def five_bar():
    return cmbs.load("five-bar-robot")


def _plane(point: np.ndarray) -> np.ndarray:
    """(x, z) of a point of the mechanism's plane y = 0."""
    return np.array([point[0], point[2]])


def _points(model, q) -> dict[str, np.ndarray]:
    """The five-bar's joint points B1, B2 (elbows) and C (the tool, and the right distal bar's end)."""
    def at(link, local=(0.0, 0.0, 0.0)):
        rotation, origin = frame_placement(model, q, link)
        return _plane(origin + rotation @ np.asarray(local))

    return {"B1": at("left_distal"), "B2": at("right_distal"), "C": at("tool"), "C2": at("right_distal", (L2, 0, 0))}


def test_five_bar_loads_closed_with_two_dof(five_bar):
    """Four joint angles, the two rows of the line closure at C of rank 2 (no redundant row),
    DOF 2; at the start the motors are at 100° and 80°, the elbows at ∓47.47°, and the tool at
    C = (0, 0.4939) by the closed form (B1, B2 on the proximal circles, C at L2 from both)."""
    report = cmbs.constraint_report(five_bar, five_bar.q0)
    assert (five_bar.n, five_bar.m, report.rank, report.dof, report.redundant) == (4, 2, 2, 2, ())
    assert five_bar.constraint_names == ("C.line1", "C.line2")
    np.testing.assert_allclose(np.degrees(five_bar.q0[[0, 2]]), [100.0, 80.0], atol=1e-9)
    points = _points(five_bar, five_bar.q0)
    B1 = np.array([-D / 2 + L1 * math.cos(math.radians(100)), L1 * math.sin(math.radians(100))])
    height = B1[1] + math.sqrt(L2**2 - B1[0] ** 2)
    np.testing.assert_allclose(points["C"], [0.0, height], atol=1e-12)
    np.testing.assert_allclose(points["C2"], points["C"], atol=1e-15)
    np.testing.assert_allclose(points["B1"], B1, atol=1e-15)


def test_five_bar_keeps_its_energy_with_zero_torques(five_bar):
    """Released at rest with zero torques, 1 s (Lagrange, DOP853 at rtol 1e-10): T + V kept to
    1e-8 J (measured 1.1e-10 J of 6.1 J) and the loop closed to 1e-9 m, while the motors turn by
    radians."""
    run = cmbs.simulate(five_bar, t_end=1.0, dt=0.05, integrator="dop853", rtol=1e-10, atol=1e-12, compiled=False)
    assert run.info["status"] == "success"
    energy = five_bar.energy_history(run.q, run.qd)
    assert np.abs(energy - energy[0]).max() < 1e-8
    assert np.abs([five_bar.constraints(q) for q in run.q]).max() < 1e-9
    assert np.ptp(run.q[:, 0]) > 1.0


def test_five_bar_type_2_singularities_are_the_sweeps_limits(five_bar):
    """The left motor swept over a turn with the right one held at 80°: the remaining four-bar
    A1-B1-C-B2 (B2 fixed) reaches the left motor's angles with |B1 - B2| <= 2 L2, so the branch
    ends where the distal bars are aligned (C between B1 and B2: a type-2 singularity, the
    motors locked and the tool free to move across): θ1 = β ± α with β the direction of
    B2 - A1 and cos α = (L1² + g² - 4 L2²) / (2 L1 g), g = |B2 - A1|.  Limits to 1e-8 rad
    (measured 8e-11), σ_min/σ_max there below 1e-4 with the motors held, of order 1 for the
    chain; the distal bars aligned there; no other singular configuration between."""
    result = workspace(five_bar, "left_motor", np.linspace(-np.pi, np.pi, 37), held=["right_motor"])
    A1, B2 = np.array([-D / 2, 0.0]), np.array([D / 2 + L1 * math.cos(math.radians(80)),
                                                 L1 * math.sin(math.radians(80))])
    g = np.linalg.norm(B2 - A1)
    beta, alpha = math.atan2(*(B2 - A1)[::-1]), math.acos((L1**2 + g**2 - 4 * L2**2) / (2 * L1 * g))
    assert [limit.value for limit in result.limits] == pytest.approx([beta - alpha, beta + alpha], abs=1e-8)
    assert (result.low, result.high) == (result.limits[0].value, result.limits[1].value)
    assert result.held == pytest.approx({"right_motor": math.radians(80)})
    for limit in result.limits:
        assert limit.relative_sigma < 1e-4 and limit.chain_relative_sigma > 0.1
        points = _points(five_bar, limit.q)
        np.testing.assert_allclose(np.linalg.norm(points["B1"] - points["B2"]), 2 * L2, atol=1e-9)
    inside = (result.values > beta - alpha) & (result.values < beta + alpha)
    assert np.array_equal(result.reached, inside) and result.singular == ()


def test_cmbs_workspace_command(capsys):
    """``cmbs workspace five-bar-robot --sweep left_motor -3.14159 3.14159 37 --hold right_motor``
    prints the range reached and both limits; without --hold it names the DOF left."""
    from cmbs.cli import main

    assert main(["workspace", "five-bar-robot", "--sweep", "left_motor", "-3.14159", "3.14159", "37",
                 "--hold", "right_motor"]) == 0
    out = capsys.readouterr().out
    assert "reached left_motor in [-0.7457224701, 2.474526987] (19 of 37 values)" in out
    assert out.count("singular, the inputs lock") == 2
    assert main(["workspace", "five-bar-robot", "--sweep", "left_motor", "0", "1", "3"]) == 2
    assert "with left_motor given, 1 degree(s) of freedom are left: hold 1 more coordinate(s)" in \
        capsys.readouterr().err


# ------------------------------------------------------------------ a crank-rocker four-bar
@pytest.fixture(scope="module")
def four_bar(tmp_path_factory):
    """The thesis four-bar (crank a = 2 from A, coupler b = 10, rocker c = 6 from B, ground g = 10:
    Grashof, s + l = 12 <= p + q = 16, the crank the shortest: a crank-rocker) as three joint
    angles about y closed at P2 by a line closure along y; its start points."""
    path, start = write_four_bar(tmp_path_factory.mktemp("four-bar"), "line")
    return cmbs.load(path), start


def _angle(v: np.ndarray) -> float:
    """The angle of v in the plane y = 0 as a turn about +y measures it (x towards -z)."""
    return math.atan2(-v[2], v[0])


def test_rocker_range_ends_at_the_dead_centres(four_bar):
    """The rocker driven over a turn: its range is bounded by the dead centres of the crank and
    coupler, collinear extended (|A - P2| = a + b) and folded (|A - P2| = b - a): the rocker's
    angle from B→A is arccos((g² + c² - (a ± b)²) / (2 g c)) (law of cosines), on the side of
    the start.  Limits to 1e-8 rad (measured 2.5e-11), singular with the rocker held
    (σ_min/σ_max < 1e-4), the crank and coupler collinear there (the sine of their angle below
    1e-4: at 1e-10 from the fold in the input, the angles are √ of it away; measured 1e-5); the
    chain itself keeps its rank."""
    model, start = four_bar
    A, B, P1, P2 = (start[key] for key in ("A", "B", "P1", "P2"))
    a, b, c, g = (np.linalg.norm(v) for v in (P1 - A, P2 - P1, P2 - B, B - A))
    result = workspace(model, "rocker-joint", np.linspace(-np.pi, np.pi, 73))
    expected = []
    for length in (b - a, a + b):
        turn = math.acos((g**2 + c**2 - length**2) / (2 * g * c))
        angle = _angle(A - B) + turn - _angle(P2 - B)              # the start's side: P2 above the ground line
        expected.append((angle + math.pi) % (2 * math.pi) - math.pi)
    assert [limit.value for limit in result.limits] == pytest.approx(sorted(expected), abs=1e-8)
    for limit in result.limits:
        assert limit.relative_sigma < 1e-4 and limit.chain_relative_sigma > 0.1
        crank = frame_placement(model, limit.q, "coupler")[1] - A
        coupler = frame_placement(model, limit.q, "rocker")[0] @ (P2 - B) + B - frame_placement(model, limit.q,
                                                                                                 "coupler")[1]
        assert abs(np.cross(crank, coupler)[1]) < 1e-4 * a * b    # sin of their angle: √ of the input's 1e-10
    assert result.singular == ()


def test_crank_turns_fully_and_swings_the_rocker_between_its_limits(four_bar):
    """The crank driven over a turn (Grashof crank-rocker): every value reached, no limit, no
    singular configuration (the transmission angle between coupler and rocker never 0 or 180°),
    and the rocker's swing within its dead-centre range, to the grid's resolution (5° steps:
    within 1e-3 rad of the limits)."""
    model, _ = four_bar
    rocker = workspace(model, "rocker-joint", np.linspace(-np.pi, np.pi, 5))
    result = workspace(model, "crank-joint", np.linspace(-np.pi, np.pi, 73))
    assert result.reached.all() and result.limits == () and result.singular == ()
    swing = result.q[:, model.coordinate_index("rocker-joint")]
    assert rocker.low - 1e-12 <= swing.min() < rocker.low + 1e-3
    assert rocker.high - 1e-3 < swing.max() <= rocker.high + 1e-12
