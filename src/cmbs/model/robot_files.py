"""Robot model files: a small TOML file that names a URDF robot and closes its loops
(docs/robots.md, "Loop closures").

``urdf`` in ``[model]`` (a path relative to the TOML file) makes a file a robot file; its other
sections are ``[closures.NAME]`` (:class:`~cmbs.model.robot_closures.Closure`), ``[drivers.NAME]``
(a joint's prescribed motion, as in the natural-coordinate files: ``coordinate`` names the joint),
``[initial_positions]`` (joint = value: the guess assembly starts from, default 0) and
``[initial_velocities]``.  The file is data, checked key by key before any work (unknown keys,
wrong types, vectors of the wrong length, unknown links, joints and kinds are one-line errors
naming the file, the entry and the field), then the model is assembled
(:func:`cmbs.model.files.assembled`).
"""

from __future__ import annotations

import math
from pathlib import Path

from cmbs.errors import ModelError, did_you_mean
from cmbs.model.files import _driver, _Entry, _entries, _initial_velocities, assembled, coordinate_values
from cmbs.model.model import Model
from cmbs.model.robot import JointDriver
from cmbs.model.robot_closures import CLOSURE_KINDS, Closure

__all__ = ["SECTIONS", "read_robot_file"]

SECTIONS = ("model", "closures", "drivers", "initial_positions", "initial_velocities")
_CLOSURE_KEYS = ("kind", "link_a", "link_b", "point_a", "point_b", "axis_a", "axis_b", "rpy_a", "rpy_b")
_VECTORS = ("point_a", "point_b", "axis_a", "axis_b", "rpy_a", "rpy_b")


class _Drivers:
    """Collects the ``[drivers.NAME]`` entries (read by :func:`cmbs.model.files._driver`)."""

    def __init__(self) -> None:
        self.drivers: list[JointDriver] = []

    def add_driver(self, coordinate: str, function: object, *, name: str) -> None:
        self.drivers.append(JointDriver(name, coordinate, function))


def _vector(entry: _Entry, key: str) -> tuple[float, float, float] | None:
    value = entry.get(key)
    if value is None:
        return None
    if not (isinstance(value, list) and len(value) == 3 and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)):
        raise ModelError(f"{key} must be a list of 3 finite numbers, got {value!r}", entry=entry.label)
    return (float(value[0]), float(value[1]), float(value[2]))


def _closure(name: str, table: object) -> Closure:
    entry = _Entry(f"closures.{name}", table, _CLOSURE_KEYS, ("kind", "link_a", "link_b"))
    kind = entry.string("kind")
    if kind not in CLOSURE_KINDS:
        raise ModelError(f"kind: unknown kind {kind!r}{did_you_mean(kind, CLOSURE_KINDS)}; kinds: "
                         f"{', '.join(CLOSURE_KINDS)}", entry=entry.label)
    vectors = {key: _vector(entry, key) for key in _VECTORS}
    zero = (0.0, 0.0, 0.0)
    return Closure(name, kind, entry.string("link_a"), entry.string("link_b"), vectors["point_a"] or zero,
                   vectors["point_b"] or zero, vectors["axis_a"], vectors["axis_b"], vectors["rpy_a"] or zero,
                   vectors["rpy_b"] or zero)


def _initial_positions(document: dict, model: Model) -> Model:
    """``model`` with the joint values of ``[initial_positions]`` in its q0 (the assembly's guess)."""
    q0, _ = coordinate_values(document, "initial_positions", model, model.q0, noun="joint")
    return model.replace(q0=q0)


def _entry_of(constraint: str, drivers: frozenset[str]) -> str:
    """The file entry of a constraint row: ``closures.NAME`` for ``NAME.x`` etc., ``drivers.NAME``."""
    return f"drivers.{constraint}" if constraint in drivers else f"closures.{constraint.rpartition('.')[0]}"


def read_robot_file(document: dict, path: Path) -> Model:
    """The assembled robot model of the parsed robot file ``document`` read from ``path``
    (module docstring).  Errors are :class:`~cmbs.errors.ModelError` naming the file."""
    from cmbs.model.urdf import load_urdf

    source = str(path)
    try:
        unknown = sorted(set(document) - set(SECTIONS))
        if unknown:
            raise ModelError(f"unknown section(s) {', '.join(map(repr, unknown))} for a robot file (allowed: "
                             f"{', '.join(SECTIONS)})")
        header = _Entry("model", document.get("model", {}), ("name", "description", "source", "urdf", "gravity"),
                        ("urdf",))
        gravity = _vector(header, "gravity") or (0.0, 0.0, -9.81)
        closures = [_closure(name, table) for name, table in _entries(document, "closures")]
        drivers = _Drivers()
        for name, table in _entries(document, "drivers"):
            try:
                _driver(drivers, name, table, path.parent)  # type: ignore[arg-type]
            except ModelError as error:
                raise error.located(entry=f"drivers.{name}") from None
        urdf = Path(header.string("urdf"))
        urdf = urdf if urdf.is_absolute() else path.parent / urdf
        if not urdf.is_file():
            raise ModelError(f"urdf: no such file {str(urdf)!r}", entry="model")
    except ModelError as error:
        raise error.located(source=source) from None
    try:
        robot = load_urdf(urdf, gravity=gravity, closures=closures, drivers=drivers.drivers)
    except ModelError as error:
        if error.source is None:      # a closure's or driver's mistake: name this file's entry
            entry = error.entry or ""
            kind, _, name = entry.partition(" ")
            where = {"closure": "closures", "driver": "drivers"}.get(kind)
            raise ModelError(error.problem, source=source,
                             entry=f"{where}.{name.strip(chr(39))}" if where else entry or None) from None
        raise
    try:
        model = robot.replace(name=header.string("name") or path.stem,
                              description=header.string("description") or robot.description,
                              source=header.string("source") or robot.source)
        model = _initial_positions(document, model)
        model, given_velocities = _initial_velocities(document, model)
    except ModelError as error:
        raise error.located(source=source) from None
    drivers_named = frozenset(model.driver_names)
    return assembled(model, source, given_velocities, lambda constraint: _entry_of(constraint, drivers_named))
