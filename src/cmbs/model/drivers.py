"""Functions of time for rheonomic drivers and time-varying loads.

Three kinds, each giving the value and its first two derivatives ``(f, f', f'')`` at ``t``:

- :class:`Expression` — a closed form of ``t`` through the restricted parser
  (:mod:`cmbs.model.expressions`); derivatives exact by Taylor arithmetic.
- :class:`Table` — samples ``(t_k, f_k)`` interpolated linearly or by a C² cubic spline
  (scipy ``CubicSpline``, not-a-knot); derivatives of the interpolant.  Outside the sampled
  range the first/last piece is extended (scipy's convention).
- :class:`PythonFunction` — any Python callable; derivatives from user callables or, if not
  given, central differences (step ``h``, error O(h²)).  It is evaluated in Python, outside the
  compiled kernels (slower path).

Models collect their time functions into a :class:`TimeFunctionPack` whose arrays the compiled
kernels read; :func:`evaluate_time_functions` fills an ``(k, 3)`` array of values.
"""

from __future__ import annotations

import abc
import dataclasses
import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

from cmbs.jit import njit
import numpy as np

from cmbs.errors import ModelError
from cmbs.model.limits import MAX_MAGNITUDE, MIN_LENGTH_RATIO
from cmbs.model.packing import int_section, real_section
from cmbs.lazy import on_first_use
from cmbs.model.expressions import Program, evaluate_program, parse_expression

interpolate = on_first_use("scipy.interpolate")

KIND_EXPRESSION, KIND_PIECEWISE, KIND_PYTHON, KIND_UNUSED = 0, 1, 2, 3


class TimeFunction(abc.ABC):
    """Interface: ``f(t) -> (value, first derivative, second derivative)``."""

    @abc.abstractmethod
    def __call__(self, t: float) -> tuple[float, float, float]:
        """Value and first two derivatives at ``t``."""


@dataclass(frozen=True)
class Constant(TimeFunction):
    """A constant value (derivatives zero)."""

    value: float

    def __call__(self, t: float) -> tuple[float, float, float]:
        return float(self.value), 0.0, 0.0

    def program(self) -> Program:
        return parse_expression(repr(float(self.value))) if self.value >= 0 else \
            parse_expression(f"-{-float(self.value)!r}")


def is_constant(function: TimeFunction) -> bool:
    """True for a :class:`Constant`: a driver of it holds its coordinate (Φ_t = 0) and does no work."""
    return isinstance(function, Constant)


@dataclass(frozen=True)
class Expression(TimeFunction):
    """Closed-form expression of ``t``, e.g. ``"pi/4*sin(pi*t - pi/2)"``."""

    text: str
    compiled: Program = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "compiled", parse_expression(self.text))

    def __call__(self, t: float) -> tuple[float, float, float]:
        return self.compiled(t)


