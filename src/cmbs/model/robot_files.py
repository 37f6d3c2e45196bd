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
``[forces.NAME]`` and ``[moments.NAME]`` (a force at a link point, a moment on a link:
:class:`~cmbs.model.robot_loads.LinkForce`, :class:`~cmbs.model.robot_loads.LinkMoment`),
``[initial_positions]`` (joint = value: the guess assembly starts from, default ``model.q0``) and
``[initial_velocities]``.  The file is data, checked key by key before any work (unknown keys,
wrong types, vectors of the wrong length, unknown links, joints and kinds are one-line errors
naming the file, the entry and the field), then the model is assembled
(:func:`cmbs.model.files.assembled`).
"""

from __future__ import annotations

import math
from pathlib import Path

from cmbs.errors import ModelError, did_you_mean
from cmbs.model.drivers import TimeFunction, as_time_function, checked_at_start
from cmbs.model.files import Entry, assembled, coordinate_values, entries, initial_velocities, read_driver
from cmbs.model.model import Model
from cmbs.model.robot import JointDriver
from cmbs.model.robot_closures import CLOSURE_KINDS, Closure
from cmbs.model.robot_loads import JointSpring, LinkForce, LinkMoment
from cmbs.model.robot_targets import PoseDriver

__all__ = ["SECTIONS", "read_robot_file"]

SECTIONS = ("model", "closures", "drivers", "springs", "forces", "moments", "initial_positions", "initial_velocities")
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
        header = Entry("model", document.get("model", {}),
                       ("name", "description", "source", "urdf", "gravity", "mimic", "joint_damping", "joint_limits"),
                       ("urdf",))
        gravity = _vector(header, "gravity") or (0.0, 0.0, -9.81)
        switches = {key: header.get(key, False) for key in ("mimic", "joint_damping", "joint_limits")}
        for key, value in switches.items():
            if not isinstance(value, bool):
                raise ModelError(f"{key} must be true or false, got {value!r}", entry="model")
        closures = [_closure(name, table) for name, table in entries(document, "closures")]
        springs = [_spring(name, table) for name, table in entries(document, "springs")]
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
    try:
        robot = load_urdf(urdf, gravity=gravity, closures=closures, drivers=drivers.drivers, springs=springs,
                          loads=loads, **switches)
    except ModelError as error:
        if error.source is None:      # a closure's, driver's, spring's or load's mistake: name this file's entry
            entry = error.entry or ""
            kind, _, name = entry.partition(" ")
            where = {"closure": "closures", "driver": "drivers", "spring": "springs", "force": "forces",
                     "moment": "moments"}.get(kind)
            raise ModelError(error.problem, source=source,
                             entry=f"{where}.{name.strip(chr(39))}" if where else entry or None) from None
        raise
    try:
        model = robot.replace(name=header.string("name") or path.stem,
                              description=header.string("description") or robot.description,
                              source=header.string("source") or robot.source)
        model = _initial_positions(document, model)
        model, given_velocities = initial_velocities(document, model)
    except ModelError as error:
        raise error.located(source=source) from None
    joint_drivers = frozenset(d.name for d in drivers.drivers if isinstance(d, JointDriver))
    pose_drivers = frozenset(d.name for d in drivers.drivers if isinstance(d, PoseDriver))
    return assembled(model, source, given_velocities,
                     lambda constraint: _entry_of(constraint, joint_drivers, pose_drivers))
