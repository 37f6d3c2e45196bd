"""The command line: every command's --help, listing, describing and a kinematics run that
writes a result file and a figure (run in-process and once as the installed console script)."""

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cmbs.cli import main
from cmbs.library import names
from cmbs.trajectory import Trajectory


@pytest.mark.parametrize("command", [[], ["models"], ["describe"], ["kinematics"], ["sweep"]])
def test_help(command, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([*command, "--help"])
    assert exit_info.value.code == 0
    assert "usage: cmbs" in capsys.readouterr().out


def test_models_lists_every_library_model(capsys):
    assert main(["models"]) == 0
    listed = [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    assert listed == names()


def test_describe_reports_dof_rank_and_masses(capsys):
    assert main(["describe", "human"]) == 0
    out = capsys.readouterr().out
    assert "n = 38" in out and "DOF          14" in out and "rank of A    24" in out
    assert "total 80.639" in out
    assert main(["describe", "chain", "--param", "links=5", "--param", "closed=true"]) == 0
    assert "DOF          3" in capsys.readouterr().out


def test_kinematics_writes_result_and_figure(tmp_path, capsys):
    out, figure = tmp_path / "fb.csv", tmp_path / "fb.png"
    assert main(["kinematics", "four-bar", "--t-end", "2", "--dt", "0.05", "--out", str(out),
                 "--plot", str(figure)]) == 0
    motion = Trajectory.load(out)
    assert motion.t.shape == (41,) and motion.names[-1] == "alpha"
    assert motion["alpha"].max() == pytest.approx(np.pi / 4, abs=1e-9)
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "alpha" in capsys.readouterr().out


def test_kinematics_without_out_prints_the_ranges_and_writes_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["kinematics", "four-bar", "--t-end", "1", "--dt", "0.5"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "four-bar: kinematics of 3 instants over [0, 1] s"
    alpha = next(line.split() for line in out if line.split()[0] == "alpha")
    assert float(alpha[2]) == pytest.approx(-np.pi / 4, abs=1e-4)     # (pi/4) sin(pi t - pi/2) at t = 0 and 1
    assert float(alpha[4]) == pytest.approx(np.pi / 4, abs=1e-4)
    assert list(tmp_path.iterdir()) == []


def test_bad_options_exit_2_without_writing(tmp_path, capsys):
    assert main(["kinematics", "four-bar", "--t-end", "-1", "--dt", "0.1", "--out", str(tmp_path / "a.npz")]) == 2
    assert main(["kinematics", "pendulum", "--t-end", "1", "--dt", "0.1", "--out", str(tmp_path / "a.npz")]) == 2
    assert main(["describe", "chain", "--param", "links"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 3 and all(line.startswith("cmbs: error: ") for line in err)
    assert list(tmp_path.iterdir()) == []


def _console_script() -> str | None:
    """The ``cmbs`` script of this interpreter's environment (a venv's bin/, which need not be
    on PATH), else the one on PATH."""
    beside = Path(sys.executable).parent / "cmbs"
    return str(beside) if beside.exists() else shutil.which("cmbs")


@pytest.mark.skipif(_console_script() is None, reason="console script not installed")
def test_console_script(tmp_path):
    result = subprocess.run([_console_script(), "describe", "no-such-model"], capture_output=True, text=True)
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr


@pytest.mark.parametrize("arguments, message", [
    (["simulate", "four-bar", "--undriven", "--t-end", "inf"], "--t-end must be a finite number > 0, got inf"),
    (["simulate", "four-bar", "--undriven", "--t-end", "1", "--rtol", "nan"], "--rtol must be a finite number > 0"),
    (["track", "four-bar", "--t-end", "1", "--kp", "-5"], "--kp must be a finite number >= 0, got -5.0"),
    (["track", "four-bar", "--t-end", "1", "--sample-rate", "0"], "--sample-rate must be a finite number > 0"),
    (["track", "four-bar", "--t-end", "1", "--initial-error", "nan"], "--initial-error must be a finite number"),
    (["kinematics", "four-bar", "--t-end", "1e9", "--dt", "1e-9", "--out", "k.csv"], "more than 10,000,000"),
    (["describe", "chain", "--param", "closed=maybe"], "parameter closed must be true or false, got 'maybe'"),
    (["describe", "chain", "--param", "links=3.5"], "parameter links must be a whole number, got 3.5"),
    (["simulate", "four-bar", "--undriven", "--t-end", "1", "--formulation", "baumgarte", "--option",
      "least_squares=maybe"], "option least_squares must be true or false, got 'maybe'"),
    (["simulate", "four-bar", "--t-end", "1", "--option", "omega"], "--option expects key=value, got 'omega'"),
    (["sweep", "slider-crank", "--vary", "crank_speed=1,abc", "--t-end", "0.1"],
     "parameter crank_speed must be a finite number, got 'abc'"),
    (["sweep", "slider-crank", "--vary", "crank_speed=1,2", "--formulation", "lagrangee", "--t-end", "0.1"],
     "--formulation: unknown 'lagrangee' (did you mean 'lagrange'?)"),
    (["sweep", "four-bar", "--undriven", "--mass", "crank=1,-1", "--t-end", "0.1"], "mass factors must be > 0"),
    (["simulate", "four-bar", "--t-end", "1", "--project", "--projection-tolerance", "0"],
     "--projection-tolerance must be a finite number > 0, got 0.0"),
    (["simulate", "four-bar", "--t-end", "1", "--projection-tolerance", "1e-12"],
     "--projection-tolerance sets the drift projection's tolerance: give --project too"),
])
def test_bad_values_one_line_exit_2(arguments, message, tmp_path, monkeypatch, capsys):
    """Numbers that are not finite or out of range, and yes/no values that are not, are named in one
    line with exit status 2 before any work (an infinite --t-end used to end in an OverflowError)."""
    monkeypatch.chdir(tmp_path)
    assert main(arguments) == 2
    err = capsys.readouterr().err
    assert err.startswith("cmbs: error: ") and err.count("\n") == 1 and message in err, err
    assert list(tmp_path.iterdir()) == []


def test_yes_no_words_are_flags(capsys):
    """--param closed=no is False (the word used to count as true and close the chain)."""
    for word, name in (("no", "chain4"), ("off", "chain4"), ("yes", "chain4-closed"), ("true", "chain4-closed")):
        assert main(["describe", "chain", "--param", f"closed={word}", "--param", "links=4"]) == 0
        first = capsys.readouterr().out.splitlines()[0].split()
        assert first == ["model", name], (word, first)


def test_kinematics_grid_is_that_of_simulate(tmp_path, capsys):
    """--dt 0.3 over 1 s gives 0, 0.3, 0.6, 0.9 and 1 (it used to be stretched to 0.333)."""
    out = tmp_path / "k.npz"
    assert main(["kinematics", "four-bar", "--t-end", "1", "--dt", "0.3", "--out", str(out)]) == 0
    assert np.allclose(np.load(out)["t"], [0.0, 0.3, 0.6, 0.9, 1.0], rtol=0, atol=1e-15)


def test_animate_mp4_without_ffmpeg_fails_before_the_run(tmp_path, monkeypatch, capsys):
    """--animate x.mp4 without ffmpeg used to be found out after the .npz and .png were written."""
    import matplotlib.animation

    monkeypatch.setattr(matplotlib.animation.writers, "is_available", lambda name: False)
    arguments = ["simulate", "pendulum", "--t-end", "0.1", "--out", str(tmp_path / "r.npz"), "--plot",
                 str(tmp_path / "r.png"), "--animate", str(tmp_path / "r.mp4")]
    assert main(arguments) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "needs ffmpeg" in err, err
    assert list(tmp_path.iterdir()) == []


def test_the_first_compilation_is_announced_once():
    """An interactive `cmbs` run says when it compiles (a fresh install's first run takes 1-2
    minutes): one line at the first compilation, none after."""
    numba = pytest.importorskip("numba")
    from cmbs.jit import announce_compilation

    lines = []
    announce_compilation(lines.append)

    @numba.njit
    def twice(x):
        return 2 * x

    assert lines == []
    assert twice(1) == 2 and twice(1.5) == 3.0          # two compilations
    assert len(lines) == 1 and "compiling the kernels" in lines[0]


@pytest.mark.parametrize("options, loop", [
    (["--integrator", "rk4", "--t-end", "0.3", "--dt", "0.1"], "compiled"),
    (["--integrator", "rk4", "--t-end", "0.35", "--dt", "0.1"], "Python loop (t_end is not a multiple of dt)"),
    (["--integrator", "rk4", "--t-end", "0.3", "--formulation", "matrix-r", "--project"], "compiled"),
    (["--integrator", "rk45", "--t-end", "0.3", "--formulation", "matrix-r", "--project"], "compiled"),
], ids=["compiled", "rk4-odd-end", "rk4-matrix-r-projection", "rk45-matrix-r-projection"])
def test_the_summary_says_whether_the_run_was_compiled(options, loop, capsys):
    """The summary line ends with the loop the run took, and the reason that run's note gives
    for the Python loop in a few words (the note itself has all of it)."""
    assert main(["simulate", "four-bar", *options]) == 0
    summary = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("four-bar:"))
    assert summary.endswith(f" s), {loop}"), summary
