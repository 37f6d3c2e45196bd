"""Assembly stays on its branch: kinematic analysis on a coarse output grid, prescribed motions,
and the one assembly routine's refusal of an angle half a turn from its points; the assembly
tolerance is relative to the mechanism's size."""

import math

import numpy as np
import pytest

import cmbs
from cmbs.cli import main
from cmbs.errors import ConvergenceError
from cmbs.kinematics import BranchError, assemble, follow_branch
from cmbs.model.drivers import Constant
from cmbs.model.files import load_model_file
from cmbs.motion import prescribe
from cmbs.trajectory import Trajectory
from test_kinematics import four_bar_points


@pytest.mark.parametrize("dt", [1.0, 2.0, 0.75])
def test_a_coarse_output_grid_keeps_the_assembly_branch(dt):
    """The crank tip at alpha and the coupler above the ground (closed form) at every output,
    however far apart the outputs are: at dt = 1 the analysis used to put the crank at -135 deg
    while alpha = +45 deg."""
    times = np.arange(0.0, 4.0 + 1e-9, dt)
    motion = cmbs.kinematic_analysis(cmbs.load("four-bar"), times)
    for t, q in zip(times, motion.q):
        np.testing.assert_allclose(q, four_bar_points(t), atol=1e-9)


def test_cli_kinematics_on_a_coarse_grid(tmp_path):
    out = tmp_path / "k.csv"
    assert main(["kinematics", "four-bar", "--t-end", "4", "--dt", "1", "--out", str(out)]) == 0
    motion = Trajectory.load(out)
    for t, q in zip(motion.t, motion.q):
        alpha = q[motion.names.index("alpha")]
        tip = q[[motion.names.index("P1.x"), motion.names.index("P1.z")]]
        np.testing.assert_allclose(tip, 2.0 * np.array([math.cos(alpha), math.sin(alpha)]), atol=1e-9)
        assert q[motion.names.index("P2.z")] > 0, f"coupler below the ground at t = {t}"


def unreachable_arm(tmp_path):
    """An arm held at 45 deg (upper link O-E), its lower link E-T of 0.76 m (as drawn): the tip's x,
    driven as 1 + t, is out of reach beyond E.x + 0.76 = 1.4616, at t = 0.4616."""
    path = tmp_path / "arm.toml"
    path.write_text("""
[model]
name = "arm"
[points]
O = { x = 0.0, z = 0.0, fixed = true }
E = { x = 0.7, z = 0.7 }
T = { x = 1.0, z = 1.4 }
[segments.upper]
points = ["O", "E"]
mass = 1.0
com = [0.5, 0.0]
inertia = 0.1
[segments.lower]
points = ["E", "T"]
mass = 1.0
com = [0.5, 0.0]
inertia = 0.1
[angles.shoulder]
segment = "upper"
[drivers.reach]
coordinate = "T.x"
expression = "1 + t"
[drivers.shoulder]
coordinate = "shoulder"
expression = "pi/4"
""")
    return path


