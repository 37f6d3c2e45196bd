"""Triangles of a robot's visual geometry (:mod:`cmbs.model.visuals`), in each link's own
coordinates, for the HTML viewer and the animations (a leaf, like :mod:`cmbs.animate`):

    surfaces = link_surfaces(cmbs.load("ur5_robot.urdf"))    # a few hundred triangles per link

A point p of a link's surface is at ``o + R p`` in the world when the link frame is at (R, o)
(:func:`cmbs.kinematics.body_poses`, :func:`cmbs.model.robot.frame_placement`).  Each visual is
made of triangles in its shape's frame, then scaled (a mesh by its ``scale``) and placed in the
link frame by its origin, ``p = R_v (S p_shape) + t_v``:

- box (a, b, c): its 8 corners, 2 triangles per face (12);
- cylinder (r, l): :data:`SEGMENTS` sides about z from -l/2 to l/2, two triangles each, and a
  fan of as many on each cap (4 x 24 = 96);
- sphere (r): :data:`SEGMENTS` meridians by :data:`SEGMENTS` / 2 parallels, the poles as fans
  (2 x 24 x 11 = 528);
- mesh: the triangle meshes of the file read by trimesh (STL, OBJ, PLY, ..., COLLADA ``.dae``
  through pycollada), each moved by its node's transform in the file (``trimesh.Scene.dump``).

Colours: the URDF material's (alpha dropped), else, for a mesh, each of the file's meshes has
its material's main colour, else :data:`GREY`.  Triangles of one visual and one colour form one
:class:`Surface`.

A link whose surfaces have more than ``budget`` triangles (:data:`TRIANGLES`) is simplified by
vertex clustering (Rossignac and Borrel, "Multi-resolution 3D approximations for rendering
complex scenes", in Modeling in Computer Graphics, Springer 1993): space is cut into cubes of
side h, the vertices in one cube become one vertex (their mean, so the link's shape stays inside
its bounding box), triangles that lose a corner that way vanish, as do repeated ones.  h is the
smallest one that a bisection on log h finds (:data:`BISECTIONS` steps from 1e-4 of the link's
size to its size) that leaves at most ``budget`` triangles.  It keeps the silhouettes of parts larger than h
(about 1/60 of a UR5 link's length at 1000 triangles) and drops details smaller than that.

A mesh file that is missing or cannot be read (no reader for its format, a broken file, no
triangles in it) is a :class:`~cmbs.errors.CmbsWarning` naming the file and the link, which is
then drawn without surfaces (the viewer and the animations draw it as a stick figure): never an
error.
"""

from __future__ import annotations

import functools
import math
import warnings
from pathlib import Path
from typing import NamedTuple

import numpy as np

from cmbs.errors import CmbsWarning
from cmbs.model.model import Model, base_equations
from cmbs.model.visuals import Visual

__all__ = ["Surface", "link_surfaces", "grounded", "visual_surfaces", "simplified", "TRIANGLES", "SEGMENTS", "GREY"]

#: the most triangles a link gets: the UR5 (7 links with meshes) in about 6,000 triangles
TRIANGLES = 1000
#: sides of a cylinder, meridians of a sphere
SEGMENTS = 24
#: steps of the bisection on log h of :func:`simplified` (h to 1 % of 10⁴ between the bounds)
BISECTIONS = 11
#: the colour of a visual that gives none (red, green, blue in [0, 1])
GREY = (0.6, 0.6, 0.6)


class Surface(NamedTuple):
    """Triangles of one colour fixed to ``link``: ``vertices`` (V, 3) in the link's coordinates,
    ``triangles`` (T, 3) indices into them, ``colour`` (red, green, blue in [0, 1]).  ``link``
    None: fixed to the ground, the vertices in world coordinates (:func:`grounded`)."""

    link: str | None
    vertices: np.ndarray
    triangles: np.ndarray
    colour: tuple[float, float, float]


def link_surfaces(model: Model, *, budget: int = TRIANGLES) -> tuple[Surface, ...]:
    """The surfaces of every link of ``model`` that has visuals (``model.parameters["visuals"]``,
    none for a model that is not a robot), in the order of the links, at most ``budget``
    triangles per link (module docstring).  A link with a mesh that cannot be read gets none,
    with a :class:`~cmbs.errors.CmbsWarning` naming the file and the link."""
    surfaces: list[Surface] = []
    for link, visuals in model.parameters.get("visuals", {}).items():
        try:
            parts = [part for visual in visuals for part in visual_surfaces(link, visual)]
        except _Unreadable as problem:
            warnings.warn(f"{model.source or model.name}: link {link!r}: {problem}; the link is drawn as a stick "
                          "figure", CmbsWarning, stacklevel=2)
            continue
        surfaces.extend(simplified(parts, budget))
    return tuple(surfaces)


