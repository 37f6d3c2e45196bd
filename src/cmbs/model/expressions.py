"""Restricted parser for time expressions in model files (never ``eval``).

Grammar (``^`` and ``**`` are powers, right-associative; unary minus binds looser than power,
so ``-t^2 = -(t^2)``)::

    expr   := term (('+' | '-') term)*
    term   := unary (('*' | '/') unary)*
    unary  := ('+' | '-') unary | power
    power  := atom (('^' | '**') unary)?
    atom   := NUMBER | 't' | 'pi' | FUNC '(' expr ')' | '(' expr ')'
    FUNC   := sin | cos | tan | exp | sqrt

An expression compiles to a small stack program (opcodes and constants as arrays) that a
compiled kernel evaluates together with its first and second time derivatives by second-order
Taylor (forward-mode) arithmetic: each stack slot holds ``(f, f', f'')``.
"""

from __future__ import annotations

import contextlib
import math
import re
from dataclasses import dataclass
from typing import Iterator

from cmbs.jit import njit
import numpy as np

from cmbs.errors import ExpressionError

OP_CONST, OP_T, OP_ADD, OP_SUB, OP_MUL, OP_DIV, OP_POW, OP_NEG = range(8)
OP_SIN, OP_COS, OP_TAN, OP_EXP, OP_SQRT = range(8, 13)

_FUNCTIONS = {"sin": OP_SIN, "cos": OP_COS, "tan": OP_TAN, "exp": OP_EXP, "sqrt": OP_SQRT}
_BINARY = {"+": OP_ADD, "-": OP_SUB, "*": OP_MUL, "/": OP_DIV, "^": OP_POW, "**": OP_POW}
_TOKEN = re.compile(r"\s*(?:(\d+\.?\d*(?:[eE][+-]?\d+)?|\.\d+(?:[eE][+-]?\d+)?)|([A-Za-z_]\w*)|(\*\*|[-+*/^()]))")


@dataclass(frozen=True)
class Program:
    """A compiled expression: ``ops`` is an (k, 2) int array of (opcode, argument) pairs,
    ``constants`` the numbers referenced by ``OP_CONST``; ``depth`` the stack size needed."""

    text: str
    ops: np.ndarray
    constants: np.ndarray
    depth: int

    def __call__(self, t: float) -> tuple[float, float, float]:
        """Value and first two time derivatives at ``t``."""
        stack = np.empty((max(self.depth, 1), 3))
        out = evaluate_program(self.ops, self.constants, float(t), stack)
        return float(out[0]), float(out[1]), float(out[2])


def _tokenize(text: str) -> list[str]:
    tokens: list[str] = []
    position = 0
    stripped = text.rstrip()
    while position < len(stripped):
        match = _TOKEN.match(stripped, position)
        if match is None or match.end() == position:
            raise ExpressionError(
                f"unexpected character {stripped[position:].lstrip()[:1]!r} at position {position + 1} "
                f"in expression {text!r} (allowed: numbers, t, pi, + - * / ^, parentheses, "
                "sin cos tan exp sqrt)")
        tokens.append(next(group for group in match.groups() if group is not None))
        position = match.end()
    return tokens


#: deepest nesting of brackets, function arguments, signs and exponents in an expression
MAX_NESTING = 100


