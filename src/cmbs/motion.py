"""Prescribed motions: coordinates given as functions of time, from expressions or from files.

A prescribed motion replaces a model's own drivers by driver rows on chosen coordinates c,

    Φ_c = q_c - f_c(t),   A_c = e_cᵀ,   γ_c = f_c''(t),   Φ_t,c = -f_c'(t)      (thesis eq. 3.6)

so that the same mechanism can be driven by any recorded or designed motion (``cmbs inverse
MODEL --motion ...``, ``cmbs track MODEL --reference ...``).  Sources of f_c:

- expressions ``"alpha = pi/4*sin(pi*t - pi/2); beta = 0.1*t"`` parsed by the restricted
  expression parser (never evaluated as Python);
- a cmbs result file (``.npz`` or ``.csv`` written by ``save``): its coordinate columns;
- a plain ``.csv`` table: a header ``t,<name>,...`` then one row per sample (``#`` comments
  allowed); samples are interpolated by a C² cubic spline (or linearly).
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from cmbs.errors import CmbsError, ExpressionError, did_you_mean
from cmbs.inverse.ida import driven_columns
from cmbs.model.drivers import Expression, Table, TimeFunction, checked_at_start
from cmbs.model.model import Model, Terms, WrappedEquations
from cmbs.trajectory import Trajectory


class _PrescribedEquations(WrappedEquations):
    """The equations of an undriven model followed by one driver row per prescribed coordinate."""

    def __init__(self, inner, columns: np.ndarray, functions: Sequence[TimeFunction]):
        self.inner = inner
        self.columns = columns
        self.functions = tuple(functions)
        self.inner_terms = inner.new_terms()
        self.n = self.inner_terms.Q.size
        self.m_inner = self.inner_terms.phi.size
        # row k of these equations is row row_origin[k] of ``inner`` (-1: a prescribed row)
        self.row_origin = np.concatenate([np.arange(self.m_inner), np.full(columns.size, -1)])

    def new_terms(self) -> Terms:
        constant = self.inner_terms.M if not self.inner_terms.M.flags.writeable else None
        return Terms(self.n, self.m_inner + self.columns.size, constant_mass=constant)

    def evaluate(self, q: np.ndarray, qd: np.ndarray, t: float, u: np.ndarray, terms: Terms) -> None:
        inner = self.inner_terms
        self.inner.evaluate(q, qd, t, u, inner)
        rows = slice(0, self.m_inner)
        terms.Q[:] = inner.Q
        if terms.M is not inner.M:
            terms.M[:] = inner.M
        terms.phi[rows], terms.A[rows], terms.gamma[rows], terms.phi_t[rows] = \
            inner.phi, inner.A, inner.gamma, inner.phi_t
        for k, (column, function) in enumerate(zip(self.columns, self.functions), start=self.m_inner):
            value, first, second = function(t)
            terms.A[k] = 0.0
            terms.A[k, column] = 1.0
            terms.phi[k] = q[column] - value
            terms.gamma[k] = second
            terms.phi_t[k] = -first



def prescribe(model: Model, functions: Mapping[str, TimeFunction]) -> Model:
    """``model`` with its drivers replaced by ``q_c = f_c(t)`` for every coordinate c in
    ``functions``.

    The new q0 is reached from the model's own assembled q0 by moving the prescribed coordinates
    continuously to f_c(0) (:func:`cmbs.kinematics.follow_branch` on the undriven mechanism), so
    it lies on the model's assembly branch: the same elbow up or down, never a point half a turn
    from its angle."""
    from cmbs.kinematics import assemble, follow_branch, velocities

    if not functions:
        raise CmbsError("a prescribed motion needs at least one coordinate")
    free = model.without_drivers()
    unknown = [name for name in functions if name not in model.coordinate_names]
    if unknown:
        raise CmbsError(f"model {model.name!r} has no coordinate(s) {', '.join(unknown)}"
                        f"{did_you_mean(unknown, model.coordinate_names)}; coordinates: "
                        f"{', '.join(model.coordinate_names)}")
    names = list(functions)
    columns = model.coordinate_indices(names)
    equations = _PrescribedEquations(free.equations, columns, [functions[name] for name in names])
    prescribed = free.replace(
        name=model.name, equations=equations,
        constraint_names=free.constraint_names + tuple(f"motion {name}" for name in names),
        drivers=np.concatenate([free.drivers, np.ones(len(names), dtype=bool)]),
        nonholonomic=np.concatenate([free.nonholonomic, np.zeros(len(names), dtype=bool)]))
    start = np.array([checked_at_start(functions[name], f"motion of {name}")(0.0) for name in names])
    q0 = follow_branch(free, assemble(free, model.q0, 0.0), 0.0, 0.0, fixed=names, fixed_to=start[:, 0])
    qd0 = model.qd0.copy()
    qd0[columns] = start[:, 1]
    q0 = assemble(prescribed, q0, 0.0, fixed=names)
    return prescribed.replace(q0=q0, qd0=velocities(prescribed, q0, 0.0, qd=qd0, fixed=names))


def read_motion(source: str, model: Model, *, coordinates: Sequence[str] | None = None,
                interpolation: str = "spline") -> dict[str, TimeFunction]:
    """Functions of time for some of ``model``'s coordinates from ``source``: a file path
    (``.npz``/``.csv``) or expressions ``name = expr; ...`` (see the module docstring).

    From a file, ``coordinates`` chooses the columns; by default the model's driven coordinates
    when the file has them all, else every column named after a model coordinate.
    """
    text = source.strip()
    if text.lower().endswith((".npz", ".csv")):
        return _motion_from_file(Path(text), model, coordinates, interpolation)
    return _motion_from_expressions(text, model, coordinates)


def _motion_from_expressions(text: str, model: Model, coordinates: Sequence[str] | None) -> dict[str, TimeFunction]:
    functions: dict[str, TimeFunction] = {}
    for item in (part.strip() for part in text.split(";")):
        if not item:
            continue
        name, equals, expression = item.partition("=")
        name = name.strip()
        if not equals or not name or not expression.strip():
            raise CmbsError(f"motion {item!r}: expected NAME = EXPRESSION (several separated by ';'), "
                            "or a .npz/.csv file")
        if name not in model.coordinate_names:
            raise CmbsError(f"motion {item!r}: model {model.name!r} has no coordinate {name!r}"
                            f"{did_you_mean(name, model.coordinate_names)}; "
                            f"coordinates: {', '.join(model.coordinate_names)}")
        if name in functions:
            raise CmbsError(f"motion: coordinate {name!r} is given twice")
        try:
            functions[name] = Expression(expression.strip())
        except ExpressionError as error:
            raise CmbsError(f"motion {item!r}: {error}") from None
    if not functions:
        raise CmbsError("motion: no coordinate given")
    if coordinates is not None:
        functions = {name: functions[name] for name in coordinates if name in functions}
    return functions


def _motion_from_file(path: Path, model: Model, coordinates: Sequence[str] | None,
                      interpolation: str) -> dict[str, TimeFunction]:
    if not path.is_file():
        raise CmbsError(f"{path}: no such motion file")
    if path.suffix.lower() == ".npz" or _is_result_csv(path):
        motion = Trajectory.load(path)
        times, columns = motion.t, {name: motion.q[:, k] for k, name in enumerate(motion.names)}
    else:
        times, columns = _read_table(path)
    available = [name for name in model.coordinate_names if name in columns]
    if coordinates is None:
        driven = [model.coordinate_names[c] for c in driven_columns(model)] if model.drivers.any() else []
        coordinates = driven if driven and all(name in columns for name in driven) else available
    missing = [name for name in coordinates if name not in columns]
    if missing or not coordinates:
        raise CmbsError(f"{path}: no column for coordinate(s) {', '.join(missing) or '(none matches the model)'}; "
                        f"columns: {', '.join(columns)}; model coordinates: {', '.join(model.coordinate_names)}")
    functions = {}
    for name in coordinates:
        try:
            functions[name] = Table(times, columns[name], interpolation)
        except CmbsError as error:
            raise CmbsError(f"{path}, column {name!r}: {error}") from None
    return functions


def _is_result_csv(path: Path) -> bool:
    with path.open() as stream:
        for line in stream:
            if not line.startswith("#"):
                return "_dot" in line
    return False


def _read_table(path: Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    numbered = [(number, line.strip()) for number, line in enumerate(path.read_text().splitlines(), start=1)]
    numbered = [(number, line) for number, line in numbered if line and not line.startswith("#")]
    if not numbered:
        raise CmbsError(f"{path}: empty motion file")
    header = [name.strip() for name in numbered[0][1].split(",")]
    if header[0] != "t" or len(header) < 2:
        raise CmbsError(f"{path}: the header must be 't,<coordinate>,...', got {numbered[0][1]!r}")
    rows = []
    for number, line in numbered[1:]:
        fields = line.split(",")
        if len(fields) != len(header):
            raise CmbsError(f"{path}, line {number}: {len(fields)} values for {len(header)} columns")
        try:
            rows.append([float(field) for field in fields])
        except ValueError:
            raise CmbsError(f"{path}, line {number}: not a number in {line!r}") from None
    table = np.array(rows, ndmin=2)
    if not np.all(np.isfinite(table)):
        raise CmbsError(f"{path}: the table contains a non-finite value")
    return table[:, 0], {name: table[:, k] for k, name in enumerate(header[1:], start=1)}
