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


# ------------------------------------------------------------------ a grid of two inputs
def _closed_form_five_bar(left: float, right: float) -> tuple[np.ndarray, np.ndarray]:
    """The elbows B1, B2 in the plane (x, z) at the motor angles (five-bar-robot.urdf)."""
    return (np.array([-D / 2 + L1 * math.cos(left), L1 * math.sin(left)]),
            np.array([D / 2 + L1 * math.cos(right), L1 * math.sin(right)]))


def _cross(u: np.ndarray, v: np.ndarray) -> float:
    """The plane cross product u_x v_z - u_z v_x of two (x, z) vectors."""
    return float(u[0] * v[1] - u[1] * v[0])


def _assembles(left: float, right: float) -> bool:
    """The distal bars close the loop: |B1 - B2| < 2 L2 (the circles of radius L2 about the elbows
    meet in two points, one per assembly mode)."""
    B1, B2 = _closed_form_five_bar(left, right)
    return 0.0 < np.linalg.norm(B2 - B1) < 2 * L2


def test_five_bar_grid_is_the_closed_form_region_of_the_start_s_mode(five_bar):
    """Both motors over a turn (13 x 13 grid of 0.52 rad steps, none of its points on the
    singularity curve, where the two modes meet): the points reached are the grid's
    connected part, from the start's point, of the closed-form region |B1 - B2| < 2 L2 (two grid
    neighbours connected when the segment between them stays in the region: 200 samples); at each
    the tool C is the closed-form point on the start's side of B1 B2, to 1e-9 m; each limit
    lies on a grid line from a point reached to one not reached, where the distal bars are
    aligned (|B1 - B2| = 2 L2 to 1e-8 m) and the motors lock (σ_min/σ_max < 1e-4 with them held,
    > 0.1 for the chain)."""
    from cmbs.workspace import workspace_grid

    values = np.linspace(-3.0, 3.2, 13)
    result = workspace_grid(five_bar, ("left_motor", values), ("right_motor", values))
    motors = np.radians([100.0, 80.0])
    assert result.start == tuple(int(np.argmin(np.abs(values - angle))) for angle in motors)
    start_B1, start_B2 = _closed_form_five_bar(*motors)
    side = np.sign(_cross(start_B2 - start_B1, _points(five_bar, five_bar.q0)["C"] - start_B1))
    gaps = [abs(np.linalg.norm(np.subtract(*_closed_form_five_bar(a, b))) - 2 * L2) for a in values for b in values]
    assert min(gaps) > 1e-3                                 # no grid point on the singularity curve

    def segment_inside(i, j, k, l):
        s = np.linspace(0.0, 1.0, 200)
        return all(_assembles(a, b) for a, b in zip(values[i] + s * (values[k] - values[i]),
                                                    values[j] + s * (values[l] - values[j])))

    expected = np.zeros((13, 13), dtype=bool)
    expected[result.start] = True
    queue = [result.start]
    while queue:
        i, j = queue.pop()
        for k, l in ((i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1)):
            if 0 <= k < 13 and 0 <= l < 13 and not expected[k, l] and segment_inside(i, j, k, l):
                expected[k, l] = True
                queue.append((k, l))
    assert np.array_equal(result.reached, expected) and 0 < expected.sum() < 169
    for i, j in zip(*np.nonzero(result.reached)):
        B1, B2 = _closed_form_five_bar(values[i], values[j])
        d = np.linalg.norm(B2 - B1)
        u = (B2 - B1) / d
        C = (B1 + B2) / 2 + side * math.sqrt(L2**2 - (d / 2) ** 2) * np.array([-u[1], u[0]])
        np.testing.assert_allclose(_points(five_bar, result.q[i, j])["C"], C, atol=1e-9)
    boundary = sum(1 for i, j in zip(*np.nonzero(expected)) for k, l in ((i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1))
                   if 0 <= k < 13 and 0 <= l < 13 and not expected[k, l])
    assert len(result.limits) == boundary == result.limit_points.shape[0]
    for limit, point in zip(result.limits, result.limit_points):
        B1, B2 = _closed_form_five_bar(*point)
        assert abs(np.linalg.norm(B2 - B1) - 2 * L2) < 1e-8
        assert limit.relative_sigma < 1e-4 and limit.chain_relative_sigma > 0.1
    assert np.all(np.isnan(result.relative_sigma[~result.reached]))
    assert np.all(result.relative_sigma[result.reached] > 0.0)


