"""cmbs.integrate.compiled_lanes: blocks of variants in lanes give, bit for bit, the one-variant
compiled loop's numbers (cmbs.integrate.variants.rk4_variants: its rk4 per variant),
including variants that leave their lanes at a singular position or when the motion diverges."""

import functools
from pathlib import Path

import numpy as np
import pytest

import cmbs
from cmbs.dynamics.base import NON_FINITE, OK, SINGULAR
from cmbs.integrate import compiled_lanes
from cmbs.integrate.compiled_plan import compiled_run
from cmbs.integrate.continuity import LEFT_BRANCH
from cmbs.integrate.variants import rk4_variants
from cmbs.dynamics import Baumgarte, formulation as make_formulation
from cmbs.simulate import simulate
from cmbs.sweep import Variant, sweep

KITCHEN_SINK = str(Path(__file__).parent / "data" / "kitchen-sink.toml")


def _initial_velocities(model, speeds, coordinate):
    column = model.coordinate_names.index(coordinate)
    return np.array([cmbs.velocities(model, model.q0, qd=np.eye(model.n)[column] * speed, fixed=[coordinate])
                     for speed in speeds])


def _both(model, QD0, chosen, steps, every, h=1e-3, U0=None):
    """(lanes, one variant at a time): each (q, q̇, |Φ|max records, statuses, records reached)."""
    count = QD0.shape[0]
    model_part, formulation, inputs = compiled_run(model, chosen, chosen.bind(model), "rk4", None, False, steps * h, h)
    setup = compiled_lanes.lane_setup(model_part, formulation, model.m, model.n)
    assert setup is not None
    Q0 = np.tile(model.q0, (count, 1))
    U0 = np.zeros((count, model.n_u)) if U0 is None else U0
    buffer_size = model.new_terms().buffer.size
    results = []
    for lanes in (True, False):
        records = steps // every + 1
        out = (np.full((count, records, model.n), np.nan), np.full((count, records, model.n), np.nan),
               np.full((count, records), np.nan), np.full(count, -9, dtype=np.int64), np.zeros(count, dtype=np.int64))
        run = functools.partial(compiled_lanes.rk4_lanes, lanes=setup) if lanes else rk4_variants
        run(model_part, formulation, inputs, Q0, QD0, U0, h, steps, every, buffer_size, model.m, *out)
        results.append(out)
    return results


def _assert_identical(lanes, single):
    for a, b in zip(lanes, single):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("formulation, options", [("lagrange", {}), ("baumgarte", {}), ("projection", {}),
                                                  ("projection", {"inertia": "symmetric"}),
                                                  ("projection", {"inertia": "parameterised"})])
