"""cmbs.model.natural_lanes: the terms of a block of states are, lane by lane and bit for bit,
those of the one-state natural-coordinate kernel, for every entry kind of the model format."""

from pathlib import Path

import numpy as np
import pytest

import cmbs
from cmbs.model.natural import _evaluate, layout
from cmbs.model.natural_lanes import LANES, evaluate_lanes

KITCHEN_SINK = Path(__file__).parent / "data" / "kitchen-sink.toml"


@pytest.mark.parametrize("source", [str(KITCHEN_SINK), "four-bar", "human", "passive-manipulator"])
def test_lane_terms_equal_the_one_state_kernel_bit_for_bit(source):
    """Random states around q0 (so that Φ ≠ 0), velocities, inputs and t: rigid, distance,
    angle, parallel and driver rows, constant, point, torque, spring and actuator forces."""
    model = cmbs.load(source)
    equations = model.equations
    n, m = model.n, model.m
    rng = np.random.default_rng(11)
    q = model.q0 + 0.05 * rng.normal(size=(LANES, n))
    qd = rng.normal(size=(LANES, n))
    U = rng.normal(size=(LANES, model.n_u))
    t = 0.37
    size = n + 3 * m + m * n
    terms = np.full((size, LANES), np.nan)
    lanes_buffer = model.new_terms().buffer
    x = np.zeros((layout(equations.ints, n, lanes_buffer.size)[2], LANES))
    evaluate_lanes(q, qd, t, U, equations.ints, equations.reals, lanes_buffer, x, np.zeros_like(x), terms)
    for w in range(LANES):
        buffer = model.new_terms().buffer
        _evaluate(q[w], qd[w], t, U[w], equations.ints, equations.reals, buffer)
        np.testing.assert_array_equal(terms[:, w], buffer[:size])
    assert np.ptp(terms[n:n + m], axis=1).max() > 1e-3        # the lanes' states really differ
