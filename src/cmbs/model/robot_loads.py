"""Applied loads of spatial joint-coordinate trees (robots): joint springs and dampers, point
forces and moments on links.

- A joint spring-damper (:class:`JointSpring`) on a movable joint with coordinate q exerts the
  torque (revolute) or force (prismatic) ``τ = -k (q - q_rest) - c q̇`` between the joint's parent
  and child: ``Q_q += τ``.  Its energy ``½ k (q - q_rest)²`` is part of the model's potential
  energy V, so T + V is conserved without dampers; a damper (c > 0) is a work source
  (:attr:`cmbs.model.model.Model.work_sources`), as is a URDF joint's ``<dynamics damping=d>``
  applied as the damper ``τ = -d q̇`` when asked for (``joint_damping``; off by default, as in
  Pinocchio's ``aba``; the URDF's ``friction``, Coulomb friction, discontinuous, stays data).
- A spring-damper between two points (:class:`PointSpring`), p_a on link a and p_b on link b
  (either may be the ground, :data:`~cmbs.model.robot_closures.GROUND`), with ``d = p_a - p_b``,
  ``ℓ = |d|``, ``u = d / ℓ`` and ``ℓ̇ = u·(ṗ_a - ṗ_b)``, has the tension ``f = k (ℓ - ℓ0) + c ℓ̇``
  (positive: it pulls the points together), the force ``-f u`` at p_a and ``f u`` at p_b:
  ``Q += J_aᵀ(-f u) + J_bᵀ(f u)`` (J_a, J_b the points' translational Jacobians).  Its energy
  ``½ k (ℓ - ℓ0)²`` is part of V; a damper (c > 0) is a work source, ``damper 'NAME'`` as a joint
  damper.  The rest length ℓ0 defaults to the points' distance at the model's start, ``model.q0``
  of the model returned: for :func:`~cmbs.model.robot.build_robot` and
  :func:`~cmbs.model.urdf.load_urdf` each joint's value nearest 0 within its limits (not
  assembled), for a robot file its assembled start (:mod:`cmbs.model.robot_files`); the points
  must not coincide there (ℓ0 would be 0, the spring without a direction).  At ℓ = 0 during a
  motion the direction u is undefined and the spring exerts no force (with ℓ0 = 0 and no damper
  its force ``-k d`` at p_a is continuous there; otherwise it jumps as the points pass each other).
- A point force (:class:`LinkForce`) F at the point p of a link (given in the link frame) adds
  ``Q += J_p(q)ᵀ F``, J_p the point's translational Jacobian (the exact virtual work of F,
  δp = J_p δq); a moment (:class:`LinkMoment`) M on a link adds ``Q += J_ω(q)ᵀ M``, J_ω the
  link's angular Jacobian.  Their components are numbers or functions of time, along the world's
  axes (``frame="world"``) or the link's (``"link"``: a follower load turning with the link,
  ``F = R_link F_link``).  Both are work sources unless every component is the constant 0.

The compiled kernel (:mod:`cmbs.model.robot_kernel`) applies the loads and the point springs as
Featherstone's external forces in its recursive Newton-Euler pass and the joint springs after it;
this module checks them and packs them into the kernel's arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple, Sequence

import numpy as np

from cmbs.errors import ModelError, did_you_mean
from cmbs.model.drivers import TimeFunction, is_constant
from cmbs.model.robot_closures import link_frame
from cmbs.model.robot_kernel import FRAME_LINK, FRAME_WORLD, LOAD_FORCE, LOAD_MOMENT, LOAD_REALS, \
    POINT_SPRING_REALS, SPRING_REALS
from cmbs.model.robot_targets import moving_link, three_functions

if TYPE_CHECKING:
    from cmbs.model.robot import TreeJoint

__all__ = ["JointSpring", "PointSpring", "LinkForce", "LinkMoment", "FRAMES", "load_elements", "point_spring_lengths",
           "measured_rest_length"]

#: the axes a load's components are given along
FRAMES = {"world": FRAME_WORLD, "link": FRAME_LINK}


@dataclass(frozen=True)
class JointSpring:
    """A linear spring-damper on the movable joint ``joint``: ``τ = -k (q - rest) - c q̇`` with
    ``stiffness`` k >= 0 (N m/rad, or N/m on a prismatic joint), ``rest`` q_rest (rad or m) and
    ``damping`` c >= 0 (N m s/rad or N s/m); at least one of k and c > 0."""

    name: str
    joint: str
    stiffness: float = 0.0
    rest: float = 0.0
    damping: float = 0.0


@dataclass(frozen=True)
class PointSpring:
    """A linear spring-damper between the point ``point_a`` of ``link_a`` and ``point_b`` of
    ``link_b`` (m, each in its link's frame; a link may be ``"ground"``, the world frame, its point
    then in world coordinates; not both): with ``ℓ = |p_a - p_b|`` and ``u = (p_a - p_b) / ℓ`` the
    tension ``f = k (ℓ - ℓ0) + c ℓ̇`` pulls the points together, ``Q += J_aᵀ(-f u) + J_bᵀ(f u)``;
    ``stiffness`` k >= 0 (N/m), ``damping`` c >= 0 (N s/m), at least one > 0, ``rest_length``
    ℓ0 >= 0 (m; None: the points' distance at the model's start, module docstring)."""

    name: str
    link_a: str
    point_a: tuple[float, float, float]
    link_b: str
    point_b: tuple[float, float, float]
    stiffness: float
    damping: float = 0.0
    rest_length: float | None = None


@dataclass(frozen=True)
class LinkForce:
    """A force ``force`` (three numbers or functions of time, N) at ``point`` (link frame, m) of
    ``link``, its components along the world's axes (``frame="world"``) or the link's
    (``"link"``)."""

    name: str
    link: str
    force: tuple[object, object, object]
    point: tuple[float, float, float] = (0.0, 0.0, 0.0)
    frame: str = "world"


@dataclass(frozen=True)
class LinkMoment:
    """A moment ``moment`` (three numbers or functions of time, N m) on ``link``, its components
    along the world's axes (``frame="world"``) or the link's (``"link"``)."""

    name: str
    link: str
    moment: tuple[object, object, object]
    frame: str = "world"


class LoadElements(NamedTuple):
    """The springs and loads as the kernel takes them (:func:`load_elements`; the arrays of
    :class:`~cmbs.model.robot_kernel.RobotKernel` of the same names)."""

    springs: np.ndarray                  # (s,) int64 coordinates
    spring_reals: np.ndarray             # (s, SPRING_REALS): k, q_rest, c
    point_springs: np.ndarray            # (p, 2) int64: body a, body b (-1: the ground)
    point_spring_reals: np.ndarray       # (p, POINT_SPRING_REALS): l_a, l_b (body frames), k, c, ℓ0 (NaN: not
                                         # given, to be measured: :func:`measured_rest_length`)
    load_ints: np.ndarray                # (l, 4) int64: kind, body, frame, first time function
    load_reals: np.ndarray               # (l, LOAD_REALS): point and link rotation in the body frame
    functions: tuple[TimeFunction, ...]  # the loads' components, three consecutive functions each
    labels: tuple[str, ...]              # each function's name in messages
    work_sources: tuple[str, ...]        # the dampers and the loads that are not constant zero


def _number(value: object, label: str, entry: str, *, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
            or not math.isfinite(value) or (positive and value < 0):
        raise ModelError(f"{label} must be a finite number{' >= 0' if positive else ''}, got {value!r}", entry=entry)
    return float(value)


def _joint_spring_row(spring: JointSpring, entry: str, joints: Sequence[TreeJoint],
                      coordinate: dict[str, int]) -> tuple[int, tuple[float, float, float]]:
    """The coordinate and (k, q_rest, c) of a joint spring."""
    if spring.joint not in coordinate:
        fixed = any(joint.name == spring.joint for joint in joints)
        problem = (f"{spring.joint!r} is a fixed joint: it has no coordinate for a spring to act on" if fixed
                   else f"unknown joint {spring.joint!r}{did_you_mean(spring.joint, coordinate)}")
        raise ModelError(f"joint: {problem}; movable joints: {', '.join(coordinate)}", entry=entry)
    stiffness = _number(spring.stiffness, "stiffness", entry, positive=True)
    damping = _number(spring.damping, "damping", entry, positive=True)
    rest = _number(spring.rest, "rest", entry)
    _acts(stiffness, damping, entry)
    return coordinate[spring.joint], (stiffness, rest, damping)


def _acts(stiffness: float, damping: float, entry: str) -> None:
    """A ModelError naming ``entry`` when a spring has neither stiffness nor damping."""
    if stiffness == 0.0 and damping == 0.0:
        raise ModelError("stiffness and damping are both 0: give either > 0 (the spring would exert no force)",
                         entry=entry)


def _point_spring_row(spring: PointSpring, entry: str, link_names: Sequence[str], link_body: np.ndarray,
                      link_offset: np.ndarray) -> tuple[tuple[int, int], np.ndarray]:
    """The bodies (a, b) and reals (l_a, l_b in the bodies' frames, k, c, ℓ0 or NaN) of a point spring."""
    ends = []
    for side in ("a", "b"):
        body, offset = link_frame(getattr(spring, f"link_{side}"), f"link_{side}", link_names, link_body,
                                  link_offset, entry)
        value = getattr(spring, f"point_{side}")
        try:
            point = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            point = np.zeros(0)
        if point.shape != (3,) or not np.all(np.isfinite(point)):
            raise ModelError(f"point_{side} must be 3 finite numbers, got {value!r}", entry=entry)
        ends.append((body, offset[:3, :3] @ point + offset[:3, 3]))
    (body_a, point_a), (body_b, point_b) = ends
    if body_a == body_b:
        problem = ("both ends are on the ground (the world, the root link or links fixed to it): the spring would "
                   "act on nothing" if body_a < 0 else
                   f"link_a {spring.link_a!r} and link_b {spring.link_b!r} are one rigid body: the spring's two "
                   "forces on it cancel")
        raise ModelError(problem, entry=entry)
    stiffness = _number(spring.stiffness, "stiffness", entry, positive=True)
    damping = _number(spring.damping, "damping", entry, positive=True)
    _acts(stiffness, damping, entry)
    rest = math.nan if spring.rest_length is None else _number(spring.rest_length, "rest_length", entry,
                                                                 positive=True)
    return (body_a, body_b), np.concatenate([point_a, point_b, [stiffness, damping, rest]])


def point_spring_lengths(point_springs: np.ndarray, point_spring_reals: np.ndarray, R: np.ndarray,
                         o: np.ndarray) -> np.ndarray:
    """ℓ = |p_a - p_b| of each point spring (the kernel's ``point_springs`` and
    ``point_spring_reals``) for the bodies' world rotations ``R`` (n, 3, 3) and origins ``o`` (n, 3)."""
    def world(body: int, local: np.ndarray) -> np.ndarray:
        return local if body < 0 else o[body] + R[body] @ local

    return np.array([np.linalg.norm(world(a, reals[0:3]) - world(b, reals[3:6]))
                     for (a, b), reals in zip(point_springs, point_spring_reals)], dtype=float)


def measured_rest_length(name: str, length: float) -> float:
    """``length``, the distance of point spring ``name``'s points at the model's start, as its
    default rest length; a ModelError naming the spring when the points coincide there."""
    if not length > 0.0:
        raise ModelError("point_a and point_b coincide at the start q0: the spring has no direction there and no "
                         "rest length to take from it; move a point or give rest_length",
                         entry=f"point spring {name!r}")
    return float(length)


def _spring_rows(springs: Sequence[JointSpring | PointSpring], joints: Sequence[TreeJoint],
                 coordinate: dict[str, int], link_names: Sequence[str], link_body: np.ndarray,
                 link_offset: np.ndarray, joint_damping: bool, source: str | None
                 ) -> tuple[list[int], list[tuple[float, float, float]], list[tuple[int, int]], list[np.ndarray],
                            list[str]]:
    """The coordinate and (k, q_rest, c) of each joint spring, then of each URDF damping applied;
    the bodies and reals of each point spring; the dampers among them as work sources."""
    rows: list[int] = []
    reals: list[tuple[float, float, float]] = []
    point_ints: list[tuple[int, int]] = []
    point_reals: list[np.ndarray] = []
    sources: list[str] = []
    seen: set[str] = set()
    for spring in springs:
        if not isinstance(spring, (JointSpring, PointSpring)):
            raise ModelError(f"a spring is a JointSpring or a PointSpring, got {spring!r}", entry="springs")
        entry = f"{'spring' if isinstance(spring, JointSpring) else 'point spring'} {spring.name!r}"
        if spring.name in seen:
            raise ModelError("duplicate spring name (joint and point springs share one namespace)", entry=entry)
        seen.add(spring.name)
        if isinstance(spring, JointSpring):
            row, values = _joint_spring_row(spring, entry, joints, coordinate)
            rows.append(row)
            reals.append(values)
            damping = values[2]
        else:
            bodies, values = _point_spring_row(spring, entry, link_names, link_body, link_offset)
            point_ints.append(bodies)
            point_reals.append(values)
            damping = float(values[7])
        if damping > 0:
            sources.append(f"damper {spring.name!r}")
    if joint_damping:
        for joint in joints:
            name, damping = joint.name, joint.damping
            if name not in coordinate or damping == 0.0:
                continue
            if not (math.isfinite(damping) and damping > 0):
                raise ModelError(f"<dynamics damping={damping!r}> must be a finite number >= 0 to be applied as a "
                                 "damper (joint_damping)", source=source, entry=f"joint {name!r}")
            rows.append(coordinate[name])
            reals.append((0.0, 0.0, float(damping)))
            sources.append(f"damping of joint {name!r}")
    return rows, reals, point_ints, point_reals, sources


def load_elements(springs: Sequence[JointSpring | PointSpring], loads: Sequence[LinkForce | LinkMoment],
                  joints: Sequence[TreeJoint], coordinate: dict[str, int], link_names: Sequence[str],
                  link_body: np.ndarray, link_offset: np.ndarray, *, joint_damping: bool = False,
                  first_function: int = 0, source: str | None = None) -> LoadElements:
    """The kernel's arrays of the joint and point ``springs``, of the URDF ``joints``' damping when
    ``joint_damping`` (the movable ones, ``coordinate``: joint name to coordinate), and of the
    forces and moments ``loads``, their points and axes moved from the link frames into their
    bodies' frames (link i on body ``link_body[i]``, -1 the ground, with the placement
    ``link_offset[i]``); the loads' components are the time functions ``first_function``
    onwards of the model's pack.  A point spring given no rest length has ℓ0 = NaN, for the
    caller to measure (:func:`measured_rest_length`).

    Raises
    ------
    ModelError
        Naming the spring, force or moment (``source`` for a URDF damping): a repeated name (the
        joint and point springs share one); a spring on an unknown or fixed joint, a stiffness or
        damping that is not a finite number >= 0 or both 0, a rest that is not finite; a point
        spring on an unknown link, with both ends on the ground or on one body, a point that is
        not 3 finite numbers, a rest_length that is not a finite number >= 0; a load on an
        unknown link or on one that does not move (the root or fixed to it), a point that is not
        3 finite numbers, components that are not 3 functions of time, a frame other than
        ``"world"`` and ``"link"``; a negative URDF damping applied.
    """
    rows, spring_reals, point_ints, point_reals, sources = _spring_rows(springs, joints, coordinate, link_names,
                                                                        link_body, link_offset, joint_damping,
                                                                        source)
    ints: list[tuple[int, int, int, int]] = []
    reals: list[np.ndarray] = []
    functions: list[TimeFunction] = []
    labels: list[str] = []
    seen: set[tuple[str, str]] = set()
    for load in loads:
        if not isinstance(load, (LinkForce, LinkMoment)):
            raise ModelError(f"a load is a LinkForce or a LinkMoment, got {load!r}", entry="loads")
        noun = "force" if isinstance(load, LinkForce) else "moment"
        entry = f"{noun} {load.name!r}"
        if (noun, load.name) in seen:
            raise ModelError(f"duplicate {noun} name", entry=entry)
        seen.add((noun, load.name))
        body, offset = moving_link(load.link, link_names, link_body, link_offset, entry,
                                   f"a {noun} on it acts on nothing")
        if load.frame not in FRAMES:
            raise ModelError(f"frame: unknown frame {load.frame!r}{did_you_mean(str(load.frame), FRAMES)}; frames: "
                             f"{', '.join(FRAMES)}", entry=entry)
        point = np.asarray(getattr(load, "point", (0.0, 0.0, 0.0)), dtype=float)
        if point.shape != (3,) or not np.all(np.isfinite(point)):
            raise ModelError(f"point must be 3 finite numbers, got {getattr(load, 'point')!r}", entry=entry)
        components = three_functions(getattr(load, noun), noun, ("x", "y", "z"), entry)
        ints.append((LOAD_FORCE if noun == "force" else LOAD_MOMENT, body, FRAMES[load.frame],
                     first_function + len(functions)))
        reals.append(np.concatenate([offset[:3, :3] @ point + offset[:3, 3], offset[:3, :3].ravel()]))
        functions += components
        labels += [f"{noun} {load.name} {axis}" for axis in "xyz"]
        if not all(is_constant(function) and function.value == 0 for function in components):
            sources.append(entry)
    return LoadElements(np.array(rows, dtype=np.int64), np.array(spring_reals, dtype=float).reshape(-1, SPRING_REALS),
                        np.array(point_ints, dtype=np.int64).reshape(-1, 2),
                        np.array(point_reals, dtype=float).reshape(-1, POINT_SPRING_REALS),
                        np.array(ints, dtype=np.int64).reshape(-1, 4),
                        np.array(reals, dtype=float).reshape(-1, LOAD_REALS), tuple(functions), tuple(labels),
                        tuple(sources))