@dataclass(frozen=True)
class Table(TimeFunction):
    """Tabulated samples, ``interpolation`` is ``"linear"`` or ``"spline"`` (cubic, C²)."""

    times: np.ndarray
    values: np.ndarray
    interpolation: str = "spline"
    breaks: np.ndarray = field(init=False, repr=False, compare=False)
    coefficients: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        times = np.asarray(self.times, dtype=float).ravel()
        values = np.asarray(self.values, dtype=float).ravel()
        if times.size != values.size:
            raise ModelError(f"table has {times.size} times but {values.size} values")
        if times.size < 2:
            raise ModelError(f"table needs at least 2 samples, got {times.size}")
        if not np.all(np.isfinite(times)) or not np.all(np.isfinite(values)):
            raise ModelError("table contains a non-finite time or value")
        if max(np.abs(times).max(), np.abs(values).max()) > MAX_MAGNITUDE:
            raise ModelError(f"table has a time or value of magnitude above {MAX_MAGNITUDE:g} (out of range)")
        if np.any(np.diff(times) <= 0.0):
            raise ModelError("table times must be strictly increasing")
        closest = MIN_LENGTH_RATIO * max(1.0, np.abs(times).max())     # slopes stay finite (< 1e36)
        if np.diff(times).min() < closest:
            raise ModelError(f"table times must be at least {closest:g} apart ({MIN_LENGTH_RATIO:g} of the largest "
                             f"time, at least 1 s), got two {np.diff(times).min():g} apart")
        if self.interpolation == "linear":
            slopes = np.diff(values) / np.diff(times)
            coefficients = np.zeros((times.size - 1, 4))
            coefficients[:, 2] = slopes
            coefficients[:, 3] = values[:-1]
        elif self.interpolation == "spline":
            if times.size < 4:
                raise ModelError(f"spline interpolation needs at least 4 samples, got {times.size}")
            coefficients = interpolate.CubicSpline(times, values).c.T.copy()
        else:
            raise ModelError(f"interpolation must be 'linear' or 'spline', got {self.interpolation!r}")
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "breaks", times)
        object.__setattr__(self, "coefficients", coefficients)

    def __call__(self, t: float) -> tuple[float, float, float]:
        out = evaluate_piecewise(self.breaks, self.coefficients.ravel(), float(t))
        return float(out[0]), float(out[1]), float(out[2])


@dataclass(frozen=True)
class PythonFunction(TimeFunction):
    """A Python callable ``f(t)`` as a function of time (a driver, a load, a prescribed motion);
    ``first`` and ``second`` derivatives optional.

    Without derivative callables they come from central differences with step ``h``
    (truncation error O(h²), about 1e-8 relative for smooth f and the default h):
    f' ≈ (f(t+h) - f(t-h)) / 2h, f'' ≈ (f(t+h) - 2 f(t) + f(t-h)) / h² (or the central
    difference of ``first`` when only it is given).  It is called from Python, so a run that
    uses one takes the Python loop, not a compiled one (docs/control.md, "Prescribed motions")::

        crank = cmbs.PythonFunction(lambda t: 0.93 + math.sin(t), first=math.cos)
        driven = cmbs.motion.prescribe(cmbs.load("four-bar"), {"alpha": crank})
    """

    function: Callable[[float], float]
    first: Callable[[float], float] | None = None
    second: Callable[[float], float] | None = None
    h: float = 1e-4

    def __call__(self, t: float) -> tuple[float, float, float]:
        f, h = self.function, self.h
        value = float(f(t))
        first = float(self.first(t)) if self.first else (float(f(t + h)) - float(f(t - h))) / (2 * h)
        if self.second:
            second = float(self.second(t))
        elif self.first:
            second = (float(self.first(t + h)) - float(self.first(t - h))) / (2 * h)
        else:
            second = (float(f(t + h)) - 2 * value + float(f(t - h))) / (h * h)
        return value, first, second


def as_time_function(value: object) -> TimeFunction:
    """Accept a number, an expression string, a :class:`TimeFunction` or a callable."""
    if isinstance(value, TimeFunction):
        return value
    if isinstance(value, bool):
        raise ModelError(f"expected a number, expression or function of t, got {value!r}")
    if isinstance(value, (int, float, np.floating, np.integer)):
        return Constant(float(value))
    if isinstance(value, str):
        return Expression(value)
    if callable(value):
        return PythonFunction(value)
    raise ModelError(f"expected a number, expression or function of t, got {value!r}")


@njit(cache=True)
def evaluate_piecewise(breaks, coefficients, t):
    """(f, f', f'') of the piecewise cubic ``f = sum_k c_k (t - t_i)^(3-k)`` (scipy PPoly layout,
    flattened rows), as a tuple: the compiled kernels that call it allocate nothing."""
    pieces = breaks.shape[0] - 1
    i = np.searchsorted(breaks, t, side="right") - 1
    i = min(max(i, 0), pieces - 1)
    s = t - breaks[i]
    c3, c2, c1, c0 = coefficients[4 * i], coefficients[4 * i + 1], coefficients[4 * i + 2], coefficients[4 * i + 3]
    return ((c3 * s + c2) * s + c1) * s + c0, (3.0 * c3 * s + 2.0 * c2) * s + c1, 6.0 * c3 * s + 2.0 * c2


