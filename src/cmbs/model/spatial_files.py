"""TOML model files for spatial natural-coordinate models: ``dimension = 3`` in ``[model]``
(format: docs/model-format.md, "Spatial models").

The same rules as the planar files (:mod:`cmbs.model.files`): a file is data, parsed with
:mod:`tomllib`; every table and key is checked (unknown keys are errors); every mistake raises
:class:`~cmbs.errors.ModelError` naming the file, the entry and the value.  The entries map one
to one onto :class:`~cmbs.model.spatial.SpatialModelBuilder`'s calls.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Callable

from cmbs.errors import ModelError
from cmbs.model.drivers import TimeFunction
from cmbs.model.files import Entry, apply_sections, read_actuator, read_driver
from cmbs.model.spatial import SpatialModelBuilder

#: the sections of a spatial model file
SECTIONS = ("model", "points", "vectors", "bodies", "rods", "distances", "sliders", "dots", "angles", "drivers",
            "springs", "rotational_springs", "forces", "moments", "actuators", "initial_velocities")


def read_spatial_builder(document: dict, base: Path, default_name: str) -> SpatialModelBuilder:
    """The builder of a spatial model file's ``document`` (``[model] dimension = 3``); ``base`` is
    the file's folder (for drivers' CSV files)."""
    unknown = sorted(set(document) - set(SECTIONS))
    if unknown:
        raise ModelError(f"unknown section(s) {', '.join(map(repr, unknown))} of a spatial model (dimension = 3; "
                         f"allowed: {', '.join(SECTIONS)})")
    if not document.get("points") and not document.get("vectors"):
        raise ModelError("the file defines no points or vectors (an empty model)", entry="points")
    header = Entry("model", document.get("model", {}), ("name", "description", "source", "gravity", "dimension"))
    gravity = _triple(header, "gravity")
    builder = SpatialModelBuilder(header.string("name") or default_name,
                                  gravity=(0.0, 0.0, -9.81) if gravity is None else gravity,
                                  description=header.string("description") or "", source=header.string("source") or "")
    handlers: dict[str, Callable[[str, object], None]] = {
        "points": lambda name, t: _point(builder, name, t),
        "vectors": lambda name, t: _vector(builder, name, t),
        "bodies": lambda name, t: _body(builder, name, t),
        "rods": lambda name, t: _rod(builder, name, t),
        "distances": lambda name, t: _distance(builder, name, t),
        "sliders": lambda name, t: _slider(builder, name, t),
        "dots": lambda name, t: _dot(builder, name, t),
        "angles": lambda name, t: _angle(builder, name, t),
        "drivers": lambda name, t: read_driver(builder, name, t, base),
        "springs": lambda name, t: _spring(builder, name, t),
        "rotational_springs": lambda name, t: _rotational_spring(builder, name, t),
        "forces": lambda name, t: _force(builder, name, t, base),
        "moments": lambda name, t: _moment(builder, name, t, base),
        "actuators": lambda name, t: read_actuator(builder, name, t),
    }
    apply_sections(document, handlers)
    return builder


def entry_of_constraint(constraint: str, drivers: frozenset[str] = frozenset()) -> str:
    """The file entry behind a spatial constraint name: 'rigid top: u·v' and 'body top: tip.x' ->
    'bodies.top', 'rigid crank' -> 'rods.crank', 'distance rod' -> 'distances.rod', 'slider s.x'
    -> 'sliders.s', 'dot plane' -> 'dots.plane', 'angle turn' -> 'angles.turn', a name in ``drivers`` ->
    'drivers.NAME'."""
    if constraint in drivers:
        return f"drivers.{constraint}"
    kind, _, name = constraint.partition(" ")
    if kind == "body" or (kind == "rigid" and ": " in name):
        return f"bodies.{name.partition(': ')[0]}"
    if kind == "slider":
        return f"sliders.{name.rpartition('.')[0]}"
    return {"rigid": "rods", "distance": "distances", "dot": "dots", "angle": "angles"}.get(kind, "model") + f".{name}"


def _triple(entry: Entry, key: str) -> tuple[float, float, float] | None:
    value = entry.get(key)
    if value is None:
        return None
    if not (isinstance(value, list) and len(value) == 3 and all(_finite(v) for v in value)):
        raise ModelError(f"{key} must be a list of three finite numbers, got {value!r}", entry=entry.label)
    return float(value[0]), float(value[1]), float(value[2])


def _finite(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _names(entry: Entry, key: str, count: int | None = None) -> list[str]:
    value = entry.get(key, [])
    if not (isinstance(value, list) and all(isinstance(v, str) for v in value)) or \
            (count is not None and len(value) != count):
        what = f"{count} names" if count is not None else "names"
        raise ModelError(f"{key} must be a list of {what}, got {value!r}", entry=entry.label)
    return value


def _flag(entry: Entry, key: str) -> bool:
    value = entry.get(key, False)
    if not isinstance(value, bool):
        raise ModelError(f"{key} must be true or false, got {value!r}", entry=entry.label)
    return value


def _point(builder: SpatialModelBuilder, name: str, table: object) -> None:
    entry = Entry(f"points.{name}", table, ("position", "fixed", "mass"), ("position",))
    builder.add_point(name, _triple(entry, "position"), fixed=_flag(entry, "fixed"), mass=entry.number("mass", 0.0))


def _vector(builder: SpatialModelBuilder, name: str, table: object) -> None:
    entry = Entry(f"vectors.{name}", table, ("direction", "fixed"), ("direction",))
    builder.add_vector(name, _triple(entry, "direction"), fixed=_flag(entry, "fixed"))


def _inertia(entry: Entry) -> list[list[float]]:
    """A 3x3 tensor, or three principal moments [Ixx, Iyy, Izz] in ground axes."""
    value = entry.get("inertia")
    if isinstance(value, list) and len(value) == 3 and all(_finite(v) for v in value):
        return [[float(value[0]), 0.0, 0.0], [0.0, float(value[1]), 0.0], [0.0, 0.0, float(value[2])]]
    if isinstance(value, list) and len(value) == 3 and all(
            isinstance(row, list) and len(row) == 3 and all(_finite(v) for v in row) for row in value):
        return [[float(v) for v in row] for row in value]
    raise ModelError(f"inertia must be a 3x3 tensor [[...], [...], [...]] or three moments [Ixx, Iyy, Izz] (kg m², "
                     f"about the centre of mass, ground axes at the start), got {value!r}", entry=entry.label)


def _body(builder: SpatialModelBuilder, name: str, table: object) -> None:
    entry = Entry(f"bodies.{name}", table, ("origin", "basis", "mass", "com", "inertia", "points", "vectors"),
                  ("origin", "basis", "mass", "com", "inertia"))
    builder.add_body(name, origin=entry.string("origin"), basis=_names(entry, "basis", 3),
                     mass=entry.number("mass"), com=_triple(entry, "com"), inertia=_inertia(entry),
                     points=_names(entry, "points"), vectors=_names(entry, "vectors"))


def _rod(builder: SpatialModelBuilder, name: str, table: object) -> None:
    entry = Entry(f"rods.{name}", table, ("points", "mass", "com", "inertia"), ("points", "mass"))
    i, j = entry.pair("points", str)
    builder.add_rod(name, i, j, mass=entry.number("mass"), com=entry.number("com", 0.5),
                    inertia=entry.number("inertia"))


def _distance(builder: SpatialModelBuilder, name: str, table: object) -> None:
    entry = Entry(f"distances.{name}", table, ("points", "initial"), ("points",))
    i, j = entry.pair("points", str)
    builder.add_distance(name, i, j, initial=entry.number("initial"))


def _slider(builder: SpatialModelBuilder, name: str, table: object) -> None:
    entry = Entry(f"sliders.{name}", table, ("point", "origin", "axis", "initial"), ("point", "origin", "axis"))
    builder.add_slider(name, point=entry.string("point"), origin=entry.string("origin"), axis=entry.string("axis"),
                       initial=entry.number("initial"))


def _element(entry: Entry, key: str) -> str | tuple[str, str]:
    value = entry.get(key)
    if isinstance(value, str):
        return value
    if isinstance(value, list) and len(value) == 2 and all(isinstance(v, str) for v in value):
        return value[0], value[1]
    raise ModelError(f"{key} must be a vector's name or a pair of point names [head, tail], got {value!r}",
                     entry=entry.label)


def _dot(builder: SpatialModelBuilder, name: str, table: object) -> None:
    entry = Entry(f"dots.{name}", table, ("a", "b", "value"), ("a", "b"))
    builder.add_dot(name, _element(entry, "a"), _element(entry, "b"), value=entry.number("value"))


def _spring(builder: SpatialModelBuilder, name: str, table: object) -> None:
    entry = Entry(f"springs.{name}", table, ("points", "stiffness", "damping", "rest_length"),
                  ("points", "stiffness"))
    i, j = entry.pair("points", str)
    builder.add_spring(name, i, j, stiffness=entry.number("stiffness"), damping=entry.number("damping", 0.0),
                       rest_length=entry.number("rest_length"))


def _rotational_spring(builder: SpatialModelBuilder, name: str, table: object) -> None:
    entry = Entry(f"rotational_springs.{name}", table, ("angle", "stiffness", "damping", "rest_angle"),
                  ("angle", "stiffness"))
    builder.add_rotational_spring(name, angle=entry.string("angle"), stiffness=entry.number("stiffness"),
                                  damping=entry.number("damping", 0.0), rest_angle=entry.number("rest_angle"))


def _components(entry: Entry, key: str, base: Path) -> list[TimeFunction]:
    """Three components [x, y, z], each a number, an expression of t or a table {t, value}."""
    value = entry.get(key)
    if not (isinstance(value, list) and len(value) == 3):
        raise ModelError(f"{key} must be a list of three components (numbers, expressions of t or tables), got "
                         f"{value!r}", entry=entry.label)
    return [Entry(f"{entry.label}.{key}", {axis: component}, (axis,)).time_function(axis, base)
            for axis, component in zip("xyz", value)]


def _force(builder: SpatialModelBuilder, name: str, table: object, base: Path) -> None:
    entry = Entry(f"forces.{name}", table, ("point", "force", "body"), ("point", "force"))
    builder.add_force(name, point=entry.string("point"), force=_components(entry, "force", base),
                      body=entry.string("body"))


def _moment(builder: SpatialModelBuilder, name: str, table: object, base: Path) -> None:
    entry = Entry(f"moments.{name}", table, ("body", "moment", "frame"), ("body", "moment"))
    builder.add_moment(name, body=entry.string("body"), moment=_components(entry, "moment", base),
                       frame=entry.string("frame") or "ground")


def _angle(builder: SpatialModelBuilder, name: str, table: object) -> None:
    entry = Entry(f"angles.{name}", table, ("reference", "vector", "axis", "initial"), ("reference", "vector", "axis"))
    builder.add_angle(name, reference=_element(entry, "reference"), vector=_element(entry, "vector"),
                      axis=entry.string("axis"), initial=entry.number("initial"))
