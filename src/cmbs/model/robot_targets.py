"""Pose drivers of a spatial joint-coordinate tree: a link frame driven to a target pose in the world.

A pose driver ``NAME`` on ``link`` prescribes, as functions of time (numbers, expressions of t,
tables or callables: :func:`cmbs.model.drivers.as_time_function`), the world position of the
link's point ``point`` (link frame, default its origin) and/or the orientation of the link frame,
given as URDF's roll-pitch-yaw ``Rz(ψ) Ry(θ) Rx(φ)`` (fixed axes x, y, z).  Rows (drivers; A, γ,
Φ_t in :mod:`cmbs.model.robot_kernel`)::

    position    (3 rows NAME.x .y .z):    p(q) - p_t(t) = 0,
    orientation (3 rows NAME.rx .ry .rz): y·z_t = z·x_t = x·y_t = 0,

with (x, y, z) the link frame's axes and (x_t, y_t, z_t) the target's, the rows of the ``weld``
closure (:mod:`cmbs.model.robot_closures`): their Jacobian at alignment is the identity in the
angular velocity, well conditioned near the target.  They vanish at other turns too (half-turns
about x_t, y_t or z_t, the turn by 120° about x_t + y_t + z_t); :meth:`RobotEquations.turned_targets`
names a frame left at such a spurious root (more than 90° from its target), and
:func:`cmbs.assemble` refuses it.  Position only is 3 rows, orientation only 3, the full pose 6.
Solving Φ = 0 for q at a time t (:func:`cmbs.assemble`) is inverse kinematics; along a time grid
(:func:`cmbs.kinematic_analysis`) the inverse kinematics of a motion.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple, Sequence

import numpy as np

from cmbs.errors import ModelError, did_you_mean
from cmbs.model.drivers import TimeFunction, as_time_function, is_constant
from cmbs.model.robot_kernel import ELEMENT_REALS, TARGET_DOT, TARGET_POINT

__all__ = ["PoseDriver", "TargetElements", "target_elements"]

#: the rows of each part of a pose, by their suffix
POSITION_ROWS, ORIENTATION_ROWS = ("x", "y", "z"), ("rx", "ry", "rz")
#: the orientation rows' pairs (link frame column, target column): y·z_t, z·x_t, x·y_t
ORIENTATION_PAIRS = ((1, 2), (2, 0), (0, 1))


@dataclass(frozen=True)
class PoseDriver:
    """A pose driver (module docstring): constraint rows ``NAME.x`` ..., ``link`` a link of the
    tree, ``point`` in its frame, ``position`` three functions of time (x, y, z in the world, m)
    or None, ``rpy`` three functions of time (roll, pitch, yaw, rad) or None; at least one of them."""

    name: str
    link: str
    point: tuple[float, float, float] = (0.0, 0.0, 0.0)
    position: tuple[object, object, object] | None = None
    rpy: tuple[object, object, object] | None = None

    @property
    def row_names(self) -> tuple[str, ...]:
        """The names of its constraint rows, ``NAME.SUFFIX``."""
        suffixes = (POSITION_ROWS if self.position is not None else ()) + \
            (ORIENTATION_ROWS if self.rpy is not None else ())
        return tuple(f"{self.name}.{suffix}" for suffix in suffixes)


def three_functions(values: object, field: str, axes: tuple[str, str, str], entry: str) -> list[TimeFunction]:
    """The three functions of time of ``values`` (numbers, expressions, tables, callables:
    :func:`~cmbs.model.drivers.as_time_function`), the components ``axes`` of ``field``; a
    ModelError naming ``entry`` and the field otherwise."""
    if not isinstance(values, (tuple, list)) or len(values) != 3:
        raise ModelError(f"{field} must be 3 functions of time, got {values!r}", entry=entry)
    functions = []
    for axis, value in zip(axes, values):
        try:
            functions.append(as_time_function(value))
        except ModelError as error:
            raise ModelError(f"{field} {axis}: {error.problem}", entry=entry) from None
    return functions


class TargetElements(NamedTuple):
    """The pose drivers as the kernel takes them (:func:`target_elements`)."""

    ints: np.ndarray                  # (e, 4) rows of ``closure_ints``
    reals: np.ndarray                 # (e, ELEMENT_REALS) rows of ``closure_reals``
    names: tuple[str, ...]            # their constraint rows
    functions: tuple[TimeFunction, ...]   # the time functions, first of the model's pack
    labels: tuple[str, ...]           # each function's name in messages
    steady: tuple[str, ...]           # the rows of drivers of constants (they do no work)
    orientations: tuple[tuple[str, int, int], ...]  # (first orientation row, link index, function of its roll)


def moving_link(link: str, link_names: Sequence[str], link_body: np.ndarray, link_offset: np.ndarray, entry: str,
                consequence: str) -> tuple[int, np.ndarray]:
    """The body of the moving ``link`` and the link frame's placement in that body's frame (4 x 4).

    Raises
    ------
    ModelError
        Naming ``entry``: an unknown link (did you mean, and the links), or a link that does not
        move (the root or a link fixed to it), saying the ``consequence``.
    """
    if link not in link_names:
        raise ModelError(f"link: unknown link {link!r}{did_you_mean(link, link_names)}; links: "
                         f"{', '.join(link_names)}", entry=entry)
    index = list(link_names).index(link)
    body, offset = int(link_body[index]), np.asarray(link_offset[index], dtype=float)
    if body < 0:
        raise ModelError(f"link: {link!r} does not move (it is the root or fixed to it): {consequence}", entry=entry)
    return body, offset


def target_elements(drivers: Sequence[PoseDriver], link_names: Sequence[str], link_body: np.ndarray,
                    link_offset: np.ndarray) -> TargetElements:
    """The kernel's elements of the pose drivers (rows of ``closure_ints`` and ``closure_reals``;
    :class:`~cmbs.model.robot_kernel.RobotKernel`), their row names, and their time functions,
    which come first in the model's pack: each driver's position x, y, z, then its roll, pitch,
    yaw, three consecutive functions each.  The point and the link frame's axes are moved into
    the link's body frame (``link_offset``, ``link_body``: link i on body ``link_body[i]``).

    Raises
    ------
    ModelError
        Naming the driver: an unknown link, a link that does not move (the root or fixed to it),
        a point that is not 3 finite numbers, no part given, or a part that is not 3 functions of
        time.
    """
    ints: list[tuple[int, int, int, int]] = []
    reals: list[np.ndarray] = []
    names: list[str] = []
    functions: list[TimeFunction] = []
    labels: list[str] = []
    steady: list[str] = []
    orientations: list[tuple[str, int, int]] = []
    for driver in drivers:
        entry = f"driver {driver.name!r}"
        body, offset = moving_link(driver.link, link_names, link_body, link_offset, entry,
                                   "no joint can bring it to a pose")
        index = list(link_names).index(driver.link)
        point = np.asarray(driver.point, dtype=float)
        if point.shape != (3,) or not np.all(np.isfinite(point)):
            raise ModelError(f"point must be 3 finite numbers, got {driver.point!r}", entry=entry)
        if driver.position is None and driver.rpy is None:
            raise ModelError("give the target's position, its orientation (rpy) or both", entry=entry)
        first = len(functions)
        if driver.position is not None:
            ints.append((TARGET_POINT, body, len(functions), 0))
            reals.append(np.concatenate([offset[:3, :3] @ point + offset[:3, 3], np.zeros(ELEMENT_REALS - 3)]))
            functions += three_functions(driver.position, "position", ("x", "y", "z"), entry)
            labels += [f"driver {driver.name} position {axis}" for axis in "xyz"]
        if driver.rpy is not None:
            orientations.append((f"{driver.name}.{ORIENTATION_ROWS[0]}", index, len(functions)))
            for i, j in ORIENTATION_PAIRS:
                ints.append((TARGET_DOT, body, len(functions), j))
                reals.append(np.concatenate([offset[:3, i], np.zeros(ELEMENT_REALS - 3)]))
            functions += three_functions(driver.rpy, "rpy", ("roll", "pitch", "yaw"), entry)
            labels += [f"driver {driver.name} {angle}" for angle in ("roll", "pitch", "yaw")]
        names += driver.row_names
        if all(is_constant(function) for function in functions[first:]):
            steady += driver.row_names
    return TargetElements(np.array(ints, dtype=np.int64).reshape(-1, 4),
                          np.array(reals, dtype=float).reshape(-1, ELEMENT_REALS), tuple(names), tuple(functions),
                          tuple(labels), tuple(steady), tuple(orientations))
