"""Every script in examples/ runs (shortened) and writes its figure, so the examples never rot."""

import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
SHORT = {"baumgarte_drift.py": ["--t-end", "2"], "slider_crank_singular.py": ["--t-end", "1.5"],
         "compare_formulations.py": ["--t-end", "0.5"], "four_bar_inverse_dynamics.py": ["--t-end", "1"],
         "aghili_arm_on_slider.py": ["--t-end", "0.3"],
         "aghili_slider_crank.py": ["--t-end", "0.3", "--t-forward", "0.5"],
         "udwadia_kalaba_tracking.py": ["--t-end", "1"], "passive_manipulator_servo.py": ["--t-end", "0.5"],
         "thesis_four_bar_control.py": ["--t-end", "1"]}


def test_every_example_is_listed():
    assert sorted(p.name for p in EXAMPLES.glob("*.py")) == sorted(SHORT)


@pytest.mark.parametrize("script", sorted(SHORT))
def test_example_runs_and_writes_its_figure(script, tmp_path):
    result = subprocess.run([sys.executable, str(EXAMPLES / script), "--out-dir", str(tmp_path), *SHORT[script]],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    figure = tmp_path / script.replace(".py", ".png")
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "figure ->" in result.stdout