class _Parser:
    """Recursive descent over the token list, emitting the stack program as it goes."""

    def __init__(self, text: str):
        self.text = text
        self.tokens = _tokenize(text)
        self.position = 0
        self.ops: list[tuple[int, int]] = []
        self.constants: list[float] = []
        self.nesting = 0

    def _fail(self, problem: str) -> ExpressionError:
        shown = self.text if len(self.text) <= 80 else f"{self.text[:60]}...{self.text[-10:]}"
        return ExpressionError(f"{problem} in expression {shown!r}")

    def _peek(self) -> str | None:
        return self.tokens[self.position] if self.position < len(self.tokens) else None

    def _take(self) -> str:
        token = self._peek()
        if token is None:
            raise self._fail("unexpected end")
        self.position += 1
        return token

    def parse(self) -> Program:
        if not self.tokens:
            raise self._fail("empty expression")
        self._expr()
        if self._peek() is not None:
            raise self._fail(f"unexpected {self._peek()!r}")
        ops = np.array(self.ops, dtype=np.int64).reshape(-1, 2)
        return Program(self.text, ops, np.array(self.constants, dtype=float), _stack_depth(ops))

    @contextlib.contextmanager
    def _deeper(self) -> Iterator[None]:
        """One level deeper (brackets, function arguments, signs, exponents): refused beyond
        MAX_NESTING, before Python's own recursion limit is reached."""
        self.nesting += 1
        if self.nesting > MAX_NESTING:
            raise self._fail(f"more than {MAX_NESTING} nested brackets, signs or powers")
        yield
        self.nesting -= 1

    def _expr(self) -> None:
        with self._deeper():
            self._term()
            while self._peek() in ("+", "-"):
                operator = self._take()
                self._term()
                self.ops.append((_BINARY[operator], 0))

    def _term(self) -> None:
        self._unary()
        while self._peek() in ("*", "/"):
            operator = self._take()
            self._unary()
            self.ops.append((_BINARY[operator], 0))

    def _unary(self) -> None:
        if self._peek() in ("+", "-"):
            negate = self._take() == "-"
            with self._deeper():
                self._unary()
            if negate:
                self.ops.append((OP_NEG, 0))
            return
        self._power()

    def _power(self) -> None:
        self._atom()
        if self._peek() in ("^", "**"):
            self._take()
            with self._deeper():
                self._unary()
            self.ops.append((OP_POW, 0))

    def _atom(self) -> None:
        token = self._take()
        if token[0].isdigit() or token[0] == ".":
            self.constants.append(float(token))
            self.ops.append((OP_CONST, len(self.constants) - 1))
        elif token == "t":
            self.ops.append((OP_T, 0))
        elif token == "pi":
            self.constants.append(math.pi)
            self.ops.append((OP_CONST, len(self.constants) - 1))
        elif token in _FUNCTIONS:
            if self._peek() != "(":
                raise self._fail(f"function {token!r} needs parentheses")
            self._take()
            self._expr()
            if self._peek() != ")":
                raise self._fail("missing ')'")
            self._take()
            self.ops.append((_FUNCTIONS[token], 0))
        elif token == "(":
            self._expr()
            if self._peek() != ")":
                raise self._fail("missing ')'")
            self._take()
        elif token[0].isalpha() or token[0] == "_":
            raise self._fail(f"unknown name {token!r} (allowed: t, pi, sin, cos, tan, exp, sqrt)")
        else:
            raise self._fail(f"unexpected {token!r}")


def _stack_depth(ops: np.ndarray) -> int:
    depth = deepest = 0
    for opcode, _ in ops:
        if opcode in (OP_CONST, OP_T):
            depth += 1
        elif opcode in (OP_ADD, OP_SUB, OP_MUL, OP_DIV, OP_POW):
            depth -= 1
        deepest = max(deepest, depth)
    return deepest


def parse_expression(text: str) -> Program:
    """Compile ``text`` (a function of time ``t``) to a :class:`Program`.

    Raises
    ------
    ExpressionError
        With the position and the offending token when ``text`` is not in the grammar.
    """
    if not isinstance(text, str):
        raise ExpressionError(f"expected an expression string, got {text!r}")
    return _Parser(text).parse()


@njit(cache=True, inline="always")
def _taylor_power(a0, a1, a2, b0, b1, b2):
    """(a^b, d/dt, d²/dt²) for Taylor triples a, b; constant exponents avoid log(a)."""
    if b1 == 0.0 and b2 == 0.0:
        p0 = a0 ** b0
        d1 = 0.0
        d2 = 0.0
        if b0 != 0.0 and (a1 != 0.0 or a2 != 0.0):
            dp = b0 * a0 ** (b0 - 1.0)
            d1 = dp * a1
            d2 = dp * a2
            if b0 != 1.0 and a1 != 0.0:
                d2 += b0 * (b0 - 1.0) * a0 ** (b0 - 2.0) * a1 * a1
        return p0, d1, d2
    # a^b = exp(b log a), a > 0
    l0 = np.log(a0)
    l1 = a1 / a0
    l2 = a2 / a0 - l1 * l1
    e0 = b0 * l0
    e1 = b1 * l0 + b0 * l1
    e2 = b2 * l0 + 2.0 * b1 * l1 + b0 * l2
    p0 = np.exp(e0)
    return p0, p0 * e1, p0 * (e2 + e1 * e1)


