"""Prescribed motions (cmbs.motion) and ``cmbs inverse --motion``: the same forces as the
model's own drivers, from an expression, a result file and a plain table; clear errors."""

import numpy as np
import pytest

import cmbs
from cmbs.cli import main
from cmbs.errors import CmbsError
from cmbs.motion import prescribe, read_motion

FOUR_BAR_DRIVER = "alpha = pi/4*sin(pi*t - pi/2)"


def test_an_expression_reproduces_the_model_driver():
    model = cmbs.load("four-bar")
    times = np.linspace(0.0, 2.0, 21)
    own = cmbs.inverse_dynamics(model, times)
    prescribed = prescribe(model, read_motion(FOUR_BAR_DRIVER, model))
    assert prescribed.constraint_names[-1] == "motion alpha"
    again = cmbs.inverse_dynamics(prescribed, times)
    np.testing.assert_allclose(again.forces, own.forces, rtol=1e-12, atol=1e-9)
    assert np.abs(own.forces).max() > 100.0


def test_a_sampled_table_converges_to_the_closed_form(tmp_path):
    """Spline interpolation of samples of the driver: the torque error falls like h² or faster."""
    model = cmbs.load("four-bar")
    times = np.linspace(0.2, 1.8, 9)
    exact = cmbs.inverse_dynamics(model, times).forces[:, 0]
    errors = []
    for step in (0.1, 0.05):
        samples = np.arange(0.0, 2.0 + step / 2, step)
        values = np.pi / 4 * np.sin(np.pi * samples - np.pi / 2)
        path = tmp_path / f"alpha-{step}.csv"
        path.write_text("# crank angle, rad\nt,alpha\n" + "".join(f"{t:.17g},{v:.17g}\n" for t, v in zip(samples, values)))
        prescribed = prescribe(model, read_motion(str(path), model))
        errors.append(np.abs(cmbs.inverse_dynamics(prescribed, times).forces[:, 0] - exact).max())
    assert errors[0] < 0.02 * np.abs(exact).max()
    assert errors[1] < errors[0] / 3.5


def test_a_result_file_prescribes_the_driven_coordinate(tmp_path):
    model = cmbs.load("four-bar")
    motion = cmbs.kinematic_analysis(model, np.linspace(0.0, 2.0, 401))
    path = motion.save(tmp_path / "motion.npz")
    functions = read_motion(str(path), model)
    assert list(functions) == ["alpha"]        # all coordinates are in the file: the driven one is chosen
    times = np.linspace(0.1, 1.9, 7)
    forces = cmbs.inverse_dynamics(prescribe(model, functions), times).forces
    exact = cmbs.inverse_dynamics(model, times).forces
    np.testing.assert_allclose(forces, exact, atol=1e-3 * np.abs(exact).max())


def test_cli_motion_on_a_joint_model_with_reactions(tmp_path, capsys):
    out = tmp_path / "ida.npz"
    status = main(["inverse", "slider-crank-joint", "--motion", "theta1 = pi/4 + 2*t", "--t-end", "1", "--dt", "0.1",
                   "--reactions", "--out", str(out)])
    assert status == 0
    text = capsys.readouterr().out
    assert "force on theta1" in text and "closure force slider" in text
    result = cmbs.Trajectory.load(out)
    np.testing.assert_allclose(result.extras["joint force theta1"], result.extras["driver_forces"][:, 0],
                               rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(result.extras["joint force theta2"], 0.0, atol=1e-9)


@pytest.mark.parametrize("motion, message", [
    ("thet1 = 2*t", "has no coordinate 'thet1' (did you mean 'theta1'?)"),
    ("theta1 = 2*t+", "unexpected end"),
    ("theta1 = __import__('os')", "unexpected character"),
    ("theta1 2*t", "expected NAME = EXPRESSION"),
    ("theta1 = t; theta1 = 2*t", "given twice"),
    ("theta1 = 1/t", "motion of theta1: value or time derivatives not finite at t = 0"),
    ("theta1 = sqrt(t)", "motion of theta1: value or time derivatives not finite at t = 0: (f, f', f'') = (0.0, inf"),
])
def test_cli_motion_mistakes(motion, message, capsys):
    assert main(["inverse", "slider-crank-joint", "--motion", motion, "--t-end", "1", "--dt", "0.1"]) == 2
    assert message in capsys.readouterr().err


def test_motion_file_mistakes(tmp_path, capsys):
    short = tmp_path / "short.csv"
    short.write_text("t,theta1\n0,0.7\n0.5,0.8\n1,1.0\n1.5,1.3\n")
    assert main(["inverse", "slider-crank-joint", "--motion", str(short), "--t-end", "3", "--dt", "0.1"]) == 2
    assert "covers t = 0..1.5 s" in capsys.readouterr().err
    bad = tmp_path / "bad.csv"
    bad.write_text("# angle\nt,theta1\n0,0.7\n0.5,x\n")
    assert main(["inverse", "slider-crank-joint", "--motion", str(bad), "--t-end", "0.5", "--dt", "0.1"]) == 2
    assert "line 4: not a number" in capsys.readouterr().err
    other = tmp_path / "other.csv"
    other.write_text("t,beta\n0,0.7\n0.5,0.8\n1,1.0\n1.5,1.3\n")
    with pytest.raises(CmbsError, match="no column for coordinate"):
        read_motion(str(other), cmbs.load("slider-crank-joint"))
    with pytest.raises(CmbsError, match="no such motion file"):
        read_motion(str(tmp_path / "missing.csv"), cmbs.load("slider-crank-joint"))


def test_cli_track_follows_a_reference_expression(capsys):
    status = main(["track", "slider-crank-joint", "--reference", "theta1 = pi/4 + 0.5*sin(2*t)", "--t-end", "2",
                   "--dt", "0.01", "--initial-error", "0.05"])
    text = capsys.readouterr().out
    assert status == 0 and "ctc tracking of theta1" in text
    nrmse = float(text.split("NRMSE (of the reference's range) theta1 ")[1].split(" %")[0]) / 100
    assert 0.0 < nrmse < 0.02            # a 0.05 rad start error on a 1 rad range, removed in about 0.6 s