@dataclass(frozen=True)
class TimeFunctionPack:
    """Time functions packed for the compiled kernels.

    ``table`` is (k, 4) ints: kind, start of its ops (expressions) or -1, number of op rows or
    pieces, start of its reals.  ``ops`` stacks every expression's (opcode, arg) rows; ``reals``
    holds expression constants and piecewise breaks+coefficients.  ``python`` lists the
    (index, function) pairs evaluated in Python; ``labels`` names each function for messages
    (e.g. ``"force push (fz)"``).
    """

    table: np.ndarray
    ops: np.ndarray
    reals: np.ndarray
    depth: int
    python: tuple[tuple[int, TimeFunction], ...]
    functions: tuple[TimeFunction, ...]
    labels: tuple[str, ...] = ()

    @property
    def count(self) -> int:
        return len(self.functions)

    def keeping(self, used: set[int]) -> "TimeFunctionPack":
        """The same pack with the functions whose index is not in ``used`` marked unused: the
        kernels skip them (their rows of ``out`` stay as they were) and the Python ones among
        them are no longer called."""
        table = self.table.copy()
        for k in range(table.shape[0]):
            if k not in used:
                table[k, 0] = KIND_UNUSED
        python = tuple((k, function) for k, function in self.python if k in used)
        return dataclasses.replace(self, table=table, python=python)

    def problem(self, times: Sequence[float]) -> str:
        """The first function (by its label) whose value or time derivatives are not finite at one
        of ``times``, as a sentence, else "": why a run met non-finite terms."""
        with np.errstate(all="ignore"):
            for k, function in enumerate(self.functions):
                if self.table[k, 0] == KIND_UNUSED:
                    continue
                for t in times:
                    try:
                        values = function(float(t))
                    except (ArithmeticError, ValueError) as error:
                        values = (str(error),)
                    if not all(isinstance(v, float) and math.isfinite(v) for v in values):
                        label = self.labels[k] if k < len(self.labels) else f"function of time {k}"
                        shown = ", ".join(f"{v:.6g}" if isinstance(v, float) else v for v in values)
                        return f"{label} ({_describe(function)}) is not finite at t = {t:.6g}: {shown}"
        return ""

    @classmethod
    def build(cls, functions: Sequence[TimeFunction], labels: Sequence[str] = ()) -> "TimeFunctionPack":
        table = np.zeros((len(functions), 4), dtype=np.int64)
        ops: list[np.ndarray] = []
        reals: list[float] = []
        python: list[tuple[int, TimeFunction]] = []
        n_ops = 0
        depth = 1
        for k, function in enumerate(functions):
            if isinstance(function, Constant):
                function_program = function.program()
            elif isinstance(function, Expression):
                function_program = function.compiled
            else:
                function_program = None
            if function_program is not None:
                table[k] = (KIND_EXPRESSION, n_ops, function_program.ops.shape[0], len(reals))
                ops.append(function_program.ops)
                n_ops += function_program.ops.shape[0]
                reals.extend(function_program.constants)
                depth = max(depth, function_program.depth)
            elif isinstance(function, Table):
                table[k] = (KIND_PIECEWISE, -1, function.coefficients.shape[0], len(reals))
                reals.extend(function.breaks)
                reals.extend(function.coefficients.ravel())
            else:
                table[k] = (KIND_PYTHON, -1, 0, len(reals))
                python.append((k, function))
        all_ops = np.concatenate(ops) if ops else np.zeros((0, 2), dtype=np.int64)
        return cls(table, np.ascontiguousarray(all_ops, dtype=np.int64), np.array(reals, dtype=float),
                   depth, tuple(python), tuple(functions), tuple(labels))