def grounded(model: Model, surfaces: tuple[Surface, ...]) -> tuple[Surface, ...]:
    """``surfaces`` of a robot ``model`` with those of the links that do not move (the root and
    the links fixed to it: not in the equations' ``bodies``) put in world coordinates, their link
    None: p_world = o + R p for the link frame's placement (R, o), the same at every q
    (``RobotEquations.link_placements``)."""
    if not surfaces:
        return ()
    equations = base_equations(model)[0]
    rotations, origins = equations.link_placements(np.asarray(model.q0, dtype=float))
    placed = []
    for surface in surfaces:
        if surface.link is None or surface.link in equations.bodies:
            placed.append(surface)
        else:
            k = equations.link_names.index(surface.link)
            placed.append(surface._replace(link=None, vertices=surface.vertices @ rotations[k].T + origins[k]))
    return tuple(placed)


def visual_surfaces(link: str, visual: Visual) -> list[Surface]:
    """The triangles of one visual of ``link`` in the link's coordinates, one surface per colour
    (module docstring).  Raises :class:`_Unreadable` for a mesh file that cannot be read."""
    if visual.shape == "mesh":
        parts = [(vertices * np.asarray(visual.size), triangles, colour)
                 for vertices, triangles, colour in _mesh_file(str(visual.filename))]
    else:
        vertices, triangles = _SHAPES[visual.shape](*visual.size)
        parts = [(vertices, triangles, None)]
    rotation, offset = visual.origin[:3, :3], visual.origin[:3, 3]
    chosen = None if visual.rgba is None else tuple(float(value) for value in visual.rgba[:3])
    merged: dict[tuple[float, float, float], list[tuple[np.ndarray, np.ndarray]]] = {}
    for vertices, triangles, colour in parts:
        merged.setdefault(chosen or colour or GREY, []).append((vertices @ rotation.T + offset, triangles))
    surfaces = []
    for colour, pieces in merged.items():
        starts = np.cumsum([0] + [len(vertices) for vertices, _ in pieces[:-1]])
        surfaces.append(Surface(link, np.concatenate([vertices for vertices, _ in pieces]),
                                np.concatenate([triangles + start for (_, triangles), start in zip(pieces, starts)]),
                                colour))
    return surfaces


def simplified(surfaces: list[Surface], budget: int) -> list[Surface]:
    """``surfaces`` (one link's) with at most ``budget`` triangles in all: unchanged if they have
    no more, else vertex-clustered on one grid (module docstring); surfaces left without
    triangles are dropped.  A budget below 56 may be missed: cubes of the link's size, the
    largest tried, leave the triangles of up to 8 cubes' vertices."""
    if sum(len(surface.triangles) for surface in surfaces) <= budget:
        return surfaces
    vertices = np.concatenate([surface.vertices for surface in surfaces])
    starts = np.cumsum([0] + [len(surface.vertices) for surface in surfaces])
    triangles = [surface.triangles + start for surface, start in zip(surfaces, starts)]
    size = float(np.linalg.norm(np.ptp(vertices, axis=0))) or 1.0
    low, high = math.log(1e-4 * size), math.log(size)
    best = _clustered(vertices, triangles, size)          # cubes the link's size: a few triangles at most
    for _ in range(BISECTIONS):
        middle = 0.5 * (low + high)
        trial = _clustered(vertices, triangles, math.exp(middle))
        if sum(len(corners) for corners in trial[1]) <= budget:
            best, high = trial, middle
        else:
            low = middle
    means, kept = best
    result = []
    for surface, corners in zip(surfaces, kept):
        if len(corners):
            used, renumbered = np.unique(corners, return_inverse=True)
            result.append(surface._replace(vertices=means[used], triangles=renumbered.reshape(-1, 3)))
    return result


