"""Messages, units and consistency: what the library and the command line say about a run
(names, units, times) says it right."""

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import cmbs
from cmbs.errors import CmbsError


def test_force_on_an_undriven_coordinate_names_the_driven_ones():
    result = cmbs.inverse_dynamics(cmbs.load("four-bar"), np.array([0.0, 0.1]))
    with pytest.raises(CmbsError, match=r"no driver force on 'hip'.*driven coordinates are alpha"):
        result.force("hip")
    with pytest.raises(CmbsError, match=r"did you mean 'alpha'"):
        result.force("alfa")


README = Path(__file__).resolve().parents[1] / "README.md"
#: names the README's prose lists under a package it names once (`cmbs.inverse` also has ...)
README_PROSE = ["cmbs.inverse.pidc_torque", "cmbs.inverse.passive_joint_torque", "cmbs.inverse.is_decoupled",
                "cmbs.inverse.joint_reactions", "cmbs.inverse.servo_inverse_dynamics", "cmbs.control.PD",
                "cmbs.control.ComputedTorque", "cmbs.control.PIDC", "cmbs.control.Hybrid",
                "cmbs.control.UdwadiaKalabaTracking", "cmbs.control.ZeroOrderHold", "cmbs.control.robustness_study",
                "cmbs.model.equations.from_callables"]


def _is_module(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except ModuleNotFoundError:      # a parent is a module, not a package
        return False


def _readme_names() -> dict[str, list[str]]:
    """Every dotted cmbs name of the README (and README_PROSE), grouped by the module path they
    go through (``cmbs.model.joints`` for cmbs.model.joints.JointModelBuilder)."""
    names = set(re.findall(r"\bcmbs(?:\.[A-Za-z_]\w*)+", README.read_text())) | set(README_PROSE)
    groups: dict[str, list[str]] = {}
    for name in sorted(names):
        parts = name.split(".")
        depth = 1
        while depth < len(parts) - 1 and _is_module(".".join(parts[:depth + 1])):
            depth += 1
        groups.setdefault(".".join(parts[:depth]), []).append(name)
    return groups


def test_every_name_the_readme_shows_resolves_after_a_plain_import_cmbs():
    """Each group in a fresh interpreter: ``import cmbs`` and then the attribute path, as written."""
    groups = _readme_names()
    assert {"cmbs.model.equations", "cmbs.model.joints", "cmbs.inverse"} <= set(groups)
    processes = {prefix: subprocess.Popen([sys.executable, "-c", "import cmbs\n" + "\n".join(
        f"assert {name} is not None" for name in names)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for prefix, names in groups.items()}
    failures = {prefix: process.communicate()[1].strip().splitlines()[-1:] for prefix, process in processes.items()}
    assert {prefix: lines for prefix, lines in failures.items() if lines} == {}