def test_four_bar_lanes_equal_the_one_variant_loop_bit_for_bit(formulation, options):
    """11 variants: a full block of 8 and a last block of 3 (its other lanes are padding)."""
    model = cmbs.load("four-bar").without_drivers()
    QD0 = _initial_velocities(model, np.linspace(-2.0, 2.0, 11), "alpha")
    lanes, single = _both(model, QD0, make_formulation(formulation, **options), steps=300, every=7)
    assert set(lanes[3]) == {OK} and set(lanes[4]) == {300 // 7 + 1}
    assert np.ptp(lanes[0][:, -1, -1]) > 0.5          # the variants really differ
    _assert_identical(lanes, single)


def test_driven_four_bar_with_inputs_in_lanes():
    """The crank driver (a time function evaluated once per stage for all lanes), the input u of
    each variant (a torque on the crank) and m = n."""
    model = cmbs.load("four-bar")
    QD0 = np.tile(model.qd0, (5, 1))
    U0 = np.linspace(-3.0, 3.0, 5).reshape(5, model.n_u)
    lanes, single = _both(model, QD0, make_formulation("lagrange"), steps=200, every=10, U0=U0)
    assert set(lanes[3]) == {OK}
    _assert_identical(lanes, single)


@pytest.mark.parametrize("name, options", [("chain", {"links": 3, "closed": True}), ("double-pendulum", {}),
                                           ("passive-manipulator", {}), (KITCHEN_SINK, {})])
def test_other_natural_models_in_lanes(name, options):
    """Without massless coordinates (the reduced system by Cholesky: the closed chain), with
    several (the double pendulum's and the manipulator's angle coordinates), and with every
    entry kind of the model format (tests/data/kitchen-sink.toml: drivers, springs, sliders,
    distances, point forces, torques)."""
    model = cmbs.load(name, **options)
    rng = np.random.default_rng(3)
    QD0 = np.array([cmbs.velocities(model, model.q0, qd=rng.normal(size=model.n)) for _ in range(9)])
    lanes, single = _both(model, QD0, make_formulation("baumgarte"), steps=250, every=25)
    assert set(lanes[3]) == {OK}
    _assert_identical(lanes, single)


def test_variants_reaching_the_singular_position_leave_their_lanes():
    """Aghili's slider-crank with equal crank and rod, released at crank speeds of 1-3 rad/s from
    45°: some variants reach the singular position (crank at 90°) within the run and stop there
    as the one-variant loop stops them; the others run to the end in the same blocks."""
    model = cmbs.load("slider-crank").without_drivers()
    QD0 = _initial_velocities(model, np.linspace(1.0, 3.0, 9), "theta1")
    lanes, single = _both(model, QD0, make_formulation("lagrange"), steps=600, every=5)
    statuses = lanes[3]
    assert SINGULAR in statuses and OK in statuses
    assert np.all(lanes[4][statuses == SINGULAR] < 600 // 5 + 1)
    _assert_identical(lanes, single)


@pytest.mark.parametrize("inertia", ["standard", "symmetric", "parameterised"])
def test_projection_variants_leave_their_lanes_for_the_svd_through_the_singular_position(inertia):
    """The same slider-crank under the projection: the variants near the singular position leave
    their lanes for the one-variant loop's SVD there (with their inertia) and run to the end
    through it; the lanes serve every inertia (each has the Lagrange solution where they run)."""
    model = cmbs.load("slider-crank").without_drivers()
    QD0 = _initial_velocities(model, np.linspace(1.0, 3.0, 9), "theta1")
    lanes, single = _both(model, QD0, make_formulation("projection", inertia=inertia), steps=600, every=5)
    assert set(lanes[3]) == {OK} and set(lanes[4]) == {600 // 5 + 1}
    assert np.sum(lanes[0][:, -1, 4] > np.pi / 2) >= 5      # from 45° through 90°
    _assert_identical(lanes, single)


def test_a_diverging_run_leaves_its_lanes_as_the_one_variant_loop_ends_it():
    """Baumgarte with h·ω = 5, outside RK4's stability interval: every variant blows up, ending
    non-finite or, where the branch watch sees |q̇| grow tenfold in a step first, as a divergence
    (which of the two comes first depends on the machine's rounding; the lanes keep the watch
    too, so they end each variant as the one-variant loop does)."""
    model = cmbs.load("four-bar").without_drivers()
    QD0 = _initial_velocities(model, np.linspace(-1.0, 1.0, 3), "alpha")
    lanes, single = _both(model, QD0, Baumgarte(xi=1.0, omega=5000.0), steps=400, every=1)
    assert set(lanes[3]) <= {NON_FINITE, LEFT_BRANCH}
    _assert_identical(lanes, single)


def test_a_run_the_branch_watch_ends_leaves_its_lanes_where_the_watch_ends_it():
    """Baumgarte with h·ω = 20: |q̇| grows more than tenfold in the first steps, which the branch
    watch (cmbs.integrate.continuity) ends as a divergence before the state overflows.  The lanes
    keep the watch per variant, so each variant ends there, with the records up to the jump's
    start, as in the one-variant loop; none runs on to a non-finite state or says success."""
    model = cmbs.load("four-bar").without_drivers()
    QD0 = _initial_velocities(model, np.linspace(-1.0, 1.0, 8), "alpha")
    lanes, single = _both(model, QD0, Baumgarte(xi=1.0, omega=20000.0), steps=400, every=1)
    assert set(single[3]) == {LEFT_BRANCH}
    _assert_identical(lanes, single)


def test_lanes_take_small_natural_models_only():
    def setup(model, name="lagrange"):
        chosen = make_formulation(name)
        model_part, formulation, _ = compiled_run(model, chosen, chosen.bind(model), "rk4", None, False, 1.0, 1e-3)
        return compiled_lanes.lane_setup(model_part, formulation, model.m, model.n)

    four_bar = cmbs.load("four-bar")
    assert setup(four_bar) is not None and setup(four_bar, "projection") is not None
    assert setup(cmbs.load("slider-crank-joint")) is None
    assert setup(cmbs.load("chain", links=14, closed=True)) is None     # solved by band LU


def test_sweep_in_lanes_equals_single_simulations_exactly():
    """Through cmbs.sweep: each variant's records are those of its own cmbs.simulate run (the
    compiled RK4 loop), to the last bit."""
    model = cmbs.load("four-bar").without_drivers()
    QD0 = _initial_velocities(model, np.linspace(-2.0, 2.0, 10), "alpha")
    result = sweep(model, [Variant(qd0=qd) for qd in QD0], t_end=0.2, dt=1e-3, every=20)
    assert result.info["mode"] == "batched"
    for v, qd0 in enumerate(QD0):
        run = simulate(model, t_end=0.2, dt=1e-3, integrator="rk4", formulation="lagrange", qd0=qd0)
        np.testing.assert_array_equal(result.q[v], run.q[::20])
        np.testing.assert_array_equal(result.qd[v], run.qd[::20])