@njit(cache=True, error_model="numpy")
def evaluate_program(ops, constants, t, stack):
    """Evaluate a stack program at time ``t``: returns the top slot ``(f, f', f'')`` as a tuple.

    IEEE arithmetic (numba's ``error_model="numpy"``, numpy's functions when interpreted): a
    division by zero or a square root of a negative number gives inf or NaN instead of raising in
    the middle of a run; the caller that meets it names the function
    (:meth:`cmbs.model.model.Model.time_function_problem`).

    Each binary/unary rule is the product/chain rule to second order, e.g. for ``c = a·b``:
    ``c' = a'b + ab'``, ``c'' = a''b + 2a'b' + ab''``.
    """
    top = -1
    for k in range(ops.shape[0]):
        opcode = ops[k, 0]
        if opcode == OP_CONST:
            top += 1
            stack[top, 0] = constants[ops[k, 1]]
            stack[top, 1] = 0.0
            stack[top, 2] = 0.0
        elif opcode == OP_T:
            top += 1
            stack[top, 0] = t
            stack[top, 1] = 1.0
            stack[top, 2] = 0.0
        elif opcode <= OP_POW:
            b0, b1, b2 = stack[top, 0], stack[top, 1], stack[top, 2]
            top -= 1
            a0, a1, a2 = stack[top, 0], stack[top, 1], stack[top, 2]
            if opcode == OP_ADD:
                c0, c1, c2 = a0 + b0, a1 + b1, a2 + b2
            elif opcode == OP_SUB:
                c0, c1, c2 = a0 - b0, a1 - b1, a2 - b2
            elif opcode == OP_MUL:
                c0, c1, c2 = a0 * b0, a1 * b0 + a0 * b1, a2 * b0 + 2.0 * a1 * b1 + a0 * b2
            elif opcode == OP_DIV:
                c0 = a0 / b0
                c1 = (a1 - c0 * b1) / b0
                c2 = (a2 - 2.0 * c1 * b1 - c0 * b2) / b0
            else:
                c0, c1, c2 = _taylor_power(a0, a1, a2, b0, b1, b2)
            stack[top, 0], stack[top, 1], stack[top, 2] = c0, c1, c2
        else:
            a0, a1, a2 = stack[top, 0], stack[top, 1], stack[top, 2]
            if opcode == OP_NEG:
                c0, c1, c2 = -a0, -a1, -a2
            elif opcode == OP_SIN:
                s, c = np.sin(a0), np.cos(a0)
                c0, c1, c2 = s, c * a1, c * a2 - s * a1 * a1
            elif opcode == OP_COS:
                s, c = np.sin(a0), np.cos(a0)
                c0, c1, c2 = c, -s * a1, -s * a2 - c * a1 * a1
            elif opcode == OP_TAN:
                tn = np.tan(a0)
                sec2 = 1.0 + tn * tn
                c0, c1, c2 = tn, sec2 * a1, sec2 * a2 + 2.0 * tn * sec2 * a1 * a1
            elif opcode == OP_EXP:
                e = np.exp(a0)
                c0, c1, c2 = e, e * a1, e * (a2 + a1 * a1)
            else:
                r = np.sqrt(a0)
                c0 = r
                c1 = a1 / (2.0 * r)
                c2 = a2 / (2.0 * r) - a1 * a1 / (4.0 * r * r * r)
            stack[top, 0], stack[top, 1], stack[top, 2] = c0, c1, c2
    return stack[0, 0], stack[0, 1], stack[0, 2]
