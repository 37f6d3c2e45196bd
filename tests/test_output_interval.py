"""An output interval for fixed-step runs: ``simulate(..., every=k)`` steps by dt, stores only
every k-th instant, and those are the instants of the run that keeps every step, bit for bit,
in each fixed-step loop (compiled RK4, compiled matrix-R RK4, Python RK4, trapezoidal, backward
Euler and generalized-α compiled, trapezoidal and generalized-α on the Python loop)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

import cmbs
from cmbs.cli import main
from cmbs.errors import CmbsError

ARRAYS = ("lam", "constraint_force", "u", "energy", "constraint_error", "velocity_constraint_error")

# (label, model, simulate options, whether the loop is compiled)
LOOPS = [
    ("compiled rk4", "four-bar", dict(integrator="rk4"), True),
    ("compiled matrix-r rk4", "free four-bar", dict(integrator="rk4", formulation="matrix-r"), True),
    ("python rk4", "four-bar", dict(integrator="rk4", compiled=False), False),
    ("compiled trapezoidal", "free four-bar", dict(integrator="trapezoidal"), True),
    ("python trapezoidal", "free four-bar", dict(integrator="trapezoidal", compiled=False), False),
    ("compiled backward-euler", "four-bar", dict(integrator="backward-euler"), True),
    ("compiled generalized-alpha", "four-bar", dict(integrator="generalized-alpha"), True),
    ("python generalized-alpha", "four-bar", dict(integrator="generalized-alpha", compiled=False), False),
]


def _model(name: str) -> cmbs.Model:
    return cmbs.load("four-bar").without_drivers() if name == "free four-bar" else cmbs.load(name)


@pytest.mark.parametrize("label, name, options, compiled", LOOPS, ids=[loop[0] for loop in LOOPS])
def test_kept_instants_are_those_of_the_run_that_keeps_every_step(label, name, options, compiled):
    model = _model(name)
    every_step = cmbs.simulate(model, t_end=0.3, dt=0.005, **options)
    kept = cmbs.simulate(model, t_end=0.3, dt=0.005, every=4, **options)
    assert every_step.info["status"] == kept.info["status"] == "success"
    assert bool(kept.info.get("compiled")) == compiled
    assert kept.t.size == 60 // 4 + 1 and kept.t[-1] == pytest.approx(0.3, abs=1e-15)
    np.testing.assert_array_equal(kept.t, every_step.t[::4])
    for values, reference in ((kept.q, every_step.q), (kept.qd, every_step.qd), (kept.qdd, every_step.qdd)):
        np.testing.assert_array_equal(values, reference[::4])
    for key in ARRAYS:
        np.testing.assert_array_equal(kept[key], every_step[key][::4], err_msg=key)
    assert kept.info["steps"] == every_step.info["steps"] and kept.info["every"] == 4


def test_an_adaptive_run_outputs_every_kth_instant_of_the_dt_grid():
    model = cmbs.load("four-bar")
    run = cmbs.simulate(model, t_end=0.5, dt=0.01, every=5)
    np.testing.assert_allclose(run.t, np.linspace(0.0, 0.5, 11), rtol=0, atol=1e-15)


def test_the_compiled_loop_stores_only_the_kept_steps():
    """200,000 steps of 10 µs with every=2000: the stored records are 101 rows, not 200,001
    (which would take more than 30 MB for the four-bar's q, q̇, q̈, λ and forces)."""
    model = cmbs.load("four-bar")
    cmbs.simulate(model, t_end=0.01, dt=1e-5, integrator="rk4", every=10)     # compile outside the measure
    tracemalloc.start()
    run = cmbs.simulate(model, t_end=2.0, dt=1e-5, integrator="rk4", every=2000)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert run.info["compiled"] and run.info["status"] == "success" and run.info["steps"] == 200_000
    assert run.t.size == 101
    assert peak < 3_000_000, peak


@pytest.mark.parametrize("every, message", [
    (3, "every = 3 does not divide the 100 steps of dt to t_end = 1 s, so t_end would not be kept; choose one that "
        "does (e.g. 2, 4, 5, 10, 20, 25, 50, 100)"),
    (0, "every must be an integer >= 1, got 0"),
    (2.5, "every must be an integer >= 1, got 2.5"),
])
def test_an_every_that_does_not_end_on_t_end_is_refused(every, message):
    with pytest.raises(CmbsError) as caught:
        cmbs.simulate("pendulum", t_end=1.0, dt=0.01, integrator="rk4", every=every)
    assert str(caught.value) == message


def test_cli_every_writes_only_the_kept_rows(tmp_path, capsys):
    out = tmp_path / "run.csv"
    assert main(["simulate", "pendulum", "--t-end", "1", "--dt", "0.001", "--integrator", "rk4", "--every", "50",
                 "--out", str(out)]) == 0
    rows = [line for line in out.read_text().splitlines() if not line.startswith("#")]
    assert len(rows) == 1 + 1000 // 50 + 1            # header, 0, 0.05, ..., 1
    assert rows[-1].startswith("1.0,") or rows[-1].startswith("1,")
    assert main(["simulate", "pendulum", "--t-end", "1", "--dt", "0.001", "--integrator", "rk4", "--every", "3"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "every = 3 does not divide the 1000 steps" in err[0]
