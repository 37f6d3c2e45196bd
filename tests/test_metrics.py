"""Metrics against closed forms."""

import math

import numpy as np
import pytest

from cmbs.errors import CmbsError
from cmbs.metrics import constraint_force_error, nrmse, peak_norm, rms_norm, rmse, settling_time

t = np.linspace(0.0, 2 * math.pi, 20001)


def test_rmse_and_nrmse_of_a_sine_offset():
    reference = np.sin(t)
    assert rmse(t, reference + 0.3, reference) == pytest.approx(0.3, rel=1e-9)
    assert rmse(t, 2 * reference, reference) == pytest.approx(math.sqrt(0.5), rel=1e-6)  # RMS of sin
    assert nrmse(t, reference + 0.3, reference) == pytest.approx(0.15, rel=1e-6)  # range 2


def test_settling_time_of_an_exponential():
    error = np.exp(-t)
    assert settling_time(t, error) == pytest.approx(math.log(100), abs=1e-3)
    assert settling_time(t, np.ones_like(t)) == math.inf


def test_rms_and_peak_norms():
    u = np.column_stack([np.sin(t), np.cos(t)])  # |u| = 1
    assert rms_norm(t, u) == pytest.approx(1.0, rel=1e-9)
    assert peak_norm(3 * u) == pytest.approx(3.0, rel=1e-9)


def test_constraint_force_error_of_a_decaying_loop():
    """λ = λ_d + e^{-t} (1, 1): sqrt(1/T ∫ 2 e^{-2t} dt) = sqrt((1 - e^{-2T}) / T)."""
    lam = np.column_stack([5 + np.exp(-t), -1 + np.exp(-t)])
    expected = math.sqrt((1 - math.exp(-2 * t[-1])) / t[-1])
    assert constraint_force_error(t, lam, [5.0, -1.0]) == pytest.approx(expected, rel=1e-7)


def test_bad_metric_input():
    with pytest.raises(CmbsError, match="strictly increasing"):
        rmse(np.array([0.0, 0.0]), np.zeros(2), np.zeros(2))
    with pytest.raises(CmbsError, match="zero range"):
        nrmse(t, t, np.ones_like(t))
