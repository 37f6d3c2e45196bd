"""The simulate and compare commands."""


import numpy as np
import pytest

from cmbs.cli import main
from cmbs.trajectory import Trajectory


def test_simulate_writes_a_result_with_the_options_used(tmp_path, capsys):
    out = tmp_path / "dp.npz"
    assert main(["simulate", "double-pendulum", "--t-end", "1", "--formulation", "baumgarte", "--option", "omega=20",
                 "--out", str(out)]) == 0
    run = Trajectory.load(out)
    assert run.info["formulation"] == "baumgarte" and run.info["formulation_options"]["omega"] == 20
    assert run.t[-1] == 1.0 and {"lam", "energy", "constraint_error"} <= set(run.extras)
    assert "max constraint error" in capsys.readouterr().out


def test_failed_simulation_exits_1_and_keeps_the_computed_part(tmp_path, capsys):
    out = tmp_path / "sc.csv"
    assert main(["simulate", "slider-crank", "--t-end", "10", "--rtol", "1e-10", "--atol", "1e-12",
                 "--out", str(out)]) == 1
    run = Trajectory.load(out)
    assert run.info["status"] == "failed" and 0 < run.t[-1] < 10
    assert "singular configuration" in capsys.readouterr().err


def test_compare_prints_one_row_per_formulation(capsys):
    assert main(["compare", "four-bar", "--undriven", "--formulations", "lagrange,projection,udwadia-kalaba",
                 "--t-end", "1", "--rtol", "1e-10", "--atol", "1e-12"]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = {line.split()[0]: line.split() for line in lines[2:]}
    assert set(rows) == {"lagrange", "projection", "udwadia-kalaba"}
    assert float(rows["lagrange"][2]) == 0.0
    assert all(float(row[2]) < 1e-8 for row in rows.values())
    assert lines[1].split()[-5] == "drift" and all(float(row[-3]) < 1e-8 for row in rows.values())
    assert main(["compare", "four-bar", "--formulations", "lagrange", "--t-end", "0.5"]) == 0
    assert capsys.readouterr().out.splitlines()[2].split()[-3] == "-"      # driven: not judged


def test_compare_runs_all_six_formulations_by_default_and_only_with_an_explicit_integrator(capsys):
    assert main(["compare", "pendulum", "--t-end", "0.5", "--rtol", "1e-10", "--atol", "1e-12"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines[2:]] == ["lagrange", "baumgarte", "penalty", "matrix-r", "projection",
                                                       "udwadia-kalaba"]
    assert "deviation against lagrange" in lines[0]
    assert main(["compare", "pendulum", "--t-end", "0.5", "--integrator", "trapezoidal"]) == 2
    assert "--integrator trapezoidal brings its own formulation" in capsys.readouterr().err


def test_bad_dynamics_options_exit_2(tmp_path, capsys):
    assert main(["simulate", "pendulum", "--t-end", "1", "--formulation", "baumgarte", "--option", "alpha=3"]) == 2
    assert main(["simulate", "pendulum", "--t-end", "-1"]) == 2
    assert main(["simulate", "pendulum", "--t-end", "1", "--integrator", "trapezoidal",
                 "--formulation", "projection"]) == 2
    assert main(["simulate", "pendulum", "--t-end", "1", "--out", str(tmp_path / "x.txt")]) == 2
    assert main(["compare", "pendulum", "--t-end", "1", "--formulations", ","]) == 2
    for tolerance in ("--rtol", "--atol"):
        assert main(["simulate", "pendulum", "--t-end", "1", "--integrator", "dop853", f"{tolerance}=-1e-8",
                     "--out", str(tmp_path / "x.npz")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 7 and all(line.startswith("cmbs: error: ") for line in err)
    assert "rtol must be a finite number > 0 and < 1, got -1e-08" in err[5] and "atol" in err[6]
    assert list(tmp_path.iterdir()) == []


def test_the_n_four_bar_keeps_its_branch_from_the_command_line(tmp_path, capsys):
    """IFToMM A02 from the CLI with the settings docs/formulations.md gives for high precision
    (projection, RK4 at 1 ms, drift projection to 1e-12): B0 stays within 1e-3 m of the exact
    motion of the 1-DOF reduction through the first passage (t = 2.66 s), and the positions are
    projected to the tolerance given (the default, 1e-10, leaves constraint errors above 1e-12)."""
    from cmbs.library.n_four_bar import exact_b0

    out = tmp_path / "a02.npz"
    assert main(["simulate", "n-four-bar", "--param", "N=2", "--formulation", "projection", "--integrator", "rk4",
                 "--dt", "0.001", "--every", "50", "--t-end", "3.5", "--project", "--projection-tolerance", "1e-12",
                 "--out", str(out)]) == 0
    assert "success" in capsys.readouterr().out
    run = Trajectory.load(out)
    position, _ = exact_b0(run.t, 2)
    assert run.t[-1] == pytest.approx(3.5)
    assert np.max(np.hypot(run["B0.x"] - position[:, 0], run["B0.z"] - position[:, 1])) < 1e-3
    assert np.max(run["constraint_error"]) <= 1e-12
