"""An interactive 3-D viewer of a model's motion in one self-contained HTML file (a leaf, like
:mod:`cmbs.animate`, whose frames it shows):

    animate(cmbs.load("bricard"), run, "bricard.html")   # or: cmbs simulate ... --animate bricard.html

The file is the template ``viewer.html`` (package data: a small hand-written canvas renderer,
no library, nothing fetched from the network) with the frames embedded as JSON in a
``<script id="cmbs-data" type="application/json">`` element.  In a browser it draws the
mechanism in perspective (equal scales) with the segments as thick lines and the points as dots,
depth-sorted, the ground points (those whose position does not depend on the coordinates) as
grey triangles, a grey floor grid across the "up" direction, an x/y/z axis triad, the trail of
one point and a reference ("ghost") figure when given.  Controls: play/pause (space), a time
slider with the label ``t = 1.23 s`` (arrow keys step a frame), mouse drag to orbit, wheel to
zoom, double-click to reset the view.  The address fragment ``#t=1.5`` opens the file paused at
the frame nearest t = 1.5 s; without it the motion plays in a loop.

Planar models (points (x, z)) are shown in the plane y = 0 of the same 3-D view, looked at
along +y (x to the right, z up, as in the GIF), and can be orbited like a spatial one.

JSON fields (format ``cmbs-viewer 1``): ``model``, ``planar``, ``up`` (unit vector: against
gravity for a spatial model, z when it has none and in the plane), ``points`` (names), ``ground``
(a flag per point), ``lines`` (index pairs), ``trail`` (point index or null), ``times`` (s),
``rate`` (frames per second of playback), ``decimals`` (of the time label), ``unit`` (m) and
``frames``: per frame the integers round(x / unit), round(y / unit), round(z / unit) of each
point in turn; ``ghost`` the same for the reference, or null.  ``unit`` is the power of ten at
most 1e-4 of the model's size (the diagonal of the box around every frame), so that positions are
kept to better than 1e-4 of the size and the file stays small (bricard over 10 s at 30 frames
per second: about 40 kB).

Format ``cmbs-viewer 2``, written for a robot with visual geometry (:mod:`cmbs.surfaces`):
format 1 and ``surfaces``, each ``{"link", "colour", "vertices", "triangles"}``: the index of its
link in ``points`` (null: fixed to the ground, the vertices in world coordinates), its colour
(red, green, blue, 0 to 255), its vertices in the link frame as the integers round(x / unit),
round(y / unit), round(z / unit) in turn and its triangles as vertex indices, three at a time;
``turning``, the links that carry surfaces and move (indices in ``points``); ``quaternionUnit``
(1e-5) and ``rotations``: per frame, for each link of ``turning`` in turn, its frame's rotation
as the quaternion (w, x, y, z) / quaternionUnit rounded.  The surfaces are sent once, the link
poses per frame (a link's origin is its point): a vertex p of a link at origin o and rotation R
is drawn at o + R p.  They are drawn flat-shaded, colour c (a + (1 - a) |n · l|) with a = 0.35,
n the triangle's unit normal and l the unit direction to the eye, depth-sorted over the stick
figure (which a check box puts in front).  The UR5 with its seven COLLADA meshes (about 6,700
triangles) over 2 s at 30 frames per second: about 155 kB; the Panda's eleven: about 250 kB.
"""

from __future__ import annotations

import html
import json
import math
from importlib import resources
from pathlib import Path

import numpy as np

from cmbs.animate import Frames, label_decimals
from cmbs.errors import CmbsError
from cmbs.files_io import atomic_path, checked_output
from cmbs.kinematics import BodyPoses, point_array
from cmbs.model.model import Model, base_equations
from cmbs.surfaces import Surface

#: the template in the package, and the markers in it replaced by the title and the JSON
TEMPLATE = "viewer.html"
TITLE_MARK = "__CMBS_TITLE__"
DATA_MARK = "__CMBS_DATA__"
#: positions are rounded to a power of ten at most this fraction of the model's size
RESOLUTION = 1e-4
FORMAT = "cmbs-viewer 1"
#: the format of a file with surfaces: format 1 and the surface fields (module docstring)
FORMAT_SURFACES = "cmbs-viewer 2"
#: the quaternions of the link rotations are rounded to this
QUATERNION_UNIT = 1e-5


def ground_points(model: Model) -> list[bool]:
    """For each of ``model.point_names``, whether it is a ground point: its position does not
    depend on the coordinates (the same, to 1e-12 of its size, at q0 and at q0 moved by 0.1 and
    by -0.07 to -0.14 in every coordinate)."""
    q0 = np.array(model.q0, dtype=float)
    steps = np.arange(1, model.n + 1) / max(model.n, 1)
    base = point_array(model, q0)
    same = np.ones(len(base), dtype=bool)
    for moved in (q0 + 0.1, q0 - 0.07 * (1.0 + steps)):
        with np.errstate(all="ignore"):
            there = point_array(model, moved)
        same &= np.all(np.abs(there - base) <= 1e-12 * (1.0 + np.abs(base)), axis=1)
    return [bool(flag) for flag in same]