def _clustered(vertices: np.ndarray, triangles: list[np.ndarray], side: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """The vertices merged per cube of edge ``side`` of the grid through the origin, each cube's
    vertices replaced by their mean, and each triangle list renumbered to them: triangles with two
    corners in one cube dropped, repeated triangles (the same corners) kept once."""
    cells = np.floor(vertices / side).astype(np.int64)
    cells -= cells.min(axis=0)
    extent = cells.max(axis=0) + 1                  # at most size / side + 1 = 10⁴ + 1 per axis: no overflow
    keys = (cells[:, 0] * extent[1] + cells[:, 1]) * extent[2] + cells[:, 2]
    _, cluster, counts = np.unique(keys, return_inverse=True, return_counts=True)
    means = np.zeros((counts.size, 3))
    np.add.at(means, cluster, vertices)
    means /= counts[:, None]
    kept = []
    for corners in triangles:
        corners = cluster[corners]
        corners = corners[(corners[:, 0] != corners[:, 1]) & (corners[:, 1] != corners[:, 2])
                          & (corners[:, 0] != corners[:, 2])]
        ordered = np.sort(corners, axis=1)
        _, first = np.unique((ordered[:, 0] * counts.size + ordered[:, 1]) * counts.size + ordered[:, 2],
                             return_index=True)
        kept.append(corners[np.sort(first)])
    return means, kept


class _Unreadable(Exception):
    """A mesh file that cannot be read; the message names the file and why."""


@functools.lru_cache(maxsize=64)
def _mesh_file(filename: str) -> tuple[tuple[np.ndarray, np.ndarray, tuple[float, float, float] | None], ...]:
    """The triangle meshes of a file (vertices moved by their node's transform, triangles, the
    material's main colour or None), read by trimesh once per file and process."""
    import trimesh

    if not Path(filename).is_file():
        raise _Unreadable(f"mesh {filename}: no such file")
    try:
        scene = trimesh.load(filename, force="scene")
        meshes = [mesh for mesh in scene.dump() if isinstance(mesh, trimesh.Trimesh) and len(mesh.faces)]
    except Exception as error:      # trimesh and its readers raise anything on a file they cannot read
        raise _Unreadable(f"cannot read mesh {filename} ({type(error).__name__}: {' '.join(str(error).split())})") \
            from None
    if not meshes:
        raise _Unreadable(f"mesh {filename} has no triangles")
    parts = []
    for mesh in meshes:
        material = getattr(mesh.visual, "material", None)
        colour = getattr(material, "main_color", None)
        vertices = np.array(mesh.vertices, dtype=float)
        triangles = np.array(mesh.faces, dtype=np.int64)
        vertices.setflags(write=False)
        triangles.setflags(write=False)
        parts.append((vertices, triangles, None if colour is None else
                      tuple(float(value) / 255.0 for value in np.asarray(colour)[:3])))
    return tuple(parts)


def _box(a: float, b: float, c: float) -> tuple[np.ndarray, np.ndarray]:
    """The 8 corners (±a/2, ±b/2, ±c/2) and 12 triangles, turning outwards."""
    corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]) * [a, b, c]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return corners, np.array([triangle for p, q, r, s in faces for triangle in ((p, q, r), (p, r, s))], np.int64)


def _cylinder(radius: float, length: float) -> tuple[np.ndarray, np.ndarray]:
    """:data:`SEGMENTS` points on each rim (z = ∓l/2), the caps' centres last; sides and fans."""
    angles = 2 * np.pi * np.arange(SEGMENTS) / SEGMENTS
    ring = np.column_stack([radius * np.cos(angles), radius * np.sin(angles), np.zeros(SEGMENTS)])
    vertices = np.concatenate([ring - [0, 0, length / 2], ring + [0, 0, length / 2],
                               [[0, 0, -length / 2], [0, 0, length / 2]]])
    k = np.arange(SEGMENTS)
    following = (k + 1) % SEGMENTS
    bottom, top = 2 * SEGMENTS, 2 * SEGMENTS + 1
    triangles = np.concatenate([np.column_stack([k, following, SEGMENTS + following]),
                                np.column_stack([k, SEGMENTS + following, SEGMENTS + k]),
                                np.column_stack([np.full(SEGMENTS, bottom), following, k]),
                                np.column_stack([np.full(SEGMENTS, top), SEGMENTS + k, SEGMENTS + following])])
    return vertices, triangles.astype(np.int64)


def _sphere(radius: float) -> tuple[np.ndarray, np.ndarray]:
    """A UV sphere: the poles and :data:`SEGMENTS` points on each of SEGMENTS / 2 - 1 parallels."""
    rings = SEGMENTS // 2
    polar = np.pi * np.arange(1, rings) / rings
    azimuth = 2 * np.pi * np.arange(SEGMENTS) / SEGMENTS
    theta, phi = np.meshgrid(polar, azimuth, indexing="ij")
    band = np.column_stack([(np.sin(theta) * np.cos(phi)).ravel(), (np.sin(theta) * np.sin(phi)).ravel(),
                            np.cos(theta).ravel()])
    vertices = radius * np.concatenate([[[0, 0, 1]], band, [[0, 0, -1]]])
    south = len(vertices) - 1
    k = np.arange(SEGMENTS)
    following = (k + 1) % SEGMENTS
    triangles = [np.column_stack([np.zeros(SEGMENTS, np.int64), 1 + k, 1 + following]),
                 np.column_stack([np.full(SEGMENTS, south), 1 + (rings - 2) * SEGMENTS + following,
                                  1 + (rings - 2) * SEGMENTS + k])]
    for ring in range(rings - 2):
        upper, lower = 1 + ring * SEGMENTS, 1 + (ring + 1) * SEGMENTS
        triangles += [np.column_stack([upper + k, lower + k, lower + following]),
                      np.column_stack([upper + k, lower + following, upper + following])]
    return vertices, np.concatenate(triangles).astype(np.int64)


_SHAPES = {"box": _box, "cylinder": _cylinder, "sphere": _sphere}
