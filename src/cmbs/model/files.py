"""TOML model files for natural-coordinate models (format: docs/model-format.md): planar ones
here, spatial ones (``[model] dimension = 3``) in :mod:`cmbs.model.spatial_files`; robot files
(``[model] urdf = ...``, a URDF robot and its loop closures) in :mod:`cmbs.model.robot_files`.

A file is data: it is parsed with :mod:`tomllib`, every table and key is checked against the
format (unknown keys are errors, so typos do not pass silently), driver and force expressions go
through the restricted parser, and the model is assembled once to prove that it closes.  Every
mistake raises :class:`~cmbs.errors.ModelError` naming the file, the entry and the problem.
"""

from __future__ import annotations

import csv
import functools
import math
import tomllib
from pathlib import Path
from typing import Any, Callable

import numpy as np

from cmbs.errors import ConvergenceError, ModelError, did_you_mean
from cmbs.model.drivers import Table, TimeFunction, as_time_function, checked_at_start
from cmbs.model.model import Model
from cmbs.model.natural import NaturalModelBuilder

_SECTIONS = ("model", "points", "segments", "bodies", "angles", "distances", "sliders", "drivers", "forces",
             "torques", "moments", "springs", "actuators", "initial_velocities")


class Entry:
    """One table of the file (e.g. ``segments.crank``) with typed accessors naming it in errors."""

    def __init__(self, label: str, table: object, allowed: tuple[str, ...], required: tuple[str, ...] = ()):
        self.label = label
        if not isinstance(table, dict):
            raise ModelError(f"expected a table of keys, got {table!r}", entry=label)
        unknown = sorted(set(table) - set(allowed))
        if unknown:
            raise ModelError(f"unknown key(s) {', '.join(map(repr, unknown))}"
                             f"{did_you_mean(unknown, set(allowed) - set(table))} (allowed: {', '.join(allowed)})",
                             entry=label)
        missing = [key for key in required if key not in table]
        if missing:
            raise ModelError(f"missing key(s) {', '.join(map(repr, missing))}", entry=label)
        self.table = table

    def get(self, key: str, default: Any = None) -> Any:
        return self.table.get(key, default)

    def number(self, key: str, default: float | None = None) -> float | None:
        value = self.table.get(key, default)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ModelError(f"{key} must be a number, got {value!r}", entry=self.label)
        return float(value)

    def string(self, key: str) -> str | None:
        value = self.table.get(key)
        if value is not None and not isinstance(value, str):
            raise ModelError(f"{key} must be a string (a name), got {value!r}", entry=self.label)
        return value

    def pair(self, key: str, kind: type = float) -> tuple | None:
        value = self.table.get(key)
        if value is None:
            return None
        ok = isinstance(value, list) and len(value) == 2 and all(
            isinstance(v, str) if kind is str else (isinstance(v, (int, float)) and not isinstance(v, bool)
                                                    and math.isfinite(v))
            for v in value)
        if not ok:
            what = "two names" if kind is str else "two finite numbers"
            raise ModelError(f"{key} must be a list of {what}, got {value!r}", entry=self.label)
        return tuple(value) if kind is str else (float(value[0]), float(value[1]))

    def time_function(self, key: str, base: Path, interpolation: str | None = None) -> TimeFunction:
        value = self.table.get(key, 0.0)
        if isinstance(value, dict):
            function: TimeFunction = _table(Entry(f"{self.label}.{key}", value, ("t", "value", "interpolation")),
                                            base, interpolation)
        elif isinstance(value, bool) or not isinstance(value, (int, float, str)):
            raise ModelError(f"{key} must be a number, an expression of t or a table, got {value!r}",
                             entry=self.label)
        else:
            try:
                function = as_time_function(value)
            except ModelError as error:
                raise ModelError(error.problem, entry=f"{self.label}.{key}") from None
        return checked_at_start(function, f"{self.label}.{key}")


