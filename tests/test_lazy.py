"""Modules imported on first use: ``import cmbs`` leaves scipy's interpolate, optimize and sparse
unexecuted until first used, and they then work as usual, imported the usual way."""

import subprocess
import sys

import pytest

from cmbs.lazy import on_first_use

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


def test_on_first_use_imports_the_module_the_usual_way_at_the_first_attribute_read():
    probe = ("import sys; from cmbs.lazy import on_first_use; colorsys = on_first_use('colorsys'); "
             "print('colorsys' in sys.modules); print(colorsys.rgb_to_hsv(1.0, 0.0, 0.0), "
             "type(sys.modules['colorsys']) is type(sys), colorsys.rgb_to_hsv is sys.modules['colorsys'].rgb_to_hsv)")
    output = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout
    assert output.splitlines() == ["False", "(0.0, 1.0, 1.0) True True"]
    with pytest.raises(ModuleNotFoundError, match="no_such_module"):
        on_first_use("no_such_module").anything
