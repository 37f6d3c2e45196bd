"""DOP853 (Dormand & Prince's 8th-order pair): its order on a closed-form solution, its
continuous extension (end conditions and 8th-order local error), its tolerance-proportional
error against the closed form and against scipy's DOP853, and through cmbs.simulate."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import cmbs
from cmbs.integrate.explicit import _dense, _step, dense_coefficients, integrate
from cmbs.integrate.tableaus import dop853, tableau


def oscillator(t: float, y: np.ndarray) -> np.ndarray:
    """y = (cos t, -sin t, e^{t/2}): a harmonic oscillator and an exponential."""
    return np.array([y[1], -y[0], 0.5 * y[2]])


def exact(t: float) -> np.ndarray:
    return np.array([math.cos(t), -math.sin(t), math.exp(0.5 * t)])


def test_tableau_is_consistent():
    method = dop853()
    assert tableau("dop853") is method
    np.testing.assert_allclose(method.a.sum(axis=1), method.c, atol=1e-14)        # row sums are the nodes
    assert method.b.sum() == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_allclose(method.a[-1], method.b, atol=0)                     # FSAL: the last stage is f(t+h, y_new)
    assert method.dense.a.shape == (3, 16) and method.dense.d.shape == (4, 16)


def test_fixed_step_converges_at_eighth_order():
    errors = [np.abs(integrate(oscillator, exact(0.0), np.array([0.0, 4.0]), tableau=dop853(), step=h).y[-1]
                     - exact(4.0)).max() for h in (0.4, 0.2)]
    assert math.log2(errors[0] / errors[1]) == pytest.approx(8.0, abs=0.4)


def step_extension(h: float, x: float) -> tuple[np.ndarray, np.ndarray, dict]:
    """One DOP853 step of size h from t = 0.3 and its continuous extension at t + x h."""
    method, t = dop853(), 0.3
    y = exact(t)
    stages = np.zeros((method.c.size, 3))
    y_new = _step(oscillator, method, t, y, h, oscillator(t, y), stages)
    f_new = oscillator(t + h, y_new)
    F = dense_coefficients(oscillator, method, t, y, h, y_new, f_new, stages)
    values, slopes = _dense(F, t, y, h, np.array([t + x * h]))
    return values[0], slopes[0], {"y": y, "y_new": y_new, "k1": stages[0], "f_new": f_new, "t": t}


def test_continuous_extension_meets_the_step_and_has_eighth_order_local_error():
    for x, end in ((0.0, "y"), (1.0, "y_new")):
        value, slope, step = step_extension(0.3, x)
        np.testing.assert_allclose(value, step[end], rtol=0, atol=1e-15)
        np.testing.assert_allclose(slope, step["k1" if x == 0.0 else "f_new"], rtol=0, atol=1e-14)
    errors = []
    for h in (0.8, 0.4):
        value, slope, step = step_extension(h, 0.37)
        errors.append(np.abs(value - exact(step["t"] + 0.37 * h)).max())
    assert math.log2(errors[0] / errors[1]) == pytest.approx(8.0, abs=0.6)


@pytest.mark.parametrize("tolerance", [1e-6, 1e-9, 1e-12])
def test_adaptive_error_follows_the_tolerance_like_scipys_dop853(tolerance):
    """Outputs between the steps (the continuous extension) are within 20 tolerances of the closed
    form, as scipy's DOP853 is at the same tolerance, with a like number of evaluations."""
    times = np.linspace(0.0, 6.0, 61)
    ours = integrate(oscillator, exact(0.0), times, tableau=dop853(), rtol=tolerance, atol=tolerance)
    theirs = solve_ivp(oscillator, (0.0, 6.0), exact(0.0), method="DOP853", rtol=tolerance, atol=tolerance,
                       t_eval=times)
    truth = np.array([exact(t) for t in times])
    ours_error = np.abs(ours.y - truth).max() / np.abs(truth).max()
    theirs_error = np.abs(theirs.y.T - truth).max() / np.abs(truth).max()
    assert ours.status == "success" and ours_error < 20 * tolerance
    assert ours_error < 10 * theirs_error + tolerance
    assert 0.5 < ours.counters["evaluations"] / theirs.nfev < 2.0


def test_simulate_with_dop853_conserves_energy_to_the_tolerance():
    model = cmbs.load("double-pendulum")
    drifts = []
    for tolerance in (1e-7, 1e-10):
        energy = cmbs.simulate(model, t_end=3.0, integrator="dop853", rtol=tolerance, atol=tolerance * 1e-2)["energy"]
        drifts.append(np.abs(energy - energy[0]).max() / abs(energy[0]))
        assert drifts[-1] < 100 * tolerance
    assert drifts[0] > 100 * drifts[1]