def _table(entry: Entry, base: Path, default_interpolation: str | None = None) -> Table:
    if default_interpolation is not None and "interpolation" in entry.table:
        raise ModelError("'interpolation' is given both in the driver and in its table; give it once",
                         entry=entry.label)
    interpolation = entry.get("interpolation", default_interpolation or "spline")
    try:
        return Table(np.asarray(entry.get("t"), dtype=float), np.asarray(entry.get("value"), dtype=float),
                     interpolation)
    except (ValueError, TypeError):
        raise ModelError("t and value must be lists of numbers", entry=entry.label) from None
    except ModelError as error:
        raise ModelError(error.problem, entry=entry.label) from None


def _file_table(entry: Entry, path_text: str, base: Path, interpolation: str) -> Table:
    """A driver table read from a two-column CSV file (t, value) relative to the model file."""
    path = (base / path_text) if not Path(path_text).is_absolute() else Path(path_text)
    try:
        if not path.is_file():
            raise ModelError(f"file {str(path)!r} not found", entry=f"{entry.label}.file")
        with path.open(newline="") as stream:
            rows = [row for row in csv.reader(stream) if row and not row[0].lstrip().startswith("#")]
        if rows and not _is_number(rows[0][0]):
            rows = rows[1:]
        data = np.array([[float(v) for v in row[:2]] for row in rows])
    except (OSError, UnicodeDecodeError) as error:
        raise ModelError(f"file {str(path)!r} cannot be read ({_reason(error)})", entry=f"{entry.label}.file") \
            from None
    except (ValueError, IndexError):
        raise ModelError(f"{str(path)!r} must have two numeric columns t, value", entry=f"{entry.label}.file") \
            from None
    if data.ndim != 2 or data.shape[1] != 2:
        raise ModelError(f"{str(path)!r} must have two numeric columns t, value", entry=f"{entry.label}.file")
    try:
        return Table(data[:, 0], data[:, 1], interpolation)
    except ModelError as error:
        raise ModelError(error.problem, entry=f"{entry.label}.file") from None


def _reason(error: OSError | UnicodeDecodeError) -> str:
    """The system's reason for a failed read, without the file name it repeats."""
    return getattr(error, "strerror", None) or "not a text file"


def _is_number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def entries(document: dict, section: str) -> list[tuple[str, object]]:
    """The (name, table) pairs of the section ``[section.NAME]`` (none when it is absent); a
    section that is not a table of named entries is a ModelError naming it."""
    tables = document.get(section, {})
    if not isinstance(tables, dict):
        raise ModelError(f"[{section}] must be a table of named entries", entry=section)
    return list(tables.items())


def read_driver(builder: NaturalModelBuilder, name: str, table: object, base: Path) -> None:
    """The entry ``[drivers.NAME]`` (``coordinate`` and one of ``expression``, ``table``,
    ``file``; docs/model-format.md section 4) added to ``builder`` (anything with
    ``add_driver(coordinate, function, name=...)``); files relative to ``base``."""
    entry = Entry(f"drivers.{name}", table, ("coordinate", "expression", "table", "file", "interpolation"),
                  ("coordinate",))
    given = [key for key in ("expression", "table", "file") if key in entry.table]
    if len(given) != 1:
        raise ModelError("give exactly one of 'expression', 'table' or 'file'", entry=entry.label)
    interpolation = entry.string("interpolation")
    if given[0] == "file":
        function: TimeFunction = _file_table(entry, entry.string("file"), base, interpolation or "spline")
    elif given[0] == "table":
        if not isinstance(entry.get("table"), dict):
            raise ModelError(f"table must be an inline table {{ t = [...], value = [...] }}, got "
                             f"{entry.get('table')!r}", entry=entry.label)
        function = entry.time_function("table", base, interpolation)
    else:
        if interpolation is not None:
            raise ModelError("'interpolation' applies to a 'table' or 'file' driver, not to an expression",
                             entry=entry.label)
        if not isinstance(entry.get("expression"), (str, int, float)) or isinstance(entry.get("expression"), bool):
            raise ModelError(f"expression must be a string, got {entry.get('expression')!r}", entry=entry.label)
        function = entry.time_function("expression", base)
    builder.add_driver(entry.string("coordinate"), function, name=name)