def test_cmbs_workspace_grid_command_writes_its_result_and_figure(tmp_path, capsys):
    """Two --sweep options sweep a grid: the points reached and the limits are printed, --out
    writes the grid (.npz: the arrays; .csv: a row per point), --plot the figure; mistakes are
    one-line errors before any work."""
    from cmbs.cli import main

    out, figure, table = tmp_path / "grid.npz", tmp_path / "grid.png", tmp_path / "grid.csv"
    arguments = ["workspace", "five-bar-robot", "--sweep", "left_motor", "-3.14159", "3.14159", "7",
                 "--sweep", "right_motor", "-3.14159", "3.14159", "7"]
    assert main([*arguments, "--out", str(out), "--plot", str(figure)]) == 0
    printed = capsys.readouterr().out
    with np.load(out) as saved:
        reached = saved["reached"]
        assert saved["q"].shape == (7, 7, 4) and reached.shape == (7, 7)
        assert f"reached {int(reached.sum())} of 49 grid points on the branch of the start" in printed
        assert f"{saved['limit_values'].size} limits located on the grid lines: singular, the inputs lock" in printed
        assert list(saved["inputs"]) == ["left_motor", "right_motor"]
        assert np.isnan(saved["q"][~reached]).all() and not np.isnan(saved["q"][reached]).any()
    assert figure.stat().st_size > 10_000
    assert main([*arguments, "--out", str(table)]) == 0
    rows = np.genfromtxt(table, delimiter=",", names=True)
    assert rows.size == 49 and int(rows["reached"].sum()) == int(reached.sum())
    capsys.readouterr()
    assert main([*arguments, "--sweep", "left_elbow", "0", "1", "3"]) == 2
    assert "--sweep: at most two inputs (a grid of two), got 3" in capsys.readouterr().err
    assert main([*arguments, "--hold", "left_motor"]) == 2
    assert "a coordinate is given twice (swept twice, swept and held, or held twice)" in capsys.readouterr().err
    assert main([*arguments, "--hold", "left_elbow"]) == 2
    assert ("with left_motor, right_motor, left_elbow given, the other coordinates cannot follow every value near the "
            "start (A over them has rank 1, the chain's A 2): the given coordinates are not independent inputs"
            in capsys.readouterr().err)
    assert main([*arguments, "--out", str(tmp_path / "grid.txt")]) == 2
    assert "must end in .npz or .csv" in capsys.readouterr().err


def test_cmbs_workspace_one_input_writes_its_result(tmp_path, capsys):
    """One --sweep with --out (.npz) and --plot: the values, the configurations and the limits."""
    from cmbs.cli import main

    out, figure = tmp_path / "sweep.npz", tmp_path / "sweep.svg"
    assert main(["workspace", "five-bar-robot", "--sweep", "left_motor", "-3.14159", "3.14159", "37",
                 "--hold", "right_motor", "--out", str(out), "--plot", str(figure)]) == 0
    capsys.readouterr()
    with np.load(out) as saved:
        assert saved["q"].shape == (37, 4) and int(saved["reached"].sum()) == 19
        np.testing.assert_allclose(saved["limit_values"], [-0.7457224701, 2.474526987], atol=1e-9)
        assert str(saved["input"]) == "left_motor"
    assert figure.read_text().lstrip().startswith("<?xml")
