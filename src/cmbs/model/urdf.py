"""Robots from URDF files (https://wiki.ros.org/urdf/XML): ``cmbs.load("arm.urdf")``.

The file is parsed by yourdfpy (no meshes loaded) into the links and joints of a spatial tree
(:func:`cmbs.model.robot.build_robot`) and the links' ``<visual>`` geometry, kept as data
(:mod:`cmbs.model.visuals`; mesh files are named, and read only when drawn:
:mod:`cmbs.surfaces`).  URDF's ``<origin xyz rpy>`` is the transform ``Trans(xyz) Rz(yaw)
Ry(pitch) Rx(roll)`` (fixed axes x, y, z); yourdfpy returns it as a 4 x 4 matrix.  Floating and
planar joints (six and three coordinates) are refused: a free-flying or planar base is modelled
in spatial natural coordinates (docs/spatial.md).  A ``<mimic joint multiplier offset>`` is kept
with its joint (``TreeJoint.mimic``); it is applied, as a constraint row ``JOINT.mimic``
(``q_joint = multiplier·q_mimicked + offset``), when ``mimic=True``; otherwise a mimicking joint
has a coordinate of its own (as in Pinocchio's default).  A joint's ``<dynamics damping>`` is kept
as data (``TreeJoint.damping``; Pinocchio's ``aba`` ignores it too) unless ``joint_damping=True``
applies it as the viscous damper ``τ = -damping·q̇``; its ``friction`` (Coulomb friction,
discontinuous) is kept as data only.
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
from cmbs.model.robot_loads import JointSpring, LinkForce, LinkMoment, PointSpring
from cmbs.model.robot_targets import PoseDriver
from cmbs.model.visuals import SHAPES, Visual

__all__ = ["load_urdf"]

_REFUSED = {"floating": "a free-flying base (6 coordinates)", "planar": "a planar base (3 coordinates)"}
#: the attributes URDF gives as numbers, by element tag, and the counts of numbers they may hold
_NUMBERS = {"origin": {"xyz": (3,), "rpy": (3,)}, "axis": {"xyz": (3,)}, "mass": {"value": (1,)},
            "inertia": dict.fromkeys(("ixx", "ixy", "ixz", "iyy", "iyz", "izz"), (1,)),
            "limit": dict.fromkeys(("lower", "upper", "effort", "velocity"), (1,)),
            "dynamics": {"damping": (1,), "friction": (1,)}, "box": {"size": (3,)},
            "cylinder": {"radius": (1,), "length": (1,)}, "sphere": {"radius": (1,)}, "mesh": {"scale": (1, 3)},
            "color": {"rgba": (4,)}, "mimic": {"multiplier": (1,), "offset": (1,)}}
#: the attributes whose numbers may also be separated by commas (as yourdfpy reads them)
_COMMAS = {"size", "scale"}


def load_urdf(path: str | Path, *, gravity: Sequence[float] = (0.0, 0.0, -9.81), closures: Sequence[Closure] = (),
              drivers: Sequence[JointDriver | PoseDriver] = (), mimic: bool = False,
              springs: Sequence[JointSpring | PointSpring] = (), loads: Sequence[LinkForce | LinkMoment] = (),
              joint_damping: bool = False, joint_limits: bool = False) -> Model:
    """The robot of the URDF file ``path`` (module docstring), gravity ``gravity`` (m/s², world
    axes), closed by ``closures``, driven by ``drivers``, its mimic joints coupled when ``mimic``,
    loaded by the ``springs`` (joint springs and spring-dampers between two points; a point
    spring's default rest length is its length at ``model.q0``), the forces and moments ``loads``
    and, when ``joint_damping``, its joints' ``<dynamics damping>`` as dampers
    (:mod:`cmbs.model.robot_loads`), its position analysis kept within the joints' ``<limit lower
    upper>`` when ``joint_limits`` (:func:`~cmbs.model.robot.build_robot`; not assembled: a robot
    file does that, :mod:`cmbs.model.robot_files`).  Every problem of the
    URDF is a one-line :class:`~cmbs.errors.ModelError` naming the file and the element: a missing
    file, XML that is not well formed, a number that is not one, an unknown, floating or planar
    joint type, a movable joint that carries no inertial."""
    import yourdfpy

    source = str(path)
    if not Path(path).is_file():
        raise ModelError("no such file", source=source)
    _check_elements(Path(path), source)
    try:
        robot = yourdfpy.URDF.load(source, build_scene_graph=False, load_meshes=False,
                                   build_collision_scene_graph=False, load_collision_meshes=False).robot
    except Exception as error:  # yourdfpy raises bare ValueError, KeyError, AttributeError on bad input
        raise ModelError(f"not a valid URDF robot: {type(error).__name__}: {' '.join(str(error).split())}",
                         source=source) from None
    colours = {material.name: material.color.rgba for material in robot.materials
               if material.name is not None and material.color is not None}
    links = [TreeLink(link.name, None if link.inertial is None else _inertial(link.inertial),
                      _visuals(link, colours, Path(path).parent))
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
            friction=0.0 if dynamics is None or dynamics.friction is None else float(dynamics.friction),
            mimic=None if joint.mimic is None else (
                str(joint.mimic.joint), 1.0 if joint.mimic.multiplier is None else float(joint.mimic.multiplier),
                0.0 if joint.mimic.offset is None else float(joint.mimic.offset))))
    return build_robot(robot.name, links, joints, gravity=gravity, source=source,
                       description=f"robot {robot.name!r} from {Path(path).name}", closures=closures, drivers=drivers,
                       mimic=mimic, springs=springs, loads=loads, joint_damping=joint_damping,
                       joint_limits=joint_limits)


def _optional(value: object) -> float | None:
    return None if value is None else float(value)  # type: ignore[arg-type]


def _inertial(inertial: object) -> Inertial:
    origin = getattr(inertial, "origin", None)
    inertia = getattr(inertial, "inertia", None)
    mass = getattr(inertial, "mass", None)
    return Inertial(mass=0.0 if mass is None else float(mass),
                    origin=np.eye(4) if origin is None else np.asarray(origin, dtype=float),
                    inertia=np.zeros((3, 3)) if inertia is None else np.asarray(inertia, dtype=float))


def _visuals(link: object, colours: dict[str, np.ndarray], folder: Path) -> tuple[Visual, ...]:
    """The link's ``<visual>`` elements (:mod:`cmbs.model.visuals`): a material's colour is its own
    ``<color>`` or that of the robot's ``<material>`` of its name (``colours``); a mesh's file is
    resolved by yourdfpy's ``filename_handler_magic`` from the URDF's ``folder`` (the name as
    written when no file is found: the viewer then says so)."""
    import yourdfpy

    visuals = []
    for visual in getattr(link, "visuals", ()):
        geometry = visual.geometry
        origin = np.eye(4) if visual.origin is None else np.asarray(visual.origin, dtype=float)
        material = visual.material
        rgba = None if material is None else material.color.rgba if material.color is not None \
            else colours.get(material.name)
        colour = None if rgba is None else tuple(float(x) for x in rgba)
        if geometry.box is not None:
            visuals.append(Visual("box", origin, tuple(float(x) for x in geometry.box.size), colour))
        elif geometry.cylinder is not None:
            visuals.append(Visual("cylinder", origin, (float(geometry.cylinder.radius),
                                                       float(geometry.cylinder.length)), colour))
        elif geometry.sphere is not None:
            visuals.append(Visual("sphere", origin, (float(geometry.sphere.radius),), colour))
        else:  # a mesh (_check_elements)
            scale = geometry.mesh.scale
            size = (1.0, 1.0, 1.0) if scale is None else tuple(float(x) for x in np.broadcast_to(scale, 3))
            filename = yourdfpy.filename_handler_magic(geometry.mesh.filename, dir=str(folder))
            visuals.append(Visual("mesh", origin, size, colour, str(filename)))
    return tuple(visuals)


def _check_elements(path: Path, source: str) -> None:
    """ModelError naming the element unless the file is well-formed XML whose numeric attributes
    (:data:`_NUMBERS`) are numbers, as many as the attribute holds (3 for xyz, rpy and a box's
    size, 4 for a colour's rgba, 1 or 3 for a mesh's scale, else 1), and whose visuals each have
    a geometry of one shape (a mesh with a filename)."""
    try:
        root = ElementTree.parse(path).getroot()
    except ElementTree.ParseError as error:
        raise ModelError(f"not well-formed XML: {error}", source=source) from None
    for owner in root:
        if owner.tag not in ("link", "joint", "material"):
            continue
        where = f"{owner.tag} {owner.get('name')!r}"
        for k, visual in enumerate(owner.findall("visual")):
            shapes = [shape for shape in visual.findall("geometry/*") if shape.tag in SHAPES]
            if len(visual.findall("geometry/*")) != 1 or len(shapes) != 1:
                raise ModelError(f"<visual> {k + 1}: its <geometry> must hold one of {', '.join(SHAPES)}",
                                 source=source, entry=where)
            if shapes[0].tag == "mesh" and not shapes[0].get("filename"):
                raise ModelError(f"<visual> {k + 1}: <mesh> without a filename", source=source, entry=where)
        for element in owner.iter():
            for attribute, counts in _NUMBERS.get(element.tag, {}).items():
                text = element.get(attribute)
                if text is None:
                    continue
                items = (text.replace(",", " ") if attribute in _COMMAS else text).split()
                try:
                    values = [float(item) for item in items]
                except ValueError:
                    values = []
                if len(values) not in counts:
                    wanted = " or ".join(str(count) for count in counts)
                    raise ModelError(f"<{element.tag} {attribute}={text!r}>: expected {wanted} number"
                                     f"{'s' if counts[-1] > 1 else ''}", source=source, entry=where)