def _read_builder(document: dict, base: Path, default_name: str) -> NaturalModelBuilder:
    unknown = sorted(set(document) - set(_SECTIONS))
    if unknown:
        raise ModelError(f"unknown section(s) {', '.join(map(repr, unknown))} (allowed: {', '.join(_SECTIONS)})")
    if not any(document.get(section) for section in _SECTIONS if section != "model"):
        raise ModelError("the file defines no points (an empty model)", entry="points")
    header = Entry("model", document.get("model", {}), ("name", "description", "source", "gravity", "dimension"))
    builder = NaturalModelBuilder(header.string("name") or default_name, gravity=header.pair("gravity") or (0.0, -9.81),
                                  description=header.string("description") or "", source=header.string("source") or "")
    handlers: dict[str, Callable[[str, object], None]] = {
        "points": lambda name, t: _point(builder, name, t),
        "segments": lambda name, t: _segment(builder, name, t),
        "bodies": lambda name, t: _body(builder, name, t),
        "distances": lambda name, t: _distance(builder, name, t),
        "angles": lambda name, t: _angle(builder, name, t),
        "sliders": lambda name, t: _slider(builder, name, t),
        "drivers": lambda name, t: read_driver(builder, name, t, base),
        "forces": lambda name, t: _force(builder, name, t, base),
        "torques": lambda name, t: _torque(builder, name, t, base),
        "moments": lambda name, t: _moment(builder, name, t, base),
        "springs": lambda name, t: _spring(builder, name, t),
        "actuators": lambda name, t: read_actuator(builder, name, t),
    }
    apply_sections(document, handlers)
    return builder


def apply_sections(document: dict, handlers: dict[str, Callable[[str, object], None]]) -> None:
    """Call each section's handler on the section's named entries, in the order of ``handlers``;
    an error is located at its entry ``SECTION.NAME``."""
    for section, handler in handlers.items():
        for name, table in entries(document, section):
            try:
                handler(name, table)
            except ModelError as error:
                raise error.located(entry=f"{section}.{name}") from None


def _point(builder: NaturalModelBuilder, name: str, table: object) -> None:
    entry = Entry(f"points.{name}", table, ("x", "z", "fixed", "mass"), ("x", "z"))
    fixed = entry.get("fixed", False)
    if not isinstance(fixed, bool):
        raise ModelError(f"fixed must be true or false, got {fixed!r}", entry=entry.label)
    builder.add_point(name, entry.number("x"), entry.number("z"), fixed=fixed, mass=entry.number("mass", 0.0))


def _segment(builder: NaturalModelBuilder, name: str, table: object) -> None:
    entry = Entry(f"segments.{name}", table, ("points", "mass", "com", "inertia", "length"), ("points", "mass"))
    i, j = entry.pair("points", str)
    builder.add_segment(name, i, j, mass=entry.number("mass"), com=entry.pair("com"),
                        inertia=entry.number("inertia"), length=entry.number("length"))


def _body(builder: NaturalModelBuilder, name: str, table: object) -> None:
    entry = Entry(f"bodies.{name}", table, ("points", "mass", "com", "inertia", "length", "local"),
                  ("points", "mass"))
    given = entry.get("local", {})
    local = Entry(f"{entry.label}.local", given, tuple(given) if isinstance(given, dict) else ())
    builder.add_body(name, entry.get("points"), mass=entry.number("mass"), com=entry.pair("com"),
                     inertia=entry.number("inertia"), length=entry.number("length"),
                     local={point: local.pair(point) for point in local.table})


def _distance(builder: NaturalModelBuilder, name: str, table: object) -> None:
    entry = Entry(f"distances.{name}", table, ("points", "initial"), ("points",))
    i, j = entry.pair("points", str)
    builder.add_distance(name, i, j, initial=entry.number("initial"))


def _angle(builder: NaturalModelBuilder, name: str, table: object) -> None:
    entry = Entry(f"angles.{name}", table, ("segment", "from", "to", "initial"))
    builder.add_angle(name, segment=entry.get("segment"), from_segment=entry.get("from"),
                      to_segment=entry.get("to"), initial=entry.number("initial"))


