"""Robots from URDF (spatial joint-coordinate trees) under the project's formulations, integrators
and sweeps: the same motion from every formulation, the implicit integrators' orders, and a
batched sweep equal to its single runs."""

from __future__ import annotations


import numpy as np
import pytest

import cmbs
from helpers import example_robots
from cmbs.sweep import Variant, sweep


@pytest.fixture(scope="module")
def ur5():
    robots = example_robots()
    if robots is None:
        pytest.skip("example-robot-data is not installed (the [test] extra)")
    return cmbs.load(str(robots / "ur_description/urdf/ur5_robot.urdf"))


START_SPEEDS = np.array([0.8, -0.5, 1.2, 0.3, -0.9, 1.5])


@pytest.mark.parametrize("formulation", ["baumgarte", "penalty", "projection", "udwadia-kalaba", "matrix-r"])
def test_every_formulation_gives_the_tree_s_motion(ur5, formulation):
    """Without constraints every formulation solves M q̈ = Q: the same 1 s swing as Lagrange, to
    the integrator's tolerance (DOP853 at rtol 1e-10).  The Python loop, which calls the same
    compiled solves, spares the test suite a compiled loop per formulation for this model kind."""
    settings = dict(t_end=1.0, dt=0.05, integrator="dop853", rtol=1e-10, atol=1e-12, qd0=START_SPEEDS,
                    compiled=False)
    reference = cmbs.simulate(ur5, formulation="lagrange", **settings)
    run = cmbs.simulate(ur5, formulation=formulation, **settings)
    assert run.info["status"] == "success"
    np.testing.assert_allclose(run.q, reference.q, rtol=0, atol=1e-8)


@pytest.mark.parametrize("integrator, order", [("trapezoidal", 2), ("generalized-alpha", 2), ("backward-euler", 1)])
def test_the_implicit_integrators_converge_at_their_order_on_a_robot(ur5, integrator, order):
    """Halving h divides the error at t = 0.4 s (against DOP853 at rtol 1e-12) by about 2^order
    (the Python loops, as above)."""
    exact = cmbs.simulate(ur5, t_end=0.4, dt=0.4, integrator="dop853", rtol=1e-12, atol=1e-14, qd0=START_SPEEDS,
                          compiled=False)
    errors = []
    for h in (4e-3, 2e-3):
        run = cmbs.simulate(ur5, t_end=0.4, dt=h, integrator=integrator, qd0=START_SPEEDS, compiled=False)
        errors.append(np.abs(run.q[-1] - exact.q[-1]).max())
    ratio = errors[0] / errors[1]
    assert 2 ** order * 0.7 < ratio < 2 ** order * 1.4, errors


def test_a_batched_sweep_of_a_robot_equals_its_single_simulations(ur5):
    """A state-only sweep runs batched (compiled, in parallel); each variant's records are its own
    cmbs.simulate run's (RK4), to the last bit."""
    rng = np.random.default_rng(0)
    variants = [Variant(qd0=rng.normal(size=ur5.n)) for _ in range(10)]
    result = sweep(ur5, variants, t_end=0.5, dt=1e-3, every=50)
    assert result.info["mode"] == "batched"
    for v in (0, 9):
        run = cmbs.simulate(ur5, t_end=0.5, dt=1e-3, integrator="rk4", qd0=variants[v].qd0)
        np.testing.assert_array_equal(result.q[v], run.q[::50])
