"""Lazily imported modules: ``import cmbs`` leaves scipy's interpolate, optimize and sparse
unexecuted until first used, and they then work as usual."""

import subprocess
import sys

import pytest

from cmbs.lazy import lazy_module

PROBE = """
import sys
import cmbs
unexecuted = [name for name in ("scipy.interpolate._interpolate", "scipy.optimize._minimize", "scipy.sparse._csr")
              if name in sys.modules]
print("executed before use:", unexecuted)
import numpy as np
from cmbs.inputs import interpolate
spline = interpolate.CubicSpline(np.arange(5.0), np.arange(5.0) ** 2)
print("after use:", "scipy.interpolate._interpolate" in sys.modules, float(spline(2.5)))
"""


def test_import_cmbs_defers_scipy_submodules_until_first_use():
    output = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, check=True).stdout
    assert "executed before use: []" in output
    assert "after use: True 6.25" in output            # the cubic through x² is x² itself


def test_a_lazy_submodule_is_bound_to_its_package_and_executed_at_first_use():
    """``import cmbs.model.joints`` after cmbs.fast made it lazy: the attribute path works."""
    probe = ("import sys, cmbs, cmbs.fast; lazy = type(sys.modules['cmbs.model.joints']).__name__; "
             "import cmbs.model.joints; print(lazy, cmbs.model.joints.JointModelBuilder.__name__, "
             "type(sys.modules['cmbs.model.joints']).__name__)")
    output = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout
    assert output.split() == ["_LazyModule", "JointModelBuilder", "module"]


def test_lazy_module_returns_an_imported_module_and_rejects_unknown_names():
    import math

    assert lazy_module("math") is math
    with pytest.raises(ImportError, match="no_such_module"):
        lazy_module("no_such_module")


def test_objects_are_frozen_out_of_the_final_collection_when_numba_is_loaded():
    """cmbs.jit registers gc.freeze at exit; a handler registered before importing cmbs runs
    after it (atexit is last-in, first-out) and sees the frozen objects."""
    probe = ("import atexit, gc; atexit.register(lambda: print('frozen', gc.get_freeze_count() > 0)); "
             "import cmbs.jit; print('compiled', cmbs.jit.COMPILED)")
    output = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout
    compiled = "compiled True" in output
    assert f"frozen {compiled}" in output