def _slider(builder: NaturalModelBuilder, name: str, table: object) -> None:
    entry = Entry(f"sliders.{name}", table, ("point", "line", "segment", "through", "direction", "lock"),
                  ("point",))
    builder.add_slider(name, point=entry.string("point"), line=entry.pair("line", str),
                       segment=entry.string("segment"), through=entry.pair("through"),
                       direction=entry.pair("direction"), lock=entry.string("lock"))


def _force(builder: NaturalModelBuilder, name: str, table: object, base: Path) -> None:
    entry = Entry(f"forces.{name}", table, ("point", "segment", "at", "frame", "fx", "fz"))
    builder.add_force(name, point=entry.string("point"), fx=entry.time_function("fx", base),
                      fz=entry.time_function("fz", base), segment=entry.string("segment"), at=entry.pair("at"),
                      frame=entry.get("frame", "ground"))


def _torque(builder: NaturalModelBuilder, name: str, table: object, base: Path) -> None:
    entry = Entry(f"torques.{name}", table, ("angle", "torque"), ("angle", "torque"))
    builder.add_torque(name, angle=entry.string("angle"), torque=entry.time_function("torque", base))


def _moment(builder: NaturalModelBuilder, name: str, table: object, base: Path) -> None:
    entry = Entry(f"moments.{name}", table, ("segment", "moment"), ("segment", "moment"))
    builder.add_moment(name, segment=entry.string("segment"), moment=entry.time_function("moment", base))


def _spring(builder: NaturalModelBuilder, name: str, table: object) -> None:
    entry = Entry(f"springs.{name}", table, ("points", "stiffness", "damping", "rest_length"),
                  ("points", "stiffness"))
    i, j = entry.pair("points", str)
    builder.add_spring(name, i, j, stiffness=entry.number("stiffness"), damping=entry.number("damping", 0.0),
                       rest_length=entry.number("rest_length"))


def read_actuator(builder: NaturalModelBuilder, name: str, table: object) -> None:
    """The entry ``[actuators.NAME]`` (``coordinate``, ``gain``) added to ``builder``."""
    entry = Entry(f"actuators.{name}", table, ("coordinate", "gain"), ("coordinate",))
    builder.add_actuator(name, coordinate=entry.string("coordinate"), gain=entry.number("gain", 1.0))


def _entry_of_constraint(constraint: str, bodies: frozenset[str] = frozenset()) -> str:
    """'rigid crank' -> 'segments.crank' (the file entry behind a constraint name); the rigid row
    of a body in ``bodies`` and its rows 'body NAME: K.x' -> 'bodies.NAME'."""
    kind, _, name = constraint.partition(" ")
    if kind == "body":
        return f"bodies.{name.rpartition(': ')[0]}"
    if kind == "rigid" and name in bodies:
        return f"bodies.{name}"
    section = {"rigid": "segments", "distance": "distances", "angle": "angles", "slider": "sliders"}.get(kind)
    if section is None:
        return f"drivers.{constraint}"
    return f"{section}.{name.removesuffix(' lock')}"


def assembled(model: Model, source: str, given_velocities: tuple[str, ...] = (),
              entry_of: Callable[[str], str] | None = None) -> Model:
    """Return ``model`` with q0 assembled and q̇0 consistent, or a :class:`ModelError` naming the
    constraint that could not be closed (e.g. a segment whose points cannot be at its length, or
    an angle half a turn away from the direction of its points), or the driver whose value at
    t = 0 the mechanism cannot reach (:func:`_unreachable_drivers`).

    q̇0 solves Φ_q q̇ = -Φ_t at (q0, 0) with the velocities of ``given_velocities`` (coordinate
    names, from ``[initial_velocities]``) held at their values in ``model.qd0`` and the others
    corrected by least squares from theirs (minimum norm); given velocities that the constraints
    do not allow are an error (:func:`_check_velocities`).  ``entry_of`` names the file entry of a
    constraint (default: the planar sections', :func:`_entry_of_constraint`)."""
    from cmbs.kinematics import BranchError, assemble, velocities

    try:
        q0 = assemble(model, model.q0, 0.0)
    except ConvergenceError as error:
        blamed = None if isinstance(error, BranchError) else _unreachable_drivers(model)
        if blamed:
            raise ModelError(f"cannot be assembled at t = 0: {blamed[1]}", source=source, entry=blamed[0]) from None
        constraint = getattr(error, "constraint", "")
        entry = entry_of(constraint) if entry_of is not None else _entry_of_constraint(constraint, _body_names(model))
        raise ModelError(f"cannot be assembled: {error}", source=source, entry=entry) from None
    qd0 = velocities(model, q0, 0.0, qd=model.qd0, fixed=given_velocities)
    _check_velocities(model, q0, qd0, given_velocities, source)
    return model.replace(q0=q0, qd0=qd0)


