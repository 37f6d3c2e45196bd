"""Spatial joint-coordinate trees (robots): links joined by revolute, prismatic and fixed joints.

A tree is a root link fixed to the ground and links each hanging from one parent link by one
joint with a fixed placement (the joint frame in the parent link's frame) and an axis in the
joint frame (URDF's kinematics, https://wiki.ros.org/urdf/XML/joint):

- revolute (or continuous: revolute without limits): the child frame is the joint frame turned
  by ``q`` about the axis;
- prismatic: the joint frame moved by ``q`` along the axis;
- fixed: the joint frame itself, no coordinate.

Coordinates: one per revolute, continuous or prismatic joint, named by the joint, in the order
the joints are given.  Constraints: the rows of the loop closures (:mod:`cmbs.model.robot_closures`),
then those of the pose drivers (a link frame's target pose, :mod:`cmbs.model.robot_targets`), then
one per joint driver, ``q_c - f(t) = 0`` on joint c (:class:`JointDriver`).  Actuators: the joints
themselves, ``u_k`` the torque (revolute) or force (prismatic) of joint k on its child, so
``Q = u - C(q, q̇) q̇ - g(q) + Q_loads`` with the applied loads of :mod:`cmbs.model.robot_loads`
(joint springs and dampers ``-k (q - q_rest) - c q̇``, spring-dampers between two points
``J_aᵀ(-f u) + J_bᵀ(f u)`` with the tension ``f = k (ℓ - ℓ0) + c ℓ̇``, point forces ``J_pᵀ F``
and moments ``J_ωᵀ M`` on links).

For the dynamics each movable joint carries one rigid body: its child link and every link
fixed to it by fixed joints, their inertias combined exactly (masses added, centres of mass
averaged, inertias moved to the common centre of mass by the parallel-axis theorem
``I_G = Σ_i R_i J_i R_iᵀ + m_i (|d_i|² 1 - d_i d_iᵀ)``, d_i = c_i - c).  Links fixed to the root
are part of the ground.  Every link keeps its own frame for the kinematics
(:func:`frame_placement`, :func:`frame_jacobian`).  M(q) and Q are computed by the compiled
composite-rigid-body and recursive Newton-Euler algorithms of :mod:`cmbs.model.robot_kernel`.
Joint limits, effort and velocity limits and friction are kept as data
(:attr:`RobotEquations.joints`), not enforced, and so is the URDF damping unless
``joint_damping`` applies it as a damper; so is the links' visual geometry
(``model.parameters["visuals"]``: per link name, its :class:`~cmbs.model.visuals.Visual` list).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from cmbs.errors import ModelError, did_you_mean
from cmbs.model.drivers import TimeFunction, TimeFunctionPack, as_time_function, is_constant
from cmbs.model.model import Model, Terms
from cmbs.model.robot_closures import Closure, closure_elements, coupling_elements, rpy_rotation
from cmbs.model.robot_loads import JointSpring, LinkForce, LinkMoment, PointSpring, load_elements, \
    measured_rest_length, point_spring_lengths
from cmbs.model.robot_targets import PoseDriver, target_elements
from cmbs.model.robot_kernel import INERTIA, PLACEMENT, PRISMATIC, REVOLUTE, TARGET_DOT, TARGET_POINT, RobotKernel, \
    body_poses, energies, evaluate_terms, scratch_size
from cmbs.model.visuals import Visual, checked_visual

__all__ = ["Inertial", "TreeLink", "TreeJoint", "JointDriver", "PoseDriver", "JointSpring", "PointSpring", "LinkForce",
           "LinkMoment", "RobotEquations", "build_robot", "frame_placement", "frame_jacobian", "initial_value"]

MOVABLE = {"revolute": REVOLUTE, "continuous": REVOLUTE, "prismatic": PRISMATIC}
JOINT_TYPES = (*MOVABLE, "fixed")


@dataclass(frozen=True, eq=False)
class Inertial:
    """Mass, centre-of-mass frame (4 x 4, in the link frame) and inertia (3 x 3, about the centre
    of mass, in that frame's axes) of a link."""

    mass: float
    origin: np.ndarray
    inertia: np.ndarray


@dataclass(frozen=True, eq=False)
class TreeLink:
    """A link: its name, inertial (None: massless) and visual geometry (in the link frame, data
    for the viewer: :mod:`cmbs.model.visuals`)."""

    name: str
    inertial: Inertial | None = None
    visuals: tuple[Visual, ...] = ()


@dataclass(frozen=True, eq=False)
class TreeJoint:
    """A joint: type (:data:`JOINT_TYPES`), parent and child link, placement ``origin`` (4 x 4,
    the joint frame in the parent link frame), axis (joint frame), and the data kept unenforced:
    position limits ``lower``/``upper``, ``effort`` and ``velocity`` limits (None: not given),
    ``damping`` (the viscous damper ``-damping·q̇`` when ``build_robot(..., joint_damping=True)``)
    and ``friction``; ``mimic``: URDF's ``<mimic>`` as (joint, multiplier, offset),
    the joint's value ``multiplier·q_joint + offset`` when mimic joints are coupled
    (``build_robot(..., mimic=True)``), else None."""

    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    lower: float | None = None
    upper: float | None = None
    effort: float | None = None
    velocity: float | None = None
    damping: float = 0.0
    friction: float = 0.0
    mimic: tuple[str, float, float] | None = None


@dataclass(frozen=True)
class JointDriver:
    """A driver: the constraint ``name``, ``q_joint - f(t) = 0`` (Φ_t = -f', γ = f''), ``function``
    anything :func:`cmbs.model.drivers.as_time_function` takes (number, expression, table,
    callable)."""

    name: str
    joint: str
    function: object


class RobotEquations:
    """Evaluator of a spatial tree (the :class:`~cmbs.model.model.ModelEquations` protocol).

    ``kernel`` is the compiled data (:class:`~cmbs.model.robot_kernel.RobotKernel`); link ``i``
    of ``link_names`` is fixed to body ``link_body[i]`` (-1: the ground) with the placement
    ``link_offset[i]`` (4 x 4) in that body's frame (in the world for the ground).
    """

    def __init__(self, kernel: RobotKernel, link_names: tuple[str, ...], link_body: np.ndarray,
                 link_offset: np.ndarray, joints: tuple[TreeJoint, ...],
                 time_functions: TimeFunctionPack | None = None, steady_drivers: frozenset[str] = frozenset(),
                 orientation_targets: tuple[tuple[str, int, int], ...] = (), work_sources: tuple[str, ...] = ()):
        self.kernel = kernel
        #: what does work besides gravity, the springs, the joint torques and the drivers: the
        #: dampers and the point forces and moments (:mod:`cmbs.model.robot_loads`; the closures are
        #: workless, friction is not applied)
        self.work_sources = work_sources
        self.n = int(kernel.parent.shape[0])
        self.m = int(kernel.sizes[0])
        self.link_names = link_names
        self.link_body = link_body
        self.link_offset = link_offset
        #: the movable joints, in coordinate order, with their limits, damping and friction
        self.joints = joints
        #: the drivers' and loads' functions of time; the (index, function) pairs evaluated in Python
        self.time_functions = time_functions or TimeFunctionPack.build(())
        self.python: tuple[tuple[int, TimeFunction], ...] = self.time_functions.python
        #: the drivers of a constant, which hold their joint and do no work
        self.steady_drivers = steady_drivers
        #: the pose drivers' orientations: (name of their first row, link index, first of the three
        #: time functions roll, pitch, yaw in :attr:`time_functions`)
        self.orientation_targets = orientation_targets
        moving = [i for i, body in enumerate(link_body) if body >= 0]
        #: the links that move (every link but the root and those fixed to it), in the order of
        #: :attr:`link_names`: the bodies of :meth:`body_poses` and of the result files' pose columns
        self.bodies: tuple[str, ...] = tuple(link_names[i] for i in moving)
        self._moving = np.array(moving, np.int64)

    @property
    def gravity(self) -> tuple[float, float, float]:
        """The acceleration of gravity (m/s², world axes)."""
        return tuple(float(value) for value in self.kernel.gravity)

    @property
    def pose_driven(self) -> bool:
        """True when a pose driver (:mod:`cmbs.model.robot_targets`) prescribes a link frame's pose."""
        return bool(np.any(np.isin(self.kernel.closure_ints[:, 0], (TARGET_POINT, TARGET_DOT))))

    @property
    def body_names(self) -> tuple[str, ...]:
        """The names of :attr:`bodies` (they are link names)."""
        return self.bodies

    def new_terms(self) -> Terms:
        """A workspace sized for this model (its scratch holds the time functions and the per-body work)."""
        return Terms(self.n, self.m, scratch=scratch_size(self.kernel))

    def compiled_kernel(self) -> RobotKernel | None:
        """The model's data for the compiled loops, or None when a driver is a Python callable."""
        return None if self.python else self.kernel

    def evaluate(self, q: np.ndarray, qd: np.ndarray, t: float, u: np.ndarray, terms: Terms) -> None:
        """M(q) (CRBA), Q = u - C(q, q̇) q̇ - g(q) + Q_loads (RNEA with q̈ = 0 and the loads and
        point springs as external forces, then the joint springs) and the closure and driver rows
        into ``terms``."""
        for k, function in self.python:
            terms.scratch[3 * k:3 * k + 3] = function(t)
        evaluate_terms(self.kernel, q, qd, t, u, terms.buffer)

    def kinetic_energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        """T = ½ q̇ᵀ M(q) q̇, summed body by body (½ vᵀ I v)."""
        return energies(self.kernel, q, qd)[0]

    def potential_energy(self, q: np.ndarray) -> float:
        """V = -Σ_k m_k g·c_k over the bodies (c_k the centre of mass) + Σ_joint springs ½ k (q - q_rest)²
        + Σ_point springs ½ k (ℓ - ℓ0)²."""
        return energies(self.kernel, q, np.zeros(self.n))[1]

    def point_spring_lengths(self, q: np.ndarray) -> np.ndarray:
        """ℓ = |p_a - p_b| at ``q`` of each point spring (:class:`PointSpring`), in the order given."""
        R, o, _ = body_poses(self.kernel, q)
        return point_spring_lengths(self.kernel.point_springs, self.kernel.point_spring_reals, R, o)

    def link_index(self, link: str) -> int:
        """Index of ``link`` in :attr:`link_names` (ModelError naming the choices otherwise)."""
        try:
            return self.link_names.index(link)
        except ValueError:
            raise ModelError(f"no link {link!r}{did_you_mean(link, self.link_names)}; links: "
                             f"{', '.join(self.link_names)}") from None

    def link_placements(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World rotations (L, 3, 3) and origins (L, 3) of every link frame at ``q``."""
        R, o, _ = body_poses(self.kernel, q)
        rotations = np.empty((len(self.link_names), 3, 3))
        origins = np.empty((len(self.link_names), 3))
        for i, (body, offset) in enumerate(zip(self.link_body, self.link_offset)):
            if body < 0:
                rotations[i], origins[i] = offset[:3, :3], offset[:3, 3]
            else:
                rotations[i] = R[body] @ offset[:3, :3]
                origins[i] = o[body] + R[body] @ offset[:3, 3]
        return rotations, origins

    def body_poses(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Origins (..., bodies, 3) and rotations (..., bodies, 3, 3) of the moving links'
        frames (:attr:`bodies`) at coordinates ``q`` (..., n): for link i fixed to body k with
        the placement (R_i⁰, p_i⁰) in its frame, ``R = R_k R_i⁰`` and ``o = o_k + R_k p_i⁰``
        (:meth:`link_placements`).  A link as built is its frame at the world origin aligned with
        the world axes, so R is the frame's world rotation and a point p given in link
        coordinates is at o + R p.  Rows of q that are not finite give NaN."""
        q = np.asarray(q, dtype=float)
        rows = q.reshape(-1, self.n)
        count = self._moving.size
        origins = np.full((rows.shape[0], count, 3), np.nan)
        rotations = np.full((rows.shape[0], count, 3, 3), np.nan)
        for r, row in enumerate(rows):
            if np.all(np.isfinite(row)):
                R, o = self.link_placements(row)
                rotations[r], origins[r] = R[self._moving], o[self._moving]
        shape = q.shape[:-1]
        return origins.reshape(*shape, count, 3), rotations.reshape(*shape, count, 3, 3)

    def turned_targets(self, q: np.ndarray, t: float) -> list[tuple[str, float]]:
        """The pose drivers whose link frame at (q, t) is turned by more than 90° from its target
        orientation F_t = Rot(rpy(t)) (a spurious root of the orientation rows,
        :mod:`cmbs.model.robot_targets`), as (first orientation row, angle in rad): the angle of
        R_tᵀ R from ``cos θ = (tr(R_tᵀ R) - 1) / 2``."""
        if not self.orientation_targets:
            return []
        rotations, _ = self.link_placements(np.asarray(q, dtype=float))
        functions = self.time_functions.functions
        turned = []
        for row, link, first in self.orientation_targets:
            target = rpy_rotation([functions[first + k](t)[0] for k in range(3)])
            cosine = (np.trace(target.T @ rotations[link]) - 1.0) / 2.0
            if cosine < 0.0:
                turned.append((row, float(np.arccos(max(cosine, -1.0)))))
        return turned

    def point_positions(self, q: np.ndarray) -> np.ndarray:
        """(L, 3): the origins of the link frames, in the order of :attr:`link_names`."""
        return self.link_placements(q)[1]

    def frame_jacobian(self, q: np.ndarray, link: str) -> np.ndarray:
        """J (6, n) with ``(ṗ, ω) = J q̇``: rows 0-2 the velocity of the link frame's origin p,
        rows 3-5 the link's angular velocity, both in world axes (Pinocchio's
        LOCAL_WORLD_ALIGNED).  Column j, for joint j between the link and the ground:
        ``(z_j × (p - o_j), z_j)`` (revolute), ``(z_j, 0)`` (prismatic); 0 for the others."""
        index = self.link_index(link)
        R, o, S = body_poses(self.kernel, q)
        body = int(self.link_body[index])
        J = np.zeros((6, self.n))
        if body < 0:
            return J
        p = o[body] + R[body] @ self.link_offset[index][:3, 3]
        parent = self.kernel.parent
        j = body
        while j >= 0:
            # S_j = (ω, v_O) about the world origin; the velocity of point p is v_O + ω × p
            J[0:3, j] = S[j, 3:6] + np.cross(S[j, 0:3], p)
            J[3:6, j] = S[j, 0:3]
            j = int(parent[j])
        return J


def frame_placement(model: Model, q: np.ndarray, link: str) -> tuple[np.ndarray, np.ndarray]:
    """World rotation (3, 3) and origin (3,) of ``link``'s frame of a robot ``model`` at ``q``."""
    equations = _robot_equations(model)
    rotations, origins = equations.link_placements(np.asarray(q, dtype=float))
    index = equations.link_index(link)
    return rotations[index], origins[index]


def frame_jacobian(model: Model, q: np.ndarray, link: str) -> np.ndarray:
    """The 6 x n Jacobian of ``link``'s frame (:meth:`RobotEquations.frame_jacobian`: linear
    velocity of its origin, then angular velocity, both in world axes)."""
    return _robot_equations(model).frame_jacobian(np.asarray(q, dtype=float), link)


def _robot_equations(model: Model) -> RobotEquations:
    if not isinstance(model.equations, RobotEquations):
        raise ModelError(f"model {model.name!r} is not a robot (spatial joint-coordinate tree)")
    return model.equations


def initial_value(joint: TreeJoint) -> float:
    """The joint's coordinate in ``model.q0``: the value nearest 0 within its limits,
    ``min(max(0, lower), upper)`` (a missing limit bounds nothing; a continuous joint has none:
    URDF ignores its ``lower`` and ``upper``)."""
    if joint.type == "continuous":
        return 0.0
    value = 0.0 if joint.lower is None else max(0.0, joint.lower)
    return value if joint.upper is None else min(value, joint.upper)


def _finite(values: Sequence[float], entry: str, label: str, source: str | None) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(array)):
        raise ModelError(f"{label} must be finite numbers, got {array.tolist()}", source=source, entry=entry)
    return array


def _combined_inertia(parts: list[tuple[float, np.ndarray, np.ndarray]]) -> np.ndarray:
    """(m, c, I_G) of rigidly joined parts (mass, centre of mass, inertia about it, one frame's
    axes) as the ten numbers of :data:`~cmbs.model.robot_kernel.INERTIA` (module docstring)."""
    mass = sum(m for m, _, _ in parts)
    centre = sum((m * c for m, c, _ in parts), np.zeros(3)) / mass if mass > 0 else np.zeros(3)
    inertia = np.zeros((3, 3))
    for m, c, I in parts:
        d = c - centre
        inertia += I + m * (d @ d * np.eye(3) - np.outer(d, d))
    return np.array([mass, *centre, inertia[0, 0], inertia[0, 1], inertia[0, 2], inertia[1, 1], inertia[1, 2],
                     inertia[2, 2]])


def _measured_rest_lengths(springs: Sequence[JointSpring | PointSpring], kernel: RobotKernel,
                           q0: np.ndarray) -> list[JointSpring | PointSpring]:
    """``springs`` with the rest length of each point spring that has none set to its length at
    ``q0``, written into the kernel's (still writable) ``point_spring_reals`` too
    (:func:`measured_rest_length`)."""
    point_springs = [spring for spring in springs if isinstance(spring, PointSpring)]
    if all(spring.rest_length is not None for spring in point_springs):
        return list(springs)
    R, o, _ = body_poses(kernel, q0)
    lengths = point_spring_lengths(kernel.point_springs, kernel.point_spring_reals, R, o)
    measured: dict[str, PointSpring] = {}
    for row, spring in enumerate(point_springs):
        if spring.rest_length is None:
            kernel.point_spring_reals[row, 8] = measured_rest_length(spring.name, lengths[row])
            measured[spring.name] = dataclasses.replace(spring, rest_length=float(kernel.point_spring_reals[row, 8]))
    return [measured.get(spring.name, spring) if isinstance(spring, PointSpring) else spring for spring in springs]


def build_robot(name: str, links: Sequence[TreeLink], joints: Sequence[TreeJoint], *,
                gravity: Sequence[float] = (0.0, 0.0, -9.81), source: str | None = None,
                description: str = "", closures: Sequence[Closure] = (),
                drivers: Sequence[JointDriver | PoseDriver] = (), mimic: bool = False,
                springs: Sequence[JointSpring | PointSpring] = (), loads: Sequence[LinkForce | LinkMoment] = (),
                joint_damping: bool = False, joint_limits: bool = False) -> Model:
    """The :class:`~cmbs.model.model.Model` of the tree of ``links`` and ``joints`` closed by
    ``closures`` and driven by ``drivers`` (joint and pose drivers; module docstring), with a
    row ``JOINT.mimic`` coupling each joint that has a ``mimic`` to the joint it mimics when
    ``mimic`` is True (:func:`~cmbs.model.robot_closures.coupling_elements`), loaded by the
    ``springs``: joint springs (:class:`JointSpring`, ``τ = -k (q - q_rest) - c q̇``) and
    spring-dampers between two points (:class:`PointSpring`, ``Q += J_aᵀ(-f u) + J_bᵀ(f u)``,
    ``f = k (ℓ - ℓ0) + c ℓ̇``; ℓ0 not given: the points' distance at ``model.q0``), by each movable
    joint's ``damping`` as the damper
    ``τ = -damping·q̇`` when ``joint_damping`` is True, and by the point forces and moments on links
    ``loads`` (``Q += J_pᵀ F``, ``Q += J_ωᵀ M``; :mod:`cmbs.model.robot_loads`), its position
    analysis kept within the joints' ``lower``/``upper`` limits when ``joint_limits`` is True
    (``Model.coordinate_limits``: inverse kinematics and loop closures within the limits,
    :func:`cmbs.kinematics.assemble`; the dynamics does not enforce them); ``source`` names the
    file it came from in errors and on the model.  ``model.q0`` is each coordinate's
    value nearest 0 within its joint's limits (:func:`initial_value`; not assembled:
    :func:`cmbs.kinematics.assemble`).

    Raises
    ------
    ModelError
        Naming the joint, link, closure or driver: an unknown type, an unknown or repeated link, a
        link with two parents, a tree without exactly one root, a zero axis, non-finite numbers, a
        negative mass, a visual that is no shape (:func:`~cmbs.model.visuals.checked_visual`),
        limits with lower > upper, a movable joint that carries no mass nor inertia, a closure's
        mistakes (:func:`~cmbs.model.robot_closures.closure_elements`), a pose driver's
        (:func:`~cmbs.model.robot_targets.target_elements`), a driver of an unknown or fixed
        joint, two drivers of one joint, repeated constraint names, a spring's or load's
        mistakes (:func:`~cmbs.model.robot_loads.load_elements`), or a point spring given no rest
        length whose points coincide at ``model.q0``.
    """
    g = _finite(gravity, f"model {name!r}", "gravity", source)
    if g.shape != (3,):
        raise ModelError(f"gravity must be 3 numbers, got {list(gravity)}", source=source, entry=f"model {name!r}")
    by_name: dict[str, TreeLink] = {}
    for link in links:
        if link.name in by_name:
            raise ModelError("duplicate link name", source=source, entry=f"link {link.name!r}")
        by_name[link.name] = link
        if link.inertial is not None:
            entry = f"link {link.name!r} inertial"
            if not math.isfinite(link.inertial.mass) or link.inertial.mass < 0:
                raise ModelError(f"mass must be a finite number >= 0, got {link.inertial.mass!r}", source=source,
                                 entry=entry)
            _finite(link.inertial.origin, entry, "origin", source)
            _finite(link.inertial.inertia, entry, "inertia", source)
        for k, visual in enumerate(link.visuals):
            checked_visual(visual, source=source, entry=f"link {link.name!r} visual {k + 1}")
    children: dict[str, list[TreeJoint]] = {link: [] for link in by_name}
    parent_joint: dict[str, TreeJoint] = {}
    for joint in joints:
        entry = f"joint {joint.name!r}"
        if joint.type not in JOINT_TYPES:
            raise ModelError(f"unknown joint type {joint.type!r}; types: {', '.join(JOINT_TYPES)}", source=source,
                             entry=entry)
        for role, link in (("parent", joint.parent), ("child", joint.child)):
            if link not in by_name:
                raise ModelError(f"unknown {role} link {link!r}{did_you_mean(link, by_name)}", source=source,
                                 entry=entry)
        if joint.child in parent_joint:
            raise ModelError(f"link {joint.child!r} is already the child of joint {parent_joint[joint.child].name!r}",
                             source=source, entry=entry)
        _finite(joint.origin, entry, "origin", source)
        if joint.type in MOVABLE and not np.linalg.norm(_finite(joint.axis, entry, "axis", source)) > 0:
            raise ModelError(f"axis must be nonzero, got {list(joint.axis)}", source=source, entry=entry)
        if joint.lower is not None and joint.upper is not None and joint.lower > joint.upper:
            raise ModelError(f"limit lower {joint.lower:g} > upper {joint.upper:g}", source=source, entry=entry)
        parent_joint[joint.child] = joint
        children[joint.parent].append(joint)
    roots = [link for link in by_name if link not in parent_joint]
    if len(roots) != 1:
        raise ModelError(f"a tree has one root link (no parent joint), found {len(roots)}: {', '.join(roots)}",
                         source=source, entry=f"model {name!r}")
    movable = [joint for joint in joints if joint.type in MOVABLE]
    coordinate = {joint.name: k for k, joint in enumerate(movable)}
    n = len(movable)
    # walk the tree from the root: each link's body (-1: the ground) and placement in the body frame
    link_body: dict[str, int] = {roots[0]: -1}
    link_offset: dict[str, np.ndarray] = {roots[0]: np.eye(4)}
    parent, order = np.full(n, -1, np.int64), []
    kind, placement, axis = np.zeros(n, np.int64), np.zeros((n, PLACEMENT)), np.zeros((n, 3))
    queue = [roots[0]]
    while queue:
        link = queue.pop(0)
        for joint in children[link]:
            placed = link_offset[link] @ np.asarray(joint.origin, dtype=float)
            if joint.type == "fixed":
                link_body[joint.child], link_offset[joint.child] = link_body[link], placed
            else:
                k = coordinate[joint.name]
                parent[k], kind[k] = link_body[link], MOVABLE[joint.type]
                placement[k] = np.concatenate([placed[:3, :3].ravel(), placed[:3, 3]])
                axis[k] = np.asarray(joint.axis, dtype=float) / np.linalg.norm(joint.axis)
                order.append(k)
                link_body[joint.child], link_offset[joint.child] = k, np.eye(4)
            queue.append(joint.child)
    if len(link_body) != len(by_name):
        unreached = [link for link in by_name if link not in link_body]
        raise ModelError(f"links not connected to the root {roots[0]!r} (a closed chain of joints): "
                         f"{', '.join(unreached)}", source=source, entry=f"model {name!r}")
    parts: list[list[tuple[float, np.ndarray, np.ndarray]]] = [[] for _ in range(n)]
    for link in by_name.values():
        body = link_body[link.name]
        if body >= 0 and link.inertial is not None:
            frame = link_offset[link.name] @ np.asarray(link.inertial.origin, dtype=float)
            rotation = frame[:3, :3]
            parts[body].append((link.inertial.mass, frame[:3, 3],
                                rotation @ np.asarray(link.inertial.inertia, dtype=float) @ rotation.T))
    inertia = np.array([_combined_inertia(p) for p in parts]).reshape(n, INERTIA)
    carried = inertia[:, 0] + np.abs(inertia[:, 4:]).sum(axis=1)
    for k in reversed(order):
        if parent[k] >= 0:
            carried[parent[k]] += carried[k]
    for k, joint in enumerate(movable):
        if not carried[k] > 0:
            raise ModelError(f"link {joint.child!r} and the links it carries have no <inertial> (no mass, no inertia): "
                             "the joint would move nothing; give the link an inertial or make the joint fixed",
                             source=source, entry=f"joint {joint.name!r}")
    link_names = tuple(by_name)
    bodies = np.array([link_body[l] for l in link_names], np.int64)
    offsets = np.array([link_offset[l] for l in link_names])
    closure_ints, closure_reals, constraint_names = closure_elements(closures, link_names, bodies, offsets)
    if mimic:
        coupling_ints, coupling_reals, coupling_names = coupling_elements(movable, source=source)
        closure_ints = np.concatenate([closure_ints, coupling_ints])
        closure_reals = np.concatenate([closure_reals, coupling_reals])
        constraint_names += coupling_names
    for driver in drivers:
        if not isinstance(driver, (JointDriver, PoseDriver)):
            raise ModelError(f"a driver is a JointDriver or a PoseDriver, got {driver!r}", entry=f"model {name!r}")
    joint_drivers = [driver for driver in drivers if isinstance(driver, JointDriver)]
    pose_drivers = [driver for driver in drivers if isinstance(driver, PoseDriver)]
    targets = target_elements(pose_drivers, link_names, bodies, offsets)
    functions, labels = list(targets.functions), list(targets.labels)
    driver_rows: list[tuple[int, int]] = []
    for driver in joint_drivers:
        entry = f"driver {driver.name!r}"
        if driver.joint not in coordinate:
            fixed = " (a fixed joint has no coordinate)" if any(j.name == driver.joint for j in joints) else ""
            raise ModelError(f"unknown joint {driver.joint!r}{fixed}{did_you_mean(driver.joint, coordinate)}; "
                             f"movable joints: {', '.join(coordinate)}", entry=entry)
        if any(row[0] == coordinate[driver.joint] for row in driver_rows):
            raise ModelError(f"joint {driver.joint!r} is driven twice", entry=entry)
        try:
            functions.append(as_time_function(driver.function))
        except ModelError as error:
            raise ModelError(error.problem, entry=entry) from None
        labels.append(f"driver {driver.name}")
        driver_rows.append((coordinate[driver.joint], len(functions) - 1))
    loaded = load_elements(springs, loads, joints, coordinate, link_names, bodies, offsets,
                           joint_damping=joint_damping, first_function=len(functions), source=source)
    functions += loaded.functions
    labels += loaded.labels
    closure_rows = len(constraint_names)
    constraint_names += targets.names + tuple(driver.name for driver in joint_drivers)
    repeated = sorted({c for c in constraint_names if constraint_names.count(c) > 1})
    if repeated:
        raise ModelError(f"repeated constraint names (closure rows and drivers share one namespace): "
                         f"{', '.join(repeated)}", entry=f"model {name!r}")
    pack = TimeFunctionPack.build(functions, labels)
    kernel = RobotKernel(parent, np.array(order, np.int64), kind, placement, axis, np.ascontiguousarray(inertia),
                         g.copy(), np.concatenate([closure_ints, targets.ints]),
                         np.concatenate([closure_reals, targets.reals]), np.array(driver_rows, np.int64).reshape(-1, 2),
                         pack.table, pack.ops, pack.reals,
                         np.array([len(constraint_names), pack.depth], np.int64), loaded.springs,
                         loaded.spring_reals, loaded.load_ints, loaded.load_reals, loaded.point_springs,
                         loaded.point_spring_reals, np.zeros((0, 0)))
    q0 = np.array([initial_value(joint) for joint in movable], dtype=float).reshape(n)
    springs = _measured_rest_lengths(springs, kernel, q0)
    for array in kernel:
        array.setflags(write=False)
    steady = targets.steady + tuple(driver.name for driver, (_, f) in zip(joint_drivers, driver_rows)
                                    if is_constant(functions[f]))
    equations = RobotEquations(kernel, link_names, bodies, offsets, tuple(movable), pack, frozenset(steady),
                               targets.orientations, loaded.work_sources)
    names = tuple(joint.name for joint in movable)
    index = {link: i for i, link in enumerate(link_names)}
    return Model(
        name=name,
        coordinate_names=names,
        coordinate_kinds=tuple("distance" if joint.type == "prismatic" else "angle" for joint in movable),
        constraint_names=constraint_names,
        drivers=np.arange(len(constraint_names)) >= closure_rows,
        actuator_names=names,
        q0=q0,
        qd0=np.zeros(n),
        point_names=link_names,
        lines=tuple((index[joint.parent], index[joint.child]) for joint in joints),
        equations=equations,
        description=description,
        source=source or "",
        parameters={"builder": "robot", "gravity": tuple(float(x) for x in g),
                    "joints": [{"name": j.name, "type": j.type, "lower": j.lower, "upper": j.upper, "effort": j.effort,
                                "velocity": j.velocity, "damping": j.damping, "friction": j.friction,
                                "mimic": j.mimic}
                               for j in movable],
                    "closures": [dict(vars(closure)) for closure in closures],
                    "drivers": [{"name": d.name, "joint": d.joint, "function": functions[f]}
                                for d, (_, f) in zip(joint_drivers, driver_rows)]
                               + [dict(vars(driver)) for driver in pose_drivers],
                    "springs": [dict(vars(spring), kind=type(spring).__name__) for spring in springs],
                    "joint_damping": joint_damping,
                    "joint_limits": joint_limits,
                    "loads": [dict(vars(load), kind=type(load).__name__) for load in loads],
                    "visuals": {link.name: tuple(link.visuals) for link in by_name.values() if link.visuals}},
        segment_masses=tuple((link.name, float(link.inertial.mass)) for link in by_name.values()
                             if link.inertial is not None and link.inertial.mass > 0),
        coordinate_limits=(np.array([-np.inf if j.lower is None else j.lower for j in movable], dtype=float),
                           np.array([np.inf if j.upper is None else j.upper for j in movable], dtype=float))
        if joint_limits else None,
    )
