"""Robot model files: a small TOML file that names a URDF robot and closes its loops
(docs/robots.md, "Loop closures").

``urdf`` in ``[model]`` (a path relative to the TOML file) makes a file a robot file
(``mimic = true`` there couples the URDF's mimic joints to the joints they mimic,
``joint_damping = true`` applies the URDF joints' ``<dynamics damping>`` as dampers,
``joint_limits = true`` keeps position analysis within the joints' limits); its other
sections are ``[closures.NAME]`` (:class:`~cmbs.model.robot_closures.Closure`), ``[drivers.NAME]``
(a joint's prescribed motion, as in the natural-coordinate files: ``coordinate`` names the joint;
or, with ``kind = "pose"``, a link frame's target pose: :class:`~cmbs.model.robot_targets.PoseDriver`),
``[springs.NAME]`` (a joint spring-damper: :class:`~cmbs.model.robot_loads.JointSpring`),
``[point_springs.NAME]`` (a spring-damper between two link points, or a link point and a world
point: :class:`~cmbs.model.robot_loads.PointSpring`; its default rest length is the points'
distance at the file's start, the assembled q0), ``[forces.NAME]`` and ``[moments.NAME]`` (a
force at a link point, a moment on a link: :class:`~cmbs.model.robot_loads.LinkForce`,
:class:`~cmbs.model.robot_loads.LinkMoment`),
``[initial_positions]`` (joint = value: the guess assembly starts from, default ``model.q0``) and
``[initial_velocities]``.  The file is data, checked key by key before any work (unknown keys,
wrong types, vectors of the wrong length, unknown links, joints and kinds are one-line errors
naming the file, the entry and the field), then the model is assembled
(:func:`cmbs.model.files.assembled`).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Sequence

from cmbs.errors import ModelError, did_you_mean
from cmbs.model.drivers import TimeFunction, as_time_function, checked_at_start
from cmbs.model.files import Entry, assembled, coordinate_values, entries, initial_velocities, read_driver
from cmbs.model.model import Model
from cmbs.model.robot import JointDriver
from cmbs.model.robot_closures import CLOSURE_KINDS, Closure
from cmbs.model.robot_loads import JointSpring, LinkForce, LinkMoment, PointSpring, measured_rest_length
from cmbs.model.robot_targets import PoseDriver

__all__ = ["SECTIONS", "read_robot_file"]

SECTIONS = ("model", "closures", "drivers", "springs", "point_springs", "forces", "moments", "initial_positions",
            "initial_velocities")
_CLOSURE_KEYS = ("kind", "link_a", "link_b", "point_a", "point_b", "axis_a", "axis_b", "rpy_a", "rpy_b")
_VECTORS = ("point_a", "point_b", "axis_a", "axis_b", "rpy_a", "rpy_b")
_POSE_KEYS = ("kind", "link", "point", "position", "rpy")
#: a driver's kinds: a joint's motion (the default) or a link frame's pose
DRIVER_KINDS = ("joint", "pose")


class _Drivers:
    """Collects the ``[drivers.NAME]`` entries (read by :func:`cmbs.model.files.read_driver` and
    :func:`_pose_driver`)."""

    def __init__(self) -> None:
        self.drivers: list[JointDriver | PoseDriver] = []

    def add_driver(self, coordinate: str, function: object, *, name: str) -> None:
        self.drivers.append(JointDriver(name, coordinate, function))


def _vector(entry: Entry, key: str) -> tuple[float, float, float] | None:
    value = entry.get(key)
    if value is None:
        return None
    if not (isinstance(value, list) and len(value) == 3 and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)):
        raise ModelError(f"{key} must be a list of 3 finite numbers, got {value!r}", entry=entry.label)
    return (float(value[0]), float(value[1]), float(value[2]))


def _closure(name: str, table: object) -> Closure:
    entry = Entry(f"closures.{name}", table, _CLOSURE_KEYS, ("kind", "link_a", "link_b"))
    kind = entry.string("kind")
    if kind not in CLOSURE_KINDS:
        raise ModelError(f"kind: unknown kind {kind!r}{did_you_mean(kind, CLOSURE_KINDS)}; kinds: "
                         f"{', '.join(CLOSURE_KINDS)}", entry=entry.label)
    vectors = {key: _vector(entry, key) for key in _VECTORS}
    zero = (0.0, 0.0, 0.0)
    return Closure(name, kind, entry.string("link_a"), entry.string("link_b"), vectors["point_a"] or zero,
                   vectors["point_b"] or zero, vectors["axis_a"], vectors["axis_b"], vectors["rpy_a"] or zero,
                   vectors["rpy_b"] or zero)


def _target(entry: Entry, key: str, axes: tuple[str, str, str]) -> tuple[TimeFunction, ...] | None:
    """The three functions of time of an entry's vector ``key`` (numbers or expressions of t: a
    pose driver's ``position`` or ``rpy``, a load's ``force`` or ``moment``), or None when not
    given."""
    value = entry.get(key)
    if value is None:
        return None
    if not (isinstance(value, list) and len(value) == 3 and all(
            isinstance(v, (int, float, str)) and not isinstance(v, bool) for v in value)):
        raise ModelError(f"{key} must be a list of 3 numbers or expressions of t, got {value!r}", entry=entry.label)
    functions = []
    for axis, item in zip(axes, value):
        label = f"{entry.label}.{key}.{axis}"
        try:
            functions.append(checked_at_start(as_time_function(item), label))
        except ModelError as error:
            raise error.located(entry=label) from None
    return tuple(functions)


def _pose_driver(name: str, entry: Entry) -> PoseDriver:
    """A ``[drivers.NAME]`` entry of kind ``"pose"``: ``link``, ``point``, ``position``, ``rpy``."""
    position = _target(entry, "position", ("x", "y", "z"))
    rpy = _target(entry, "rpy", ("roll", "pitch", "yaw"))
    if position is None and rpy is None:
        raise ModelError("give the target's 'position', its orientation 'rpy', or both", entry=entry.label)
    return PoseDriver(name, entry.string("link"), _vector(entry, "point") or (0.0, 0.0, 0.0), position, rpy)


def _spring(name: str, table: object) -> JointSpring:
    """A ``[springs.NAME]`` entry: ``joint``, ``stiffness``, ``rest``, ``damping`` (their values
    are checked by :func:`~cmbs.model.robot_loads.load_elements`)."""
    entry = Entry(f"springs.{name}", table, ("joint", "stiffness", "rest", "damping"), ("joint",))
    return JointSpring(name, entry.string("joint"), entry.number("stiffness", 0.0), entry.number("rest", 0.0),
                       entry.number("damping", 0.0))


def _point_spring(name: str, table: object) -> PointSpring:
    """A ``[point_springs.NAME]`` entry: ``link_a``, ``point_a``, ``link_b``, ``point_b``, ``stiffness``,
    ``damping``, ``rest_length`` (the points default to the links' origins; the values are checked
    by :func:`~cmbs.model.robot_loads.load_elements`)."""
    entry = Entry(f"point_springs.{name}", table,
                  ("link_a", "point_a", "link_b", "point_b", "stiffness", "damping", "rest_length"),
                  ("link_a", "link_b", "stiffness"))
    zero = (0.0, 0.0, 0.0)
    return PointSpring(name, entry.string("link_a"), _vector(entry, "point_a") or zero, entry.string("link_b"),
                       _vector(entry, "point_b") or zero, entry.number("stiffness"), entry.number("damping", 0.0),
                       entry.number("rest_length"))


def _load(section: str, name: str, table: object) -> LinkForce | LinkMoment:
    """A ``[forces.NAME]`` entry (``link``, ``point``, ``force``, ``frame``) or a ``[moments.NAME]``
    one (``link``, ``moment``, ``frame``); the components numbers or expressions of t."""
    field = "force" if section == "forces" else "moment"
    keys = ("link", "point", field, "frame") if field == "force" else ("link", field, "frame")
    entry = Entry(f"{section}.{name}", table, keys, ("link", field))
    components = _target(entry, field, ("x", "y", "z"))
    frame = entry.string("frame") or "world"
    if field == "force":
        return LinkForce(name, entry.string("link"), components, _vector(entry, "point") or (0.0, 0.0, 0.0), frame)
    return LinkMoment(name, entry.string("link"), components, frame)


def _read_driver(drivers: _Drivers, name: str, table: object, base: Path) -> None:
    """A ``[drivers.NAME]`` entry: a joint driver (``kind = "joint"``, the default; read as in the
    model files by :func:`cmbs.model.files.read_driver`) or a pose driver (``kind = "pose"``)."""
    if not isinstance(table, dict):
        raise ModelError(f"expected a table of keys, got {table!r}", entry=f"drivers.{name}")
    kind = table.get("kind", "joint")
    if kind not in DRIVER_KINDS:
        raise ModelError(f"kind: unknown kind {kind!r}{did_you_mean(str(kind), DRIVER_KINDS)}; kinds: "
                         f"{', '.join(DRIVER_KINDS)}", entry=f"drivers.{name}")
    if kind == "pose":
        drivers.drivers.append(_pose_driver(name, Entry(f"drivers.{name}", table, _POSE_KEYS, ("link",))))
    else:
        read_driver(drivers, name, {key: value for key, value in table.items() if key != "kind"},  # type: ignore[arg-type]
                base)


def _initial_positions(document: dict, model: Model) -> Model:
    """``model`` with the joint values of ``[initial_positions]`` in its q0 (the assembly's guess)."""
    q0, _ = coordinate_values(document, "initial_positions", model, model.q0, noun="joint")
    return model.replace(q0=q0)


def _entry_of(constraint: str, joint_drivers: frozenset[str], pose_drivers: frozenset[str]) -> str:
    """The file entry of a constraint row: ``closures.NAME`` or ``drivers.NAME`` (a pose driver)
    for ``NAME.x`` etc., ``drivers.NAME`` for a joint driver's row."""
    if constraint in joint_drivers:
        return f"drivers.{constraint}"
    name = constraint.rpartition(".")[0]
    return f"drivers.{name}" if name in pose_drivers else f"closures.{name}"


#: the entries of the Python elements' errors (``KIND 'NAME'``) by the file's sections
_SECTION_OF = {"closure": "closures", "driver": "drivers", "spring": "springs", "point spring": "point_springs",
               "force": "forces", "moment": "moments"}


def _in_file(error: ModelError, source: str) -> ModelError:
    """A closure's, driver's, spring's or load's mistake (an error naming no file) as this file's:
    its entry ``KIND 'NAME'`` named ``SECTION.NAME``."""
    if error.source is not None:
        return error
    entry = error.entry or ""
    for kind, section in _SECTION_OF.items():
        if entry.startswith(f"{kind} '") and entry.endswith("'"):
            entry = f"{section}.{entry[len(kind) + 2:-1]}"
            break
    return ModelError(error.problem, source=source, entry=entry or None)


def _measured_at_start(springs: Sequence[JointSpring | PointSpring], model: Model,
                       source: str) -> list[JointSpring | PointSpring]:
    """``springs`` with each point spring that the file gives no ``rest_length`` given the points'
    distance at the assembled start ``model.q0`` (:func:`~cmbs.model.robot_loads.measured_rest_length`)."""
    point_springs = [spring for spring in springs if isinstance(spring, PointSpring)]
    lengths = dict(zip((spring.name for spring in point_springs), model.equations.point_spring_lengths(model.q0)))
    try:
        return [dataclasses.replace(spring, rest_length=measured_rest_length(spring.name, lengths[spring.name]))
                if isinstance(spring, PointSpring) and spring.rest_length is None else spring for spring in springs]
    except ModelError as error:
        raise _in_file(error, source) from None


def read_robot_file(document: dict, path: Path) -> Model:
    """The assembled robot model of the parsed robot file ``document`` read from ``path``
    (module docstring).  Errors are :class:`~cmbs.errors.ModelError` naming the file.  A point
    spring given no ``rest_length`` takes the points' distance at the assembled start: the model
    is built with a stand-in rest length, assembled, then built again with the measured ones."""
    from cmbs.model.urdf import load_urdf

    source = str(path)
    try:
        unknown = sorted(set(document) - set(SECTIONS))
        if unknown:
            raise ModelError(f"unknown section(s) {', '.join(map(repr, unknown))} for a robot file (allowed: "
                             f"{', '.join(SECTIONS)})")
        header = Entry("model", document.get("model", {}),
                       ("name", "description", "source", "urdf", "gravity", "mimic", "joint_damping", "joint_limits"),
                       ("urdf",))
        gravity = _vector(header, "gravity") or (0.0, 0.0, -9.81)
        switches = {key: header.get(key, False) for key in ("mimic", "joint_damping", "joint_limits")}
        for key, value in switches.items():
            if not isinstance(value, bool):
                raise ModelError(f"{key} must be true or false, got {value!r}", entry="model")
        closures = [_closure(name, table) for name, table in entries(document, "closures")]
        springs: list[JointSpring | PointSpring] = [_spring(name, table)
                                                    for name, table in entries(document, "springs")]
        springs += [_point_spring(name, table) for name, table in entries(document, "point_springs")]
        loads = [_load(section, name, table) for section in ("forces", "moments")
                 for name, table in entries(document, section)]
        drivers = _Drivers()
        for name, table in entries(document, "drivers"):
            try:
                _read_driver(drivers, name, table, path.parent)
            except ModelError as error:
                raise error.located(entry=f"drivers.{name}") from None
        urdf = Path(header.string("urdf"))
        urdf = urdf if urdf.is_absolute() else path.parent / urdf
        if not urdf.is_file():
            raise ModelError(f"urdf: no such file {str(urdf)!r}", entry="model")
    except ModelError as error:
        raise error.located(source=source) from None

    def robot(springs: Sequence[JointSpring | PointSpring]) -> Model:
        try:
            return load_urdf(urdf, gravity=gravity, closures=closures, drivers=drivers.drivers, springs=springs,
                             loads=loads, **switches)
        except ModelError as error:
            raise _in_file(error, source) from None

    # a stand-in rest length (1 m) for the point springs given none, measured once the start is known
    measured = any(isinstance(spring, PointSpring) and spring.rest_length is None for spring in springs)
    built = robot([dataclasses.replace(spring, rest_length=1.0)
                   if isinstance(spring, PointSpring) and spring.rest_length is None else spring for spring in springs])
    try:
        model = built.replace(name=header.string("name") or path.stem,
                              description=header.string("description") or built.description,
                              source=header.string("source") or built.source)
        model = _initial_positions(document, model)
        model, given_velocities = initial_velocities(document, model)
    except ModelError as error:
        raise error.located(source=source) from None
    joint_drivers = frozenset(d.name for d in drivers.drivers if isinstance(d, JointDriver))
    pose_drivers = frozenset(d.name for d in drivers.drivers if isinstance(d, PoseDriver))
    model = assembled(model, source, given_velocities,
                      lambda constraint: _entry_of(constraint, joint_drivers, pose_drivers))
    if not measured:
        return model
    return robot(_measured_at_start(springs, model, source)).replace(
        name=model.name, description=model.description, source=model.source, q0=model.q0, qd0=model.qd0)