def _body_names(model: Model) -> frozenset[str]:
    from cmbs.model.natural import NaturalEquations

    segments = model.equations.segments if isinstance(model.equations, NaturalEquations) else ()
    return frozenset(segment.name for segment in segments if segment.kind == "body")


def _driven_coordinates(model: Model) -> list[tuple[str, int, float]]:
    """(driver name, driven coordinate, its value f(0)) of every driver row Φ = q_c - f(t); rows
    of another form are left out."""
    terms = model.evaluate(model.q0, np.zeros(model.n), 0.0)
    driven = []
    for row in np.flatnonzero(model.drivers):
        coordinate = int(np.argmax(np.abs(terms.A[row])))
        unit = np.zeros(model.n)
        unit[coordinate] = 1.0
        if np.array_equal(terms.A[row], unit):
            driven.append((model.constraint_names[row], coordinate, float(model.q0[coordinate] - terms.phi[row])))
    return driven


def _unreachable_drivers(model: Model) -> tuple[str, str] | None:
    """When the mechanism assembles without its drivers but not with them, (entry, reason) naming
    the driver whose value at t = 0 it cannot reach: the mechanism assembled with that driver's
    coordinate held at f(0) fails.  When each value is reachable alone but not all together, the
    drivers are named together.  None when the drivers are not shown to be the cause."""
    from cmbs.kinematics import assemble

    driven = _driven_coordinates(model)
    if not driven:
        return None
    free = model.without_drivers()
    try:
        start = assemble(free, model.q0, 0.0)
    except ConvergenceError:
        return None                     # the mechanism does not close even without its drivers

    def reachable(drivers: list[tuple[str, int, float]]) -> bool:
        q = start.copy()
        for _, coordinate, value in drivers:
            q[coordinate] = value
        try:
            assemble(free, q, 0.0, fixed=[coordinate for _, coordinate, _ in drivers])
        except ConvergenceError:
            return False
        return True

    def held(name: str, coordinate: int, value: float) -> str:
        return f"drivers.{name} holds {model.coordinate_names[coordinate]} at {value:.6g} at t = 0"

    for name, coordinate, value in driven:
        if not reachable([(name, coordinate, value)]):
            return (f"drivers.{name}", f"{held(name, coordinate, value)}, which the mechanism cannot reach (it "
                                       "assembles without its drivers); change the driver's value at t = 0 or the "
                                       "lengths")
    if len(driven) > 1 and not reachable(driven):
        return ("drivers", f"the drivers' values at t = 0 cannot all be reached together, though each can alone "
                           f"({'; '.join(held(*d) for d in driven)})")
    return None


def coordinate_values(document: dict, section: str, model: Model, start: np.ndarray, *, noun: str = "coordinate",
                      quantity: str = "value") -> tuple[np.ndarray, tuple[str, ...]]:
    """A copy of ``start`` (n,) with the numbers of the table ``[section]`` ({name: number}, each
    name a coordinate of ``model``, a ``noun`` in the messages) in place, and the names given.
    One-line errors for a section that is not a table, an unknown name and a ``quantity`` that is
    not a finite number."""
    table = document.get(section, {})
    if not isinstance(table, dict):
        raise ModelError(f"[{section}] must be a table of {noun} = {quantity}", entry=section)
    values = np.array(start, dtype=float)
    names = model.coordinate_names
    for name, value in table.items():
        entry = f"{section}.{name}"
        if name not in names:
            raise ModelError(f"unknown {noun} {name!r}{did_you_mean(name, names)} ({noun}s: {', '.join(names)})",
                             entry=entry)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ModelError(f"the {quantity} must be a finite number, got {value!r}", entry=entry)
        values[model.coordinate_index(name)] = float(value)
    return values, tuple(table)


