"""Applied loads of spatial joint-coordinate trees (robots): joint springs and dampers, point
forces and moments on links.

- A joint spring-damper (:class:`JointSpring`) on a movable joint with coordinate q exerts the
  torque (revolute) or force (prismatic) ``τ = -k (q - q_rest) - c q̇`` between the joint's parent
  and child: ``Q_q += τ``.  Its energy ``½ k (q - q_rest)²`` is part of the model's potential
  energy V, so T + V is conserved without dampers; a damper (c > 0) is a work source
  (:attr:`cmbs.model.model.Model.work_sources`), as is a URDF joint's ``<dynamics damping=d>``
  applied as the damper ``τ = -d q̇`` when asked for (``joint_damping``; off by default, as in
  Pinocchio's ``aba``; the URDF's ``friction``, Coulomb friction, discontinuous, stays data).
- A point force (:class:`LinkForce`) F at the point p of a link (given in the link frame) adds
  ``Q += J_p(q)ᵀ F``, J_p the point's translational Jacobian (the exact virtual work of F,
  δp = J_p δq); a moment (:class:`LinkMoment`) M on a link adds ``Q += J_ω(q)ᵀ M``, J_ω the
  link's angular Jacobian.  Their components are numbers or functions of time, along the world's
  axes (``frame="world"``) or the link's (``"link"``: a follower load turning with the link,
  ``F = R_link F_link``).  Both are work sources unless every component is the constant 0.

The compiled kernel (:mod:`cmbs.model.robot_kernel`) applies the loads as Featherstone's external
forces in its recursive Newton-Euler pass and the springs after it; this module checks them and
packs them into the kernel's arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple, Sequence

import numpy as np

from cmbs.errors import ModelError, did_you_mean
from cmbs.model.drivers import TimeFunction, is_constant
from cmbs.model.robot_kernel import FRAME_LINK, FRAME_WORLD, LOAD_FORCE, LOAD_MOMENT, LOAD_REALS, SPRING_REALS
from cmbs.model.robot_targets import three_functions

if TYPE_CHECKING:
    from cmbs.model.robot import TreeJoint

__all__ = ["JointSpring", "LinkForce", "LinkMoment", "FRAMES", "load_elements"]

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


def _spring_rows(springs: Sequence[JointSpring], joints: Sequence[TreeJoint], coordinate: dict[str, int],
                 joint_damping: bool, source: str | None) -> tuple[list[int], list[tuple[float, float, float]],
                                                                   list[str]]:
    """The coordinate and (k, q_rest, c) of each spring, then of each URDF damping applied, and
    the dampers among them as work sources."""
    rows: list[int] = []
    reals: list[tuple[float, float, float]] = []
    sources: list[str] = []
    seen: set[str] = set()
    for spring in springs:
        if not isinstance(spring, JointSpring):
            raise ModelError(f"a spring is a JointSpring, got {spring!r}", entry="springs")
        entry = f"spring {spring.name!r}"
        if spring.name in seen:
            raise ModelError("duplicate spring name", entry=entry)
        seen.add(spring.name)
        if spring.joint not in coordinate:
            fixed = any(joint.name == spring.joint for joint in joints)
            problem = (f"{spring.joint!r} is a fixed joint: it has no coordinate for a spring to act on" if fixed
                       else f"unknown joint {spring.joint!r}{did_you_mean(spring.joint, coordinate)}")
            raise ModelError(f"joint: {problem}; movable joints: {', '.join(coordinate)}", entry=entry)
        stiffness = _number(spring.stiffness, "stiffness", entry, positive=True)
        damping = _number(spring.damping, "damping", entry, positive=True)
        rest = _number(spring.rest, "rest", entry)
        if stiffness == 0.0 and damping == 0.0:
            raise ModelError("stiffness and damping are both 0: give either > 0 (the spring would exert no force)",
                             entry=entry)
        rows.append(coordinate[spring.joint])
        reals.append((stiffness, rest, damping))
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
    return rows, reals, sources


def load_elements(springs: Sequence[JointSpring], loads: Sequence[LinkForce | LinkMoment],
                  joints: Sequence[TreeJoint], coordinate: dict[str, int], link_names: Sequence[str],
                  link_body: np.ndarray, link_offset: np.ndarray, *, joint_damping: bool = False,
                  first_function: int = 0, source: str | None = None) -> LoadElements:
    """The kernel's arrays of the joint ``springs``, of the URDF ``joints``' damping when
    ``joint_damping`` (the movable ones, ``coordinate``: joint name to coordinate), and of the
    forces and moments ``loads``, their points and axes moved from the link frames into their
    bodies' frames (link i on body ``link_body[i]``, -1 the ground, with the placement
    ``link_offset[i]``); the loads' components are the time functions ``first_function``
    onwards of the model's pack.

    Raises
    ------
    ModelError
        Naming the spring, force or moment (``source`` for a URDF damping): a repeated name; a
        spring on an unknown or fixed joint, a stiffness or damping that is not a finite number
        >= 0 or both 0, a rest that is not finite; a load on an unknown link or on one that does
        not move (the root or fixed to it), a point that is not 3 finite numbers, components that
        are not 3 functions of time, a frame other than ``"world"`` and ``"link"``; a negative
        URDF damping applied.
    """
    rows, spring_reals, sources = _spring_rows(springs, joints, coordinate, joint_damping, source)
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
        if load.link not in link_names:
            raise ModelError(f"link: unknown link {load.link!r}{did_you_mean(load.link, link_names)}; links: "
                             f"{', '.join(link_names)}", entry=entry)
        index = list(link_names).index(load.link)
        body, offset = int(link_body[index]), np.asarray(link_offset[index], dtype=float)
        if body < 0:
            raise ModelError(f"link: {load.link!r} does not move (it is the root or fixed to it): a {noun} on it "
                             "acts on nothing", entry=entry)
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
                        np.array(ints, dtype=np.int64).reshape(-1, 4),
                        np.array(reals, dtype=float).reshape(-1, LOAD_REALS), tuple(functions), tuple(labels),
                        tuple(sources))
