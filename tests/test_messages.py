"""Messages, units and consistency: what the library and the command line say about a run
(names, units, times) says it right."""

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