def initial_velocities(document: dict, model: Model) -> tuple[Model, tuple[str, ...]]:
    """``model`` with the velocities of ``[initial_velocities]`` ({coordinate: value}) in its
    q̇0, and their coordinate names."""
    qd0, names = coordinate_values(document, "initial_velocities", model, model.qd0, quantity="velocity")
    return model.replace(qd0=qd0), names


#: largest |Φ_q q̇0 + Φ_t| (relative to 1 + max |q̇0|) accepted for the given initial velocities
VELOCITY_TOLERANCE = 1e-9


def _check_velocities(model: Model, q0: np.ndarray, qd0: np.ndarray, given: tuple[str, ...], source: str) -> None:
    """The given initial velocities must be possible: with them held, Φ_q q̇ = -Φ_t must have a
    solution (they are independent, and a driven coordinate gets its driver's rate)."""
    if not given or model.m == 0:
        return
    terms = model.evaluate(q0, qd0, 0.0)
    residual = np.abs(terms.A @ qd0 + terms.phi_t)
    worst = int(np.argmax(residual))
    if residual[worst] <= VELOCITY_TOLERANCE * (1.0 + float(np.max(np.abs(qd0)))):
        return
    values = ", ".join(f"{name} = {qd0[model.coordinate_index(name)]:g}" for name in given)
    row = model.constraint_names[worst]
    raise ModelError(f"the given velocities ({values}) violate the velocity constraints at t = 0 (residual "
                     f"{residual[worst]:.3g} in {'driver' if model.drivers[worst] else 'constraint'} {row!r}): give "
                     "only independent ones, at most one per degree of freedom, and none of a driven coordinate "
                     "other than its driver's rate", source=source, entry="initial_velocities")


def load_model_file(path: str | Path) -> Model:
    """Read, validate and assemble a TOML model file.

    Raises
    ------
    ModelError
        ``<file>: <entry>: <problem>`` for every mistake in the file.
    """
    path = Path(path)
    source = str(path)
    try:
        if path.is_dir():
            raise ModelError("is a folder, not a model file (give the path of a .toml file)", source=source)
        if not path.is_file():
            raise ModelError("no such model file", source=source)
        document = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as error:
        raise ModelError(f"not valid TOML: {error}", source=source) from None
    except UnicodeDecodeError:
        raise ModelError("not a text file", source=source) from None
    except OSError as error:
        raise ModelError(f"cannot be read ({_reason(error)})", source=source) from None
    header = document.get("model")
    if isinstance(header, dict) and "urdf" in header:
        from cmbs.model.robot_files import read_robot_file

        return read_robot_file(document, path)
    try:
        entry_of = None
        if _dimension(document) == 3:
            from cmbs.model.spatial_files import entry_of_constraint, read_spatial_builder

            model = read_spatial_builder(document, path.parent, path.stem).build()
            entry_of = functools.partial(entry_of_constraint, drivers=frozenset(model.driver_names))
        else:
            model = _read_builder(document, path.parent, path.stem).build()
        model, given_velocities = initial_velocities(document, model)
    except ModelError as error:
        raise error.located(source=source) from None
    return assembled(model, source, given_velocities, entry_of)


def _dimension(document: dict) -> int:
    """The file's ``[model] dimension``: 2 (the plane, the default) or 3 (space)."""
    header = document.get("model", {})
    value = header.get("dimension", 2) if isinstance(header, dict) else 2
    if isinstance(value, bool) or value not in (2, 3):
        raise ModelError(f"dimension must be 2 (planar) or 3 (spatial), got {value!r}", entry="model.dimension")
    return int(value)
