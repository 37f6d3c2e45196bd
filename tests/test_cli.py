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
