"""Loop closures of a spatial joint-coordinate tree: constraints between frames of its links.

A closure joins link a and link b (or the ground: ``"ground"``, the world frame, to which the
tree's root link is fixed too; a moving link of that name is refused) at a point given
in each link's frame (``point_a``, ``point_b``; for the ground in world coordinates).  Kinds and
their rows (Φ = 0; A, γ in :mod:`cmbs.model.robot_kernel`):

- ``point`` (3 rows ``.x .y .z``): the points coincide, ``p_a - p_b = 0`` (a spherical joint);
- ``axis`` (2 rows ``.axis1 .axis2``): the unit axis ``axis_a`` fixed in link a stays parallel to
  ``axis_b`` fixed in link b, ``u·v_1 = 0``, ``u·v_2 = 0`` with (v_1, v_2) an orthonormal pair
  perpendicular to axis_b.  The rows' gradient has the length of ``u × v_i``, which is 1 whenever
  the axes are parallel, whatever the turn about them: the rows are well conditioned at every
  joint angle (they vanish for antiparallel axes too: the same line);
- ``revolute`` (5 rows): ``point`` and ``axis`` (a revolute joint that closes the loop);
- ``line`` (2 rows ``.line1 .line2``): ``point_a`` of link a stays on the line of link b through
  ``point_b`` along ``axis_b``, ``(p_a - p_b)·v_i = 0`` with (v_1, v_2) an orthonormal pair
  perpendicular to axis_b fixed in link b (a cylindrical loop joint, or the sliding of a
  prismatic one; with an ``axis`` closure of the same axes a cylindrical joint that also keeps
  the axes parallel).  The rows' gradients in p_a are the unit vectors v_i: well conditioned
  everywhere on the line;
- ``weld`` (6 rows ``.x .y .z .rx .ry .rz``): ``point`` and the frames ``F_a = R_a Rot(rpy_a)``,
  ``F_b = R_b Rot(rpy_b)`` (rpy in URDF's convention, default 0) aligned: with their columns
  (x, y, z), ``y_a·z_b = z_a·x_b = x_a·y_b = 0``, whose Jacobian at alignment is the identity
  (they also vanish at half-turns about x, y or z: the start guess picks the alignment).
- ``prismatic`` (5 rows ``.line1 .line2 .rx .ry .rz``): ``line`` and the frames aligned as in
  ``weld``: ``point_a`` slides on the line of link b along ``axis_b`` and link a cannot turn
  relative to link b (a prismatic joint that closes the loop; the rotation lock about the line
  is the frames' alignment).

Redundant rows (e.g. a planar loop closed by a revolute joint) are allowed: the projection and
Udwadia-Kalaba formulations handle them and :func:`cmbs.constraint_report` names them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from cmbs.errors import ModelError, did_you_mean
from cmbs.model.robot_kernel import CLOSE_DOT, CLOSE_LINE, CLOSE_POINT, ELEMENT_REALS, JOINT_COUPLING

__all__ = ["Closure", "CLOSURE_KINDS", "GROUND", "closure_elements", "link_frame", "rpy_rotation"]

#: the rows of each kind, by their suffix
CLOSURE_KINDS = {"point": ("x", "y", "z"), "axis": ("axis1", "axis2"), "revolute": ("x", "y", "z", "axis1", "axis2"),
                 "weld": ("x", "y", "z", "rx", "ry", "rz"), "line": ("line1", "line2"),
                 "prismatic": ("line1", "line2", "rx", "ry", "rz")}
#: the name of the world frame as a closure's link
GROUND = "ground"


@dataclass(frozen=True)
class Closure:
    """A loop closure (module docstring): ``name``, ``kind`` (:data:`CLOSURE_KINDS`), links a and
    b (:data:`GROUND` for the world), points in their frames, axes in their frames (``axis``,
    ``revolute``; ``line`` and ``prismatic``: ``axis_b`` only) and frame turns (``weld``,
    ``prismatic``)."""

    name: str
    kind: str
    link_a: str
    link_b: str
    point_a: tuple[float, float, float] = (0.0, 0.0, 0.0)
    point_b: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axis_a: tuple[float, float, float] | None = None
    axis_b: tuple[float, float, float] | None = None
    rpy_a: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy_b: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def row_names(self) -> tuple[str, ...]:
        """The names of its constraint rows, ``NAME.SUFFIX``."""
        return tuple(f"{self.name}.{suffix}" for suffix in CLOSURE_KINDS[self.kind])


def rpy_rotation(rpy: Sequence[float]) -> np.ndarray:
    """URDF's ``Rz(yaw) Ry(pitch) Rx(roll)`` for ``rpy = (roll, pitch, yaw)``."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _perpendicular_pair(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An orthonormal pair (v_1, v_2) perpendicular to the unit ``axis`` (v_1 from the world axis
    least aligned with it, so never a near-zero cross product)."""
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    first = np.cross(axis, helper)
    first /= np.linalg.norm(first)
    return first, np.cross(axis, first)


def _vector(values: object, entry: str, field: str, source: str | None, *, unit: bool = False) -> np.ndarray:
    """Three finite numbers (nonzero when ``unit``; then normalised), else a ModelError naming the field."""
    array = np.asarray(values, dtype=float) if values is not None else None
    if array is None or array.shape != (3,) or not np.all(np.isfinite(array)):
        raise ModelError(f"{field} must be 3 finite numbers, got {values!r}", source=source, entry=entry)
    if unit:
        norm = float(np.linalg.norm(array))
        if not norm > 0:
            raise ModelError(f"{field} must be nonzero, got {values!r}", source=source, entry=entry)
        array = array / norm
    return array


def link_frame(link: str, field: str, link_names: Sequence[str], link_body: np.ndarray, link_offset: np.ndarray,
               entry: str, source: str | None = None) -> tuple[int, np.ndarray]:
    """The body of ``link`` (-1: the ground) and the link frame's placement in that body's frame
    (4 x 4; in the world for the ground); :data:`GROUND` is the world frame itself.

    Raises
    ------
    ModelError
        Naming ``entry`` and ``field``: an unknown link (did you mean, and the choices), or a moving
        link named :data:`GROUND`.
    """
    if link == GROUND and link in link_names and link_body[list(link_names).index(link)] >= 0:
        raise ModelError(f"{field}: {GROUND!r} names the world frame, but the tree has a moving link of "
                         "that name; rename the link", source=source, entry=entry)
    if link == GROUND:
        return -1, np.eye(4)
    if link in link_names:
        index = list(link_names).index(link)
        return int(link_body[index]), np.asarray(link_offset[index], dtype=float)
    choices = (GROUND, *(name for name in link_names if name != GROUND))
    raise ModelError(f"{field}: unknown link {link!r}{did_you_mean(link, choices)}; links: "
                     f"{', '.join(choices)}", source=source, entry=entry)


def closure_elements(closures: Sequence[Closure], link_names: Sequence[str], link_body: np.ndarray,
                     link_offset: np.ndarray, *, source: str | None = None
                     ) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """The kernel's closure elements (``closure_ints`` (e, 4), ``closure_reals`` (e, ELEMENT_REALS); see
    :class:`~cmbs.model.robot_kernel.RobotKernel`) and the row names, the points and vectors moved
    from the link frames into their bodies' frames (``link_offset``, ``link_body``: link i on body
    ``link_body[i]``, -1 the ground).

    Raises
    ------
    ModelError
        Naming the closure: a repeated name, an unknown kind or link, a closure of a link to
        itself, a vector that is not 3 finite numbers, a zero axis, or an axis missing.
    """
    ints: list[tuple[int, int, int, int]] = []
    reals: list[np.ndarray] = []
    names: list[str] = []
    seen: set[str] = set()
    for closure in closures:
        entry = f"closure {closure.name!r}"
        if closure.name in seen:
            raise ModelError("duplicate closure name", source=source, entry=entry)
        seen.add(closure.name)
        if closure.kind not in CLOSURE_KINDS:
            raise ModelError(f"unknown kind {closure.kind!r}{did_you_mean(closure.kind, CLOSURE_KINDS)}; kinds: "
                             f"{', '.join(CLOSURE_KINDS)}", source=source, entry=entry)
        if closure.link_a == closure.link_b:
            raise ModelError(f"link_a and link_b are the same link {closure.link_a!r}", source=source, entry=entry)
        (body_a, offset_a), (body_b, offset_b) = (
            link_frame(link, field, link_names, link_body, link_offset, entry, source)
            for field, link in (("link_a", closure.link_a), ("link_b", closure.link_b)))
        point_a = offset_a[:3, :3] @ _vector(closure.point_a, entry, "point_a", source) + offset_a[:3, 3]
        point_b = offset_b[:3, :3] @ _vector(closure.point_b, entry, "point_b", source) + offset_b[:3, 3]
        rpy_a = _vector(closure.rpy_a, entry, "rpy_a", source)
        rpy_b = _vector(closure.rpy_b, entry, "rpy_b", source)
        axes = {"axis": ("axis_a", "axis_b"), "revolute": ("axis_a", "axis_b"), "line": ("axis_b",),
                "prismatic": ("axis_b",)}.get(closure.kind, ())
        for field in ("axis_a", "axis_b"):
            given = getattr(closure, field) is not None
            if given != (field in axes):
                raise ModelError(f"{field} is {'required' if field in axes else 'not used'} by kind {closure.kind!r}",
                                 source=source, entry=entry)
        if closure.kind not in ("weld", "prismatic") and (np.any(rpy_a) or np.any(rpy_b)):
            raise ModelError(f"rpy_a and rpy_b are used by kinds 'weld' and 'prismatic' only, not by {closure.kind!r}",
                             source=source, entry=entry)
        if closure.kind in ("point", "revolute", "weld"):
            ints.append((CLOSE_POINT, body_a, body_b, 0))
            reals.append(np.concatenate([point_a, point_b, np.zeros(3)]))
        if "axis_a" in axes:
            u = offset_a[:3, :3] @ _vector(closure.axis_a, entry, "axis_a", source, unit=True)
        if axes:
            axis_b = offset_b[:3, :3] @ _vector(closure.axis_b, entry, "axis_b", source, unit=True)
            for v in _perpendicular_pair(axis_b):
                if closure.kind in ("line", "prismatic"):
                    ints.append((CLOSE_LINE, body_a, body_b, 0))
                    reals.append(np.concatenate([point_a, point_b, v]))
                else:
                    ints.append((CLOSE_DOT, body_a, body_b, 0))
                    reals.append(np.concatenate([u, v, np.zeros(3)]))
        if closure.kind in ("weld", "prismatic"):
            frame_a = offset_a[:3, :3] @ rpy_rotation(rpy_a)
            frame_b = offset_b[:3, :3] @ rpy_rotation(rpy_b)
            for i, j in ((1, 2), (2, 0), (0, 1)):
                ints.append((CLOSE_DOT, body_a, body_b, 0))
                reals.append(np.concatenate([frame_a[:, i], frame_b[:, j], np.zeros(3)]))
        names += closure.row_names
    return (np.array(ints, dtype=np.int64).reshape(-1, 4), np.array(reals, dtype=float).reshape(-1, ELEMENT_REALS),
            tuple(names))


def coupling_elements(joints: Sequence, *, source: str | None = None
                      ) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """The kernel's elements (``closure_ints`` (e, 4), ``closure_reals`` (e, ELEMENT_REALS)) and
    row names ``JOINT.mimic`` of the movable ``joints`` (in coordinate order) that mimic another:
    URDF's ``<mimic joint multiplier offset>``, the row ``q_joint - multiplier·q_mimicked -
    offset = 0`` (:mod:`cmbs.model.robot_kernel`, JOINT_COUPLING).

    Raises
    ------
    ModelError
        Naming the joint: it mimics a joint that is not a movable joint of the tree, or itself.
    """
    coordinate = {joint.name: k for k, joint in enumerate(joints)}
    ints, reals, names = [], [], []
    for k, joint in enumerate(joints):
        if joint.mimic is None:
            continue
        mimicked, multiplier, offset = joint.mimic
        entry = f"joint {joint.name!r}"
        if mimicked == joint.name:
            raise ModelError("<mimic> names the joint itself", source=source, entry=entry)
        if mimicked not in coordinate:
            raise ModelError(f"<mimic joint={mimicked!r}>: not a movable joint of the tree"
                             f"{did_you_mean(mimicked, coordinate)}", source=source, entry=entry)
        ints.append((JOINT_COUPLING, k, coordinate[mimicked], 0))
        values = np.zeros(ELEMENT_REALS)
        values[0], values[1] = multiplier, offset
        reals.append(values)
        names.append(f"{joint.name}.mimic")
    return (np.array(ints, dtype=np.int64).reshape(-1, 4), np.array(reals, dtype=float).reshape(-1, ELEMENT_REALS),
            tuple(names))