def up_direction(model: Model, spatial: bool) -> list[float]:
    """The viewer's "up": against gravity for a spatial model with gravity, else z (the plane's
    vertical for a planar model)."""
    gravity = np.array(getattr(base_equations(model)[0], "gravity", (0.0, 0.0, 0.0)), dtype=float) if spatial \
        else np.zeros(3)
    size = float(np.linalg.norm(gravity))
    return [float(value) for value in (-gravity / size if size > 0 else np.array([0.0, 0.0, 1.0]))]


def viewer_data(model: Model, frames: Frames) -> dict:
    """The JSON object the viewer shows (module docstring): ``frames`` of
    :func:`cmbs.animate.animation_frames`, planar points put in the plane y = 0."""
    planar = frames.points.shape[2] == 2

    def spatial(points: np.ndarray) -> np.ndarray:
        return np.insert(points, 1, 0.0, axis=2) if planar else points

    points = spatial(frames.points)
    ghost = spatial(frames.ghost) if frames.ghost is not None else None
    everything = (points if ghost is None else np.concatenate([points, ghost], axis=1)).reshape(-1, 3)
    size = float(np.linalg.norm(np.ptp(everything, axis=0))) if everything.size else 0.0
    scale = size if size > 0 else max(1.0, float(np.abs(everything).max(initial=0.0)))
    unit = 10.0 ** math.floor(math.log10(RESOLUTION * scale))

    def integers(values: np.ndarray) -> list[list[int]]:
        return np.rint(values / unit).astype(np.int64).reshape(len(values), -1).tolist()

    data = {"format": FORMAT, "model": model.name, "planar": planar, "up": up_direction(model, not planar),
            "points": list(model.point_names), "ground": ground_points(model),
            "lines": [[int(i), int(j)] for i, j in model.lines], "trail": frames.trail,
            "times": [float(f"{t:.9g}") for t in frames.times], "rate": float(f"{frames.rate:.9g}"),
            "decimals": label_decimals(frames.times), "unit": unit, "frames": integers(points),
            "ghost": integers(ghost) if ghost is not None else None}
    if frames.surfaces and frames.poses is not None:
        data.update(surface_data(model, frames.surfaces, frames.poses, unit), format=FORMAT_SURFACES)
    return data


def surface_data(model: Model, surfaces: tuple[Surface, ...], poses: BodyPoses, unit: float) -> dict:
    """The fields of format ``cmbs-viewer 2`` (module docstring) for a robot's ``surfaces``
    (:attr:`cmbs.animate.Frames.surfaces`) and the ``poses`` of its moving links at the frames;
    links are named by their index in ``model.point_names`` (a robot's points are its links)."""
    points = list(model.point_names)
    turning = [name for name in poses.names if any(surface.link == name for surface in surfaces)]
    columns = [poses.names.index(name) for name in turning]
    rotations = np.rint(poses.quaternions[:, columns] / QUATERNION_UNIT).astype(np.int64)
    return {"surfaces": [{"link": None if surface.link is None else points.index(surface.link),
                          "colour": [int(round(255 * value)) for value in surface.colour],
                          "vertices": np.rint(surface.vertices / unit).astype(np.int64).ravel().tolist(),
                          "triangles": surface.triangles.ravel().tolist()} for surface in surfaces],
            "turning": [points.index(name) for name in turning], "quaternionUnit": QUATERNION_UNIT,
            "rotations": rotations.reshape(len(rotations), -1).tolist()}


def viewer_page(model: Model, frames: Frames) -> str:
    """The HTML text of the viewer of ``frames`` (:func:`viewer_data` in the template)."""
    template = resources.files("cmbs").joinpath(TEMPLATE).read_text(encoding="utf-8")
    payload = json.dumps(viewer_data(model, frames), separators=(",", ":"), allow_nan=False)
    # "<" only occurs in strings (names): as \u003c no name can close the script element
    payload = payload.replace("<", "\\u003c")
    return template.replace(TITLE_MARK, html.escape(model.name)).replace(DATA_MARK, payload)


def write_viewer(model: Model, frames: Frames, path: str | Path) -> Path:
    """Write the viewer of ``frames`` (:func:`cmbs.animate.animation_frames`) to the ``.html`` file
    ``path`` atomically (temporary file, then rename); returns its path.

    Raises
    ------
    CmbsError
        ``path`` does not end in .html, its folder is missing, or the write fails.
    """
    path = checked_output(path, (".html",), "viewer")
    page = viewer_page(model, frames)
    try:
        with atomic_path(path) as temporary:
            Path(temporary).write_text(page, encoding="utf-8")
    except OSError as error:
        raise CmbsError(f"{path}: writing the viewer failed ({error.strerror or error})") from None
    return path
