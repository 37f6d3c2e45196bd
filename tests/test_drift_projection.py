"""Drift projection (project=True) in the compiled loops (cmbs.dynamics.drift.DriftProjection):
the same steps, counters and outputs as the Python loop, which projects with
cmbs.simulate.project_state after each step and, for an adaptive run, at each output."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import cmbs
from cmbs.cli import main
from cmbs.simulate import project_state, simulate

CASES = [(name, formulation, integrator) for integrator in ("rk4", "rk45")
         for name, formulation in (("four-bar", "projection"), ("four-bar", "lagrange"),
                                   ("slider-crank-joint", "lagrange"))]
CASES += [("four-bar", "lagrange", "rk23"), ("four-bar", "lagrange", "dop853")]


def _model(name: str) -> cmbs.Model:
    return cmbs.load(name).without_drivers() if name == "four-bar" else cmbs.load(name)


@pytest.mark.parametrize("name, formulation, integrator", CASES)
def test_compiled_projection_takes_the_python_loops_steps(name, formulation, integrator):
    """The four-bar (natural coordinates) and the slider-crank (joint coordinates), two closed
    chains, up to 0.4 s (the slider-crank's singular position is at 0.46 s)."""
    model = _model(name)
    options = dict(t_end=0.4, integrator=integrator, dt=1e-3 if integrator == "rk4" else 0.01, rtol=1e-8,
                   atol=1e-8, formulation=formulation, project=True, projection_tolerance=1e-11)
    fast, python = simulate(model, **options), simulate(model, compiled=False, **options)
    assert fast.info["compiled"] and "compiled" not in python.info
    assert fast.info["status"] == python.info["status"] == "success"
    assert fast.info["steps"] == python.info["steps"]
    if integrator != "rk4":           # the Python RK4 loop counts rejections (0) and the last record's evaluation
        assert (fast.info["rejected"], fast.info["evaluations"]) == (python.info["rejected"],
                                                                     python.info["evaluations"])
    np.testing.assert_allclose(fast.t, python.t, rtol=0, atol=1e-15)
    np.testing.assert_allclose(fast.q, python.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.qd, python.qd, rtol=0, atol=1e-11)
    np.testing.assert_allclose(fast.qdd, python.qdd, rtol=0, atol=1e-9 * max(1.0, np.abs(python.qdd).max()))
    np.testing.assert_allclose(fast["lam"], python["lam"], rtol=0, atol=1e-9 * max(1.0, np.abs(python["lam"]).max()))


@pytest.mark.parametrize("integrator", ["rk4", "rk45"])
def test_compiled_projection_keeps_every_output_on_the_constraints(integrator):
    """Every recorded state after the start (rk4: the projected steps; rk45: the projected
    interpolants) meets |Φ| below the tolerance and A q̇ + Φ_t to rounding, where the
    unprojected run drifts above it."""
    model = cmbs.load("four-bar").without_drivers()
    options = dict(t_end=2.0, integrator=integrator, dt=1e-2, rtol=1e-6, atol=1e-9, formulation="lagrange")
    free = simulate(model, compiled=True, **options)
    projected = simulate(model, compiled=True, project=True, projection_tolerance=1e-12, **options)
    assert projected.info["compiled"] and projected.info["status"] == "success"
    assert free["constraint_error"].max() > 1e-9                  # the drift the projection removes
    # after the start (as assembled, to 1e-11: RK4 projects after each step only)
    assert projected["constraint_error"][1:].max() < 1e-12
    assert projected["velocity_constraint_error"][1:].max() < 1e-12


def test_readme_first_command_runs_compiled(tmp_path):
    """The README's first command: an undriven four-bar, projection formulation, rk45, --project."""
    out = tmp_path / "four-bar.npz"
    assert main(["simulate", "four-bar", "--undriven", "--t-end", "10", "--formulation", "projection", "--rtol",
                 "1e-9", "--project", "--out", os.fspath(out)]) == 0
    with np.load(out, allow_pickle=False) as saved:
        info = json.loads(str(saved["info"]))
        assert info["compiled"] is True and info["project"] is True and info["status"] == "success"
        assert saved["constraint_error"].max() < 1e-10


def test_project_state_is_the_minimum_norm_projection():
    """cmbs.simulate.project_state against the same projection written with numpy's
    pseudo-inverse (Aghili 2005, eq. 45-47): Newton steps q ← q - A⁺Φ to |Φ| < 1e-13, then
    q̇ ← (I - A⁺A) q̇ - A⁺Φ_t; the four-bar moved off its constraints by 1e-3."""
    model = cmbs.load("four-bar").without_drivers()
    q = model.q0 + 1e-3 * np.sin(np.arange(1.0, model.n + 1.0))
    qd = np.cos(np.arange(1.0, model.n + 1.0))
    expected = q.copy()
    for _ in range(10):
        terms = model.evaluate(expected, np.zeros(model.n), 0.0)
        if np.abs(terms.phi).max() < 1e-13:
            break
        expected -= np.linalg.pinv(terms.A) @ terms.phi
    terms = model.evaluate(expected, np.zeros(model.n), 0.0)
    pinv = np.linalg.pinv(terms.A)
    expected_qd = (np.eye(model.n) - pinv @ terms.A) @ qd - pinv @ terms.phi_t
    projected, projected_qd = project_state(model, q, qd, 0.0, tolerance=1e-13)
    np.testing.assert_allclose(projected, expected, rtol=0, atol=1e-13)
    np.testing.assert_allclose(projected_qd, expected_qd, rtol=0, atol=1e-12)
    assert np.abs(model.evaluate(projected, projected_qd, 0.0).phi).max() < 1e-13
