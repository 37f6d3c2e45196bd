"""The visual geometry of robot links (URDF ``<visual>``, https://wiki.ros.org/urdf/XML/link), kept
as data on the model for the viewer and the animations (:mod:`cmbs.surfaces` turns it into
triangles); it plays no part in the dynamics.

A link has any number of visuals.  Each is a shape in its own frame, placed in the link frame by
``origin`` (4 x 4, URDF's ``<origin xyz rpy>``: ``Trans(xyz) Rz(yaw) Ry(pitch) Rx(roll)``):

- ``box``: ``size`` = (a, b, c), the edge lengths along x, y, z, centred on the frame's origin;
- ``cylinder``: ``size`` = (r, l), radius and length, its axis the frame's z, centred;
- ``sphere``: ``size`` = (r,), centred;
- ``mesh``: the triangles of the file ``filename`` (resolved as yourdfpy resolves it: relative to
  the URDF, ``package://`` paths searched upwards from it), its vertices scaled by ``size`` =
  (sx, sy, sz) (URDF's ``scale``, default 1; one number scales the three axes).

``rgba``: the URDF material's colour (red, green, blue, alpha in [0, 1]), the visual's own
``<material><color>`` or that of the robot's top-level ``<material>`` of the same name; None
when neither gives one (a mesh then shows its file's colours, anything else a grey).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cmbs.errors import ModelError

__all__ = ["SHAPES", "Visual", "checked_visual"]

#: the shapes and how many numbers ``size`` holds for each
SHAPES = {"box": 3, "cylinder": 2, "sphere": 1, "mesh": 3}


@dataclass(frozen=True, eq=False)
class Visual:
    """One visual of a link (module docstring): ``shape`` (:data:`SHAPES`), ``origin`` (4 x 4, the
    shape's frame in the link frame), ``size`` (box edges, cylinder radius and length, sphere
    radius, mesh scale), ``rgba`` (or None) and, for a mesh, ``filename``."""

    shape: str
    origin: np.ndarray
    size: tuple[float, ...]
    rgba: tuple[float, float, float, float] | None = None
    filename: str | None = None


def checked_visual(visual: Visual, *, source: str | None = None, entry: str | None = None) -> Visual:
    """``visual`` if its data make a shape, else a :class:`ModelError` naming ``source`` and
    ``entry`` (the link and the visual's number) and the value: an unknown shape, a size of the
    wrong count, not finite, negative (box, cylinder, sphere) or zero (a mesh's scale), an origin
    that is not a finite 4 x 4 rigid transform, a colour outside [0, 1], a mesh without a file."""

    def refuse(problem: str) -> ModelError:
        return ModelError(problem, source=source, entry=entry)

    if visual.shape not in SHAPES:
        raise refuse(f"unknown shape {visual.shape!r}; shapes: {', '.join(SHAPES)}")
    size = tuple(visual.size)
    if len(size) != SHAPES[visual.shape] or not all(math.isfinite(value) for value in size):
        raise refuse(f"{visual.shape} size must be {SHAPES[visual.shape]} finite numbers, got {list(size)}")
    if visual.shape == "mesh" and 0.0 in size:
        raise refuse(f"mesh scale must be nonzero, got {list(size)}")
    if visual.shape != "mesh" and min(size) < 0:
        raise refuse(f"{visual.shape} size must be >= 0, got {list(size)}")
    origin = np.asarray(visual.origin, dtype=float)
    if origin.shape != (4, 4) or not np.all(np.isfinite(origin)) \
            or not np.allclose(origin[:3, :3] @ origin[:3, :3].T, np.eye(3), atol=1e-9) \
            or not np.array_equal(origin[3], [0.0, 0.0, 0.0, 1.0]):
        raise refuse("origin must be a finite 4 x 4 rigid transform")
    if visual.rgba is not None and (len(visual.rgba) != 4 or not all(0.0 <= value <= 1.0 for value in visual.rgba)):
        raise refuse(f"colour rgba must be 4 numbers in [0, 1], got {list(visual.rgba)}")
    if visual.shape == "mesh" and not visual.filename:
        raise refuse("mesh without a filename")
    return visual