def test_kinematics_that_cannot_follow_the_branch_fails_with_a_message(tmp_path, capsys):
    path = unreachable_arm(tmp_path)
    with pytest.raises(ConvergenceError, match=r"cannot follow the assembly branch beyond t=0\.461"):
        cmbs.kinematic_analysis(load_model_file(path), np.linspace(0.0, 2.0, 5))
    assert main(["kinematics", str(path), "--t-end", "2", "--dt", "0.5", "--out", str(tmp_path / "k.csv")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot follow the assembly branch" in err


ANGLES = {"theta1": 1.6535, "theta2": -1.1641, "theta3": -2.0602}


def link_direction(model, q, i, j):
    points = model.point_positions(q)
    d = points[model.point_names.index(j)] - points[model.point_names.index(i)]
    return math.atan2(d[1], d[0])


def test_prescribe_keeps_every_link_at_its_angle():
    """Absolute direction of link k = θ1 + ... + θk (relative angles): link 3 used to point at
    +90 deg while the angles summed to -90 deg."""
    model = cmbs.load("passive-manipulator")
    prescribed = prescribe(model, {name: Constant(value) for name, value in ANGLES.items()})
    q = prescribed.q0
    assert np.max(np.abs(prescribed.constraints(q))) < 1e-10
    total = 0.0
    for (i, j), value in zip((("O", "P1"), ("P1", "P2"), ("P2", "P3")), ANGLES.values()):
        total += value
        difference = (link_direction(prescribed, q, i, j) - total + math.pi) % (2 * math.pi) - math.pi
        assert abs(difference) < 1e-9


def test_assembly_refuses_an_angle_half_a_turn_away():
    """Newton from the model's q0 with the angles held converges to the spurious root of link 3's
    angle row; the one assembly routine refuses it."""
    model = cmbs.load("passive-manipulator")
    q = model.q0.copy()
    for name, value in ANGLES.items():
        q[model.coordinate_index(name)] = value
    with pytest.raises(BranchError, match="theta3 half a turn away"):
        assemble(model, q, fixed=list(ANGLES))


def test_follow_branch_moves_held_coordinates_continuously():
    """Moving the crank of the four-bar from -45 deg to +45 deg with alpha held keeps the coupler
    above the ground (the closed form's branch) at the end."""
    model = cmbs.load("four-bar").without_drivers()
    q = follow_branch(model, model.q0, 0.0, 0.0, fixed=["alpha"], fixed_to=[math.pi / 4])
    np.testing.assert_allclose(q, four_bar_points(1.0), atol=1e-9)


def scaled_four_bar(tmp_path, scale):
    text = f"""
[model]
name = "four-bar-{scale:g}"
[points]
A = {{ x = 0.0, z = 0.0, fixed = true }}
B = {{ x = {10 * scale!r}, z = 0.0, fixed = true }}
P1 = {{ x = {1.3 * scale!r}, z = {-1.5 * scale!r} }}
P2 = {{ x = {8.2 * scale!r}, z = {5.9 * scale!r} }}
[segments.crank]
points = ["A", "P1"]
length = {2 * scale!r}
mass = 1.0
com = [0.5, 0.0]
inertia = 0.1
[segments.coupler]
points = ["P1", "P2"]
length = {10 * scale!r}
mass = 1.0
com = [0.5, 0.0]
inertia = 0.1
[segments.rocker]
points = ["P2", "B"]
length = {6 * scale!r}
mass = 1.0
com = [0.5, 0.0]
inertia = 0.1
[angles.alpha]
segment = "crank"
initial = -0.8
"""
    path = tmp_path / f"four-bar-{scale:g}.toml"
    path.write_text(text)
    return load_model_file(path)


@pytest.mark.parametrize("scale", [1e-3, 1.0, 100.0])
def test_assembly_accuracy_does_not_depend_on_the_mechanism_size(tmp_path, scale):
    """Each segment's length to 1e-12 relative whatever the units' scale; the tolerance used to be
    1e-10 m² on |IJ|² - L², a relative length error up to 5e-7 on a centimetre segment."""
    model = scaled_four_bar(tmp_path, scale)
    guess = model.q0 * (1 + 0.02 * np.sin(np.arange(model.n)))
    q = assemble(model, guess, fixed=["alpha"])
    points = model.point_positions(q)
    for (i, j), length in zip((("A", "P1"), ("P1", "P2"), ("P2", "B")), (2.0, 10.0, 6.0)):
        d = points[model.point_names.index(j)] - points[model.point_names.index(i)]
        assert abs(np.hypot(*d) / (length * scale) - 1.0) < 1e-12


def test_a_run_refuses_a_start_off_the_constraints_or_half_a_turn_away():
    """simulate used to integrate from any q0: a link drawn the wrong way round (theta3 = 0 while
    link 3 points back along link 2) ran as another mechanism, with exit status 0."""
    model = cmbs.load("passive-manipulator")
    moved = model.q0.copy()
    moved[model.coordinate_index("P1.x")] += 0.01
    flipped = model.q0.copy()
    flipped[model.coordinate_index("P3.x")] = 0.0        # P3 back at P1's x: link 3 reversed, lengths kept
    assert np.max(np.abs(model.constraints(flipped))) < 1e-12
    with pytest.raises(cmbs.CmbsError, match="q0 violates constraint 'rigid link[12]'"):
        cmbs.simulate(model, t_end=0.1, q0=moved)
    with pytest.raises(cmbs.CmbsError, match="qd0 violates constraint"):
        cmbs.simulate(model, t_end=0.1, qd0=np.ones(model.n))
    with pytest.raises(cmbs.CmbsError, match="angle theta3 = 0 rad .* half a turn away"):
        cmbs.simulate(model, t_end=0.1, q0=flipped)
