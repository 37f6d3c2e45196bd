"""The restricted expression parser: values against Python's math, derivatives against finite
differences, and every malformed input rejected with a message that names the problem."""

import math

import numpy as np
import pytest

from cmbs.errors import ExpressionError
from cmbs.model.expressions import parse_expression
from helpers import first_derivative_fd, second_derivative_fd

CASES = [
    ("pi/4*sin(2*(pi/2)*t - pi/2)", lambda t: math.pi / 4 * math.sin(math.pi * t - math.pi / 2)),
    ("-t^2", lambda t: -(t**2)),
    ("2^-1 + t**3", lambda t: 0.5 + t**3),
    ("2^3^2", lambda t: 2.0 ** 9),
    ("sqrt(t)*exp(t)/tan(t)", lambda t: math.sqrt(t) * math.exp(t) / math.tan(t)),
    ("cos(t)^2 + sin(t)^2", lambda t: 1.0),
    ("(1 + t)^(t)", lambda t: (1 + t) ** t),
    ("3.5e-1*t - .25 + 1e2", lambda t: 0.35 * t - 0.25 + 100.0),
    ("-(-t)", lambda t: t),
    ("t/(1+t*t)", lambda t: t / (1 + t * t)),
]


@pytest.mark.parametrize("text, reference", CASES)
def test_value_and_derivatives(text, reference):
    program = parse_expression(text)
    for t in (0.3, 0.77, 1.3):
        value, first, second = program(t)
        assert value == pytest.approx(reference(t), rel=1e-13, abs=1e-13)
        assert first == pytest.approx(first_derivative_fd(reference, t), rel=1e-7, abs=1e-7)
        assert second == pytest.approx(second_derivative_fd(reference, t), rel=1e-5, abs=1e-5)


@pytest.mark.parametrize("text, problem", [
    ("", "empty expression"),
    ("t +", "unexpected end"),
    ("foo(t)", "unknown name 'foo'"),
    ("__import__(t)", "unknown name '__import__'"),
    ("__import__('os')", "unexpected character"),
    ("sin t", "needs parentheses"),
    ("2*(t", "missing ')'"),
    ("t ; 3", "unexpected character ';'"),
    ("t t", "unexpected 't'"),
    ("3 +* t", "unexpected '*'"),
    ("x + 1", "unknown name 'x'"),
])
def test_malformed_expressions_are_rejected(text, problem):
    with pytest.raises(ExpressionError, match=problem.replace("(", r"\(").replace(")", r"\)")):
        parse_expression(text)


def test_non_string_is_rejected():
    with pytest.raises(ExpressionError, match="expected an expression string"):
        parse_expression(3.0)


def test_constants_and_time_only():
    assert parse_expression("pi")(5.0) == (math.pi, 0.0, 0.0)
    assert parse_expression("t")(2.5) == (2.5, 1.0, 0.0)
    assert np.isfinite(parse_expression("exp(-t)")(100.0)).all()


@pytest.mark.parametrize("text", ["(" * 200 + "t" + ")" * 200, "-" * 1000 + "t", "t" + "^t" * 300,
                                  "sin(" * 150 + "t" + ")" * 150])
def test_deep_nesting_is_refused_before_the_recursion_limit(text):
    """Brackets, signs, powers and function calls nested more than 100 deep: an ExpressionError
    (it used to be Python's RecursionError, a traceback)."""
    with pytest.raises(ExpressionError, match="more than 100 nested"):
        parse_expression(text)


def test_nesting_up_to_the_limit_parses():
    program = parse_expression("(" * 99 + "t + 1" + ")" * 99)
    assert program(0.5) == pytest.approx((1.5, 1.0, 0.0))


def test_evaluation_follows_ieee_arithmetic_instead_of_raising():
    """A run that reaches a pole or a negative square root meets inf/NaN, which it reports with the
    function's name, rather than an exception from inside a compiled loop."""
    value, first, second = parse_expression("1/(t-0.5)")(0.5)
    assert value == math.inf and first == -math.inf and math.isnan(second)
    assert all(math.isnan(v) for v in parse_expression("sqrt(t - 2)")(1.0))
    assert parse_expression("exp(t)")(1000.0)[0] == math.inf