def _describe(function: TimeFunction) -> str:
    """A short description of a time function for messages: its expression, or its kind."""
    if isinstance(function, Expression):
        return repr(function.text)
    return type(function).__name__.lower()


@njit(cache=True, inline="always")
def packed_time_functions(ints, reals, table_section, ops_section, reals_section, t, buffer, s0, x0):
    """A model kernel's time functions at t (their table, ops and reals the given sections of
    its packed ``ints``, ``reals``: :mod:`cmbs.model.packing`) into ``buffer``: the rows
    (f, f', f'') from ``s0``, then the expression stack up to ``x0``."""
    n_tf = (ints[2 + table_section] - ints[1 + table_section]) // 4
    if n_tf > 0:
        evaluate_time_functions(int_section(ints, table_section).reshape((n_tf, 4)),
                                int_section(ints, ops_section).reshape((-1, 2)),
                                real_section(ints, reals, reals_section), t,
                                buffer[s0 + 3 * n_tf:x0].reshape((-1, 3)), buffer[s0:s0 + 3 * n_tf].reshape((n_tf, 3)))


@njit(cache=True, inline="always")
def driver_rows(ints, section, buffer, n, a0, g0, t0, s0, x0, row):
    """The driver rows Φ = q_c - f(t), Φ_t = -f'(t), γ = f''(t) of the (coordinate, function)
    pairs in int section ``section``, from row ``row`` of a terms buffer (A row-major at ``a0``,
    γ at ``g0``, Φ_t at ``t0``, the functions' rows at ``s0``, x at ``x0``); the next row."""
    i0 = ints[1 + section]
    for k in range((ints[2 + section] - i0) // 2):
        c, f = ints[i0 + 2 * k], ints[i0 + 2 * k + 1]
        buffer[n + row] = buffer[x0 + c] - buffer[s0 + 3 * f]
        buffer[a0 + row * n + c] = 1.0
        buffer[t0 + row] = -buffer[s0 + 3 * f + 1]
        buffer[g0 + row] = buffer[s0 + 3 * f + 2]
        row += 1
    return row


@njit(cache=True)
def evaluate_time_functions(table, ops, reals, t, stack, out):
    """Fill ``out[k] = (f_k, f_k', f_k'')`` for the compiled kinds (Python and unused ones are
    skipped)."""
    for k in range(table.shape[0]):
        kind = table[k, 0]
        if kind == KIND_EXPRESSION:
            start, rows, r0 = table[k, 1], table[k, 2], table[k, 3]
            value = evaluate_program(ops[start:start + rows], reals[r0:], t, stack)
            out[k, 0], out[k, 1], out[k, 2] = value[0], value[1], value[2]
        elif kind == KIND_PIECEWISE:
            pieces, r0 = table[k, 2], table[k, 3]
            breaks = reals[r0:r0 + pieces + 1]
            coefficients = reals[r0 + pieces + 1:r0 + pieces + 1 + 4 * pieces]
            value = evaluate_piecewise(breaks, coefficients, t)
            out[k, 0], out[k, 1], out[k, 2] = value[0], value[1], value[2]


def checked_at_start(function: TimeFunction, label: str) -> TimeFunction:
    """``function`` once its value and time derivatives at t = 0 are known to be finite, so that
    e.g. ``1/t`` or ``sqrt(0-1)`` is reported where it is given, naming ``label`` (a model-file
    entry, a prescribed coordinate), rather than as a division by zero or a NaN deep inside
    assembly; else a :class:`ModelError`."""
    with np.errstate(all="ignore"):
        try:
            values = function(0.0)
        except (ArithmeticError, ValueError) as error:
            raise ModelError(f"cannot be evaluated at t = 0 ({error})", entry=label) from None
    if not np.all(np.isfinite(values)):
        raise ModelError(f"value or time derivatives not finite at t = 0: (f, f', f'') = {tuple(values)}",
                         entry=label)
    return function
