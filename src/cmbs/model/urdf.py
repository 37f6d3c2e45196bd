"""Robots from URDF files (https://wiki.ros.org/urdf/XML): ``cmbs.load("arm.urdf")``.

The file is parsed by yourdfpy (no meshes loaded) into the links and joints of a spatial tree
(:func:`cmbs.model.robot.build_robot`).  URDF's ``<origin xyz rpy>`` is the transform
``Trans(xyz) Rz(yaw) Ry(pitch) Rx(roll)`` (fixed axes x, y, z); yourdfpy returns it as a 4 x 4
matrix.  Floating and planar joints (six and three coordinates) are refused: a free-flying or
planar base is modelled in spatial natural coordinates (docs/spatial.md).  ``<mimic>`` is not
applied: a mimicking joint has a coordinate of its own.
"""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from pathlib import Path
from typing import Sequence

import numpy as np

from cmbs.errors import ModelError
from cmbs.model.model import Model
from cmbs.model.robot import Inertial, JointDriver, TreeJoint, TreeLink, build_robot
from cmbs.model.robot_closures import Closure

__all__ = ["load_urdf"]

_REFUSED = {"floating": "a free-flying base (6 coordinates)", "planar": "a planar base (3 coordinates)"}
#: the attributes URDF gives as numbers, by element tag
_NUMBERS = {"origin": ("xyz", "rpy"), "axis": ("xyz",), "mass": ("value",),
            "inertia": ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"),
            "limit": ("lower", "upper", "effort", "velocity"), "dynamics": ("damping", "friction")}


def load_urdf(path: str | Path, *, gravity: Sequence[float] = (0.0, 0.0, -9.81), closures: Sequence[Closure] = (),
              drivers: Sequence[JointDriver] = ()) -> Model:
    """The robot of the URDF file ``path`` (module docstring), gravity ``gravity`` (m/s², world
    axes), closed by ``closures`` and driven by ``drivers`` (:func:`~cmbs.model.robot.build_robot`;
    not assembled: a robot file does that, :mod:`cmbs.model.robot_files`).  Every problem of the
    URDF is a one-line :class:`~cmbs.errors.ModelError` naming the file and the element: a missing
    file, XML that is not well formed, a number that is not one, an unknown, floating or planar
    joint type, a movable joint that carries no inertial."""
    import yourdfpy

    source = str(path)
    if not Path(path).is_file():
        raise ModelError("no such file", source=source)
    _check_numbers(Path(path), source)
    try:
        robot = yourdfpy.URDF.load(source, build_scene_graph=False, load_meshes=False,
                                   build_collision_scene_graph=False, load_collision_meshes=False).robot
    except Exception as error:  # yourdfpy raises bare ValueError, KeyError, AttributeError on bad input
        raise ModelError(f"not a valid URDF robot: {type(error).__name__}: {' '.join(str(error).split())}",
                         source=source) from None
    links = [TreeLink(link.name, None if link.inertial is None else _inertial(link.inertial))
             for link in robot.links]
    joints = []
    for joint in robot.joints:
        if joint.type in _REFUSED:
            raise ModelError(f"{joint.type} joints are not supported by the joint-coordinate tree (fixed base); model "
                             f"{_REFUSED[joint.type]} in spatial natural coordinates instead (docs/spatial.md)",
                             source=source, entry=f"joint {joint.name!r}")
        limit, dynamics = joint.limit, joint.dynamics
        joints.append(TreeJoint(
            name=joint.name, type=joint.type, parent=joint.parent, child=joint.child,
            origin=np.eye(4) if joint.origin is None else np.asarray(joint.origin, dtype=float),
            axis=tuple(float(x) for x in (joint.axis if joint.axis is not None else (1.0, 0.0, 0.0))),
            lower=None if limit is None else _optional(limit.lower),
            upper=None if limit is None else _optional(limit.upper),
            effort=None if limit is None else _optional(limit.effort),
            velocity=None if limit is None else _optional(limit.velocity),
            damping=0.0 if dynamics is None or dynamics.damping is None else float(dynamics.damping),
            friction=0.0 if dynamics is None or dynamics.friction is None else float(dynamics.friction)))
    return build_robot(robot.name, links, joints, gravity=gravity, source=source,
                       description=f"robot {robot.name!r} from {Path(path).name}", closures=closures, drivers=drivers)


def _optional(value: object) -> float | None:
    return None if value is None else float(value)  # type: ignore[arg-type]


def _inertial(inertial: object) -> Inertial:
    origin = getattr(inertial, "origin", None)
    inertia = getattr(inertial, "inertia", None)
    mass = getattr(inertial, "mass", None)
    return Inertial(mass=0.0 if mass is None else float(mass),
                    origin=np.eye(4) if origin is None else np.asarray(origin, dtype=float),
                    inertia=np.zeros((3, 3)) if inertia is None else np.asarray(inertia, dtype=float))


def _check_numbers(path: Path, source: str) -> None:
    """ModelError naming the element unless the file is well-formed XML whose numeric attributes
    (:data:`_NUMBERS`) are numbers (the right count of them: 3 for xyz and rpy, else 1)."""
    try:
        root = ElementTree.parse(path).getroot()
    except ElementTree.ParseError as error:
        raise ModelError(f"not well-formed XML: {error}", source=source) from None
    for owner in root:
        if owner.tag not in ("link", "joint"):
            continue
        where = f"{owner.tag} {owner.get('name')!r}"
        for element in owner.iter():
            for attribute in _NUMBERS.get(element.tag, ()):
                text = element.get(attribute)
                if text is None:
                    continue
                count = 3 if attribute in ("xyz", "rpy") else 1
                try:
                    values = [float(item) for item in text.split()]
                except ValueError:
                    values = []
                if len(values) != count:
                    raise ModelError(f"<{element.tag} {attribute}={text!r}>: expected {count} number"
                                     f"{'s' if count > 1 else ''}", source=source, entry=where)
