"""Time functions: tables (linear, spline), callables and the packed compiled evaluation."""

import math

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from cmbs.errors import ModelError
from cmbs.model.drivers import (Constant, Expression, PythonFunction, Table, TimeFunctionPack, as_time_function,
                                evaluate_time_functions)


def test_linear_table_interpolates_and_differentiates():
    table = Table([0.0, 1.0, 3.0], [0.0, 2.0, 1.0], "linear")
    assert table(0.5) == pytest.approx((1.0, 2.0, 0.0))
    assert table(2.0) == pytest.approx((1.5, -0.5, 0.0))


def test_spline_table_matches_scipy_spline_derivatives():
    times = np.linspace(0.0, 2.0, 21)
    values = np.sin(3 * times)
    reference = CubicSpline(times, values)
    table = Table(times, values, "spline")
    for t in (0.05, 0.731, 1.999):
        expected = (float(reference(t)), float(reference(t, 1)), float(reference(t, 2)))
        assert table(t) == pytest.approx(expected, rel=1e-12, abs=1e-12)


def test_spline_of_smooth_data_approximates_the_function():
    times = np.linspace(0.0, 2.0, 201)
    table = Table(times, np.sin(times), "spline")
    value, first, second = table(1.234)
    assert value == pytest.approx(math.sin(1.234), abs=1e-9)
    assert first == pytest.approx(math.cos(1.234), abs=1e-6)
    assert second == pytest.approx(-math.sin(1.234), abs=1e-3)


@pytest.mark.parametrize("times, values, interpolation, problem", [
    ([0, 1], [1], "linear", "2 times but 1 values"),
    ([0], [1], "linear", "at least 2 samples"),
    ([0, 1, 1, 2], [0, 1, 2, 3], "linear", "strictly increasing"),
    ([0, 1, 2], [0, 1, 2], "spline", "at least 4 samples"),
    ([0, 1, 2], [0, 1, 2], "cubic", "'linear' or 'spline'"),
    ([0, 1, 2], [0, float("nan"), 2], "linear", "non-finite"),
])
def test_bad_tables(times, values, interpolation, problem):
    with pytest.raises(ModelError, match=problem):
        Table(times, values, interpolation)


def test_python_function_with_and_without_derivatives():
    exact = PythonFunction(math.sin, math.cos, lambda t: -math.sin(t))
    assert exact(0.4) == (math.sin(0.4), math.cos(0.4), -math.sin(0.4))
    approx = PythonFunction(math.sin)
    value, first, second = approx(0.4)
    assert first == pytest.approx(math.cos(0.4), abs=1e-8)
    assert second == pytest.approx(-math.sin(0.4), abs=1e-6)


def test_as_time_function_kinds():
    assert isinstance(as_time_function(2), Constant)
    assert isinstance(as_time_function("t"), Expression)
    assert isinstance(as_time_function(math.cos), PythonFunction)
    with pytest.raises(ModelError):
        as_time_function(True)
    with pytest.raises(ModelError):
        as_time_function([1, 2])


def test_packed_evaluation_equals_each_function():
    functions = [Expression("sin(t)*t"), Table(np.linspace(0, 1, 11), np.linspace(0, 1, 11) ** 2, "spline"),
                 Constant(-2.5), Table([0, 1, 2], [0, 1, 0], "linear"), Expression("exp(t)")]
    pack = TimeFunctionPack.build(functions)
    out = np.zeros((len(functions), 3))
    evaluate_time_functions(pack.table, pack.ops, pack.reals, 0.55, np.empty((pack.depth, 3)), out)
    for row, function in zip(out, functions):
        np.testing.assert_allclose(row, function(0.55), rtol=1e-14, atol=1e-14)
