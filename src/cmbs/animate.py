"""Animations of a model moving along a :class:`~cmbs.trajectory.Trajectory` (a leaf, like plotting).

    animate(cmbs.load("four-bar"), motion, "four-bar.gif")   # 640 x 480 px, 30 frames per s
"""

from __future__ import annotations

import math
import os
import subprocess
from pathlib import Path
from typing import NamedTuple

import matplotlib

matplotlib.use("Agg")
import matplotlib.animation as animation  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from PIL import Image  # noqa: E402  (a dependency of matplotlib)

from cmbs.errors import CmbsError, did_you_mean  # noqa: E402
from cmbs.files_io import atomic_path, checked_output  # noqa: E402
from cmbs.kinematics import BodyPoses, body_poses, point_array  # noqa: E402
from cmbs.model.model import Model  # noqa: E402
from cmbs.surfaces import Surface, grounded, link_surfaces  # noqa: E402
from cmbs.trajectory import Trajectory  # noqa: E402

#: Most frames an animation gets; longer motions are shown with a lower frame rate.
MAX_FRAMES = 600
#: Figure size in inches; the frames are ``int(FIGURE_SIZE * dpi)`` pixels.
FIGURE_SIZE = (6.4, 4.8)
#: Line styles of the moving figure's segments and of the reference ("ghost") figure under it.
FIGURE_STYLE = {"color": "C0", "linewidth": 2.5, "solid_capstyle": "round"}
GHOST_STYLE = {"color": "0.55", "alpha": 0.5, "linewidth": 5.0, "solid_capstyle": "round"}
#: the light of a surface facing away from the light, as a fraction of its colour (flat shading)
AMBIENT = 0.35


def frame_times(trajectory: Trajectory, *, fps: float = 30, speed: float = 1.0,
                reference: Trajectory | None = None) -> tuple[np.ndarray, float]:
    """The simulated times of the frames and the frame rate they are played at.

    ``count = min(MAX_FRAMES, round(fps * duration / speed) + 1)`` frames, evenly spaced from
    the first to the last time of the trajectory (both included; ``duration`` is their
    difference) or, with a ``reference``, of the interval both cover (from the later start to
    the earlier end).  When the cap applies, the returned frame rate is lowered to
    ``(count - 1) * speed / duration`` so that the playback still lasts ``duration / speed``.

    Raises
    ------
    CmbsError
        Non-positive ``fps``/``speed``, an empty trajectory or reference, times not finite and
        increasing, or a reference that does not overlap the trajectory in time.
    """
    _check_positive(fps=fps, speed=speed)
    start, end = _time_span(trajectory, "trajectory")
    if reference is not None:
        reference_start, reference_end = _time_span(reference, "reference")
        if reference_start > end or reference_end < start:
            raise CmbsError(f"the reference ({reference_start:g} to {reference_end:g} s) does not overlap the "
                            f"trajectory ({start:g} to {end:g} s) in time")
        start, end = max(start, reference_start), min(end, reference_end)
    duration = end - start
    if duration == 0:
        return np.array([start]), float(fps)
    wanted = int(round(fps * duration / speed)) + 1
    count = min(MAX_FRAMES, wanted)
    rate = float(fps) if count == wanted else (count - 1) * speed / duration
    return np.linspace(start, end, count), rate


class Frames(NamedTuple):
    """What an animation shows (:func:`animation_frames`): the simulated ``times`` of its frames,
    the frame ``rate`` they are played at, the model's point positions ``points`` (frames, points,
    2) in the plane (x, z) or (frames, points, 3) in space, those of the reference (``ghost``,
    same shape) or None, and the index of the ``trail`` point or None; for a robot with visual
    geometry its ``surfaces`` (:func:`cmbs.surfaces.link_surfaces`, those of the links that do
    not move in world coordinates: :func:`cmbs.surfaces.grounded`) and the ``poses`` of its
    moving links at the frame times (:func:`cmbs.kinematics.body_poses`), else () and None."""

    times: np.ndarray
    rate: float
    points: np.ndarray
    ghost: np.ndarray | None
    trail: int | None
    surfaces: tuple[Surface, ...] = ()
    poses: BodyPoses | None = None


def animation_frames(model: Model, trajectory: Trajectory, *, fps: float = 30, speed: float = 1.0,
                     trail: str | None = None, reference: Trajectory | None = None) -> Frames:
    """The frames of an animation of ``model`` moving along ``trajectory`` (and ``reference``):
    the frame times of :func:`frame_times`, the coordinates interpolated linearly to them, the
    point positions there (see :func:`animate` for the options).

    Raises
    ------
    CmbsError
        Non-positive ``fps``/``speed``, unknown ``trail`` point, a trajectory or reference of
        another model or with non-finite coordinates or point positions, a reference that does
        not overlap the trajectory in time.
    """
    _check_positive(fps=fps, speed=speed)
    q = _coordinates_of(model, trajectory, "trajectory")
    reference_q = _coordinates_of(model, reference, "reference") if reference is not None else None
    trail_index = None
    if trail is not None:
        if trail not in model.point_names:
            raise CmbsError(f"no point {trail!r}{did_you_mean(trail, model.point_names)} to trail in model "
                            f"{model.name!r}; points: "
                            f"{', '.join(model.point_names) or 'none'}")
        trail_index = model.point_names.index(trail)
    times, rate = frame_times(trajectory, fps=fps, speed=speed, reference=reference)
    frames_q = _interpolated(times, trajectory.t, q)
    points = _points(model, frames_q, "trajectory")
    ghost = _points(model, _interpolated(times, reference.t, reference_q), "reference") \
        if reference is not None else None
    surfaces = grounded(model, link_surfaces(model))
    poses = body_poses(model, frames_q) if surfaces else None
    return Frames(times, rate, points, ghost, trail_index, surfaces, poses)


def label_decimals(times: np.ndarray) -> int:
    """Decimals of the frames' label ``t = 1.23 s``: 2, more when frames are closer than 0.02 s
    apart, so that every frame's label differs."""
    spacing = float(times[1] - times[0]) if times.size > 1 else 1.0
    return max(2, math.ceil(math.log10(2.0 / spacing))) if spacing > 0 else 2


def checked_animation_path(path: str | Path, option: str = "animation") -> Path:
    """``path`` as an animation file that can be written: a .gif, an .html (interactive 3-D
    viewer), or a .mp4 when ffmpeg is found, in an existing folder (CmbsError otherwise; the CLI
    checks it before the run)."""
    path = checked_output(path, (".gif", ".mp4", ".html"), option)
    if path.suffix.lower() == ".mp4" and not animation.writers.is_available("ffmpeg"):
        raise CmbsError(f"{path}: writing .mp4 needs ffmpeg, which was not found; "
                        "install ffmpeg or write a .gif instead (always available)")
    return path


def animate(model: Model, trajectory: Trajectory, path: str | os.PathLike, *, fps: float = 30,
            speed: float = 1.0, trail: str | None = None, dpi: float = 100,
            reference: Trajectory | None = None) -> Path:
    """Draw ``model`` moving along ``trajectory`` into a ``.gif``, ``.mp4`` or ``.html`` file;
    returns its path.

    Each frame shows the model's segments (``model.lines`` between ``model.point_positions``),
    its points, the label ``t = 1.23 s`` (more decimals when frames are closer than 0.02 s
    apart, so that every frame's label differs) and, with ``trail`` (a name from
    ``model.point_names``), the path that point has traced so far.  The axis limits are fixed
    and cover every frame, with equal scales on x and z.  A spatial model (points in 3-D) is
    drawn in a 3-D axis with a fixed view and equal scales on x, y and z.  A robot with visual
    geometry (URDF ``<visual>``: :mod:`cmbs.surfaces`) is drawn as its links' flat-shaded
    triangles over the stick figure, the limits covering them too.

    Reference
        ``reference``, a second motion of the same model (e.g. the recorded motion a simulation
        tracks), is drawn under the moving figure as a wide light-grey "ghost" stick figure at
        the same frame times, with a legend "simulated" / "reference"; the frames then span
        only the time both motions cover, and the axis limits cover both figures.
    Frames
        The coordinates are interpolated linearly between the trajectory's samples to the
        frame times of :func:`frame_times`: ``min(MAX_FRAMES, round(fps * duration / speed) + 1)``
        frames (MAX_FRAMES = 600), the first at the first sample and the last at the last
        (of the common interval, with a reference).
        ``speed`` > 1 plays faster than real time.  Motions that would need more than 600
        frames are played at a lower frame rate instead (same playback length), so a long run
        still takes seconds to write.  A 5-s motion at 30 fps gives 151 frames.
        The coordinates are taken as continuous in time (angles not wrapped to ±π).
    Size
        ``int(6.4 * dpi)`` x ``int(4.8 * dpi)`` pixels, rounded down (640 x 480 at the default
        dpi 100); an mp4 is padded by a pixel to even sizes where needed.  A GIF's frames are
        held in memory until written: about width x height bytes each (600 frames of 640 x 480:
        185 MB).  Writing takes about 10 ms per frame at the default size.
    Formats (by extension)
        ``.gif``: always available (matplotlib's PillowWriter).  GIF stores frame delays in
        hundredths of a second, so the frame rate is approximate, and viewers play rates above
        50 fps slower.  ``.mp4``: needs ffmpeg (``matplotlib.animation.writers.is_available
        ("ffmpeg")``); without it a :class:`CmbsError` suggests ``.gif``.  ``.html``: an
        interactive viewer in one self-contained file (:func:`cmbs.viewer_html.write_viewer`:
        play/pause, a time slider, a camera to orbit and zoom; the same frames, ``dpi`` unused).
        Anything else is a :class:`CmbsError`.
    Files
        Written atomically: to a temporary file in the destination folder, renamed on success,
        so a failed write leaves neither a partial file nor a changed old one.

    Raises
    ------
    CmbsError
        Bad extension, missing folder, mp4 without ffmpeg, non-positive ``fps``/``speed``/
        ``dpi``, unknown ``trail`` point, a trajectory or reference of another model or with
        non-finite coordinates, a reference that does not overlap the trajectory in time, or a
        failed write.
    """
    path = checked_animation_path(path)
    _check_positive(dpi=dpi)
    frames = animation_frames(model, trajectory, fps=fps, speed=speed, trail=trail, reference=reference)
    if path.suffix.lower() == ".html":
        from cmbs.viewer_html import write_viewer

        return write_viewer(model, frames, path)
    mp4 = path.suffix.lower() == ".mp4"
    times, rate, points, ghost, trail_index = frames[:5]
    decimals = label_decimals(times)

    spatial = points.shape[2] == 3
    everything = points if ghost is None else np.concatenate([points, ghost], axis=1)
    shaded = _Shaded(frames.surfaces, frames.poses) if spatial and frames.surfaces else None
    if shaded is not None:
        everything = np.concatenate([everything, shaded.extent(times.size)], axis=1)
    figure = plt.figure(figsize=FIGURE_SIZE, dpi=dpi)
    try:
        if spatial:
            axis = figure.add_subplot(projection="3d")
            _cube_limits(axis, everything)
            axis.set(xlabel="x", ylabel="y", zlabel="z")
        else:
            axis = figure.add_axes((0.1, 0.1, 0.85, 0.8))
            _fixed_limits(axis, figure, everything)
            axis.set_xlabel("x")
            axis.set_ylabel("z")
            axis.grid(alpha=0.3)
        axis.set_title(model.name + (f" (trail of {trail})" if trail_index is not None else ""))
        empty = ([], [], []) if spatial else ([], [])
        trail_line = axis.plot(*empty, "-", color="C1", linewidth=1.2)[0] if trail_index is not None else None
        ghosts = [] if ghost is None else [axis.plot(*empty, "-", gid="reference", **GHOST_STYLE)[0]
                                           for _ in model.lines]
        segments = [axis.plot(*empty, "-", gid="trajectory", **FIGURE_STYLE)[0] for _ in model.lines]
        dots = axis.plot(*empty, "o", color="k", markersize=4, zorder=3)[0]
        text = axis.text2D if spatial else axis.text
        label = text(0.02, 0.96, "", transform=axis.transAxes, va="top", family="monospace")
        if ghost is not None:
            axis.legend([Line2D([], [], **FIGURE_STYLE), Line2D([], [], **GHOST_STYLE)], ["simulated", "reference"],
                        loc="upper right")

        if shaded is not None:
            axis.add_collection3d(shaded.collection)
        # the stick figure under the surfaces, the trail over them
        moving = [artist for artist in (*ghosts, *segments, dots, shaded and shaded.collection, trail_line, label)
                  if artist is not None]

        def pose(frame: int) -> None:
            here = points[frame]
            for line, (i, j) in zip(segments, model.lines):
                _place(line, here[[i, j]])
            for line, (i, j) in zip(ghosts, model.lines):
                _place(line, ghost[frame][[i, j]])
            _place(dots, here)
            if shaded is not None:
                shaded.pose(frame, axis)
            if trail_line is not None:
                _place(trail_line, points[:frame + 1, trail_index])
            label.set_text(f"t = {times[frame]:.{decimals}f} s")

        # Blitting: the axes, ticks and grid are drawn once; each frame redraws only the moving
        # artists over that background and hands the canvas to the writer (no savefig per frame).
        for artist in moving:
            artist.set_animated(True)
        figure.canvas.draw()
        background = figure.canvas.copy_from_bbox(figure.bbox)

        def draw(frame: int) -> None:
            pose(frame)
            figure.canvas.restore_region(background)
            for artist in moving:
                if shaded is not None and artist is shaded.collection:
                    artist.do_3d_projection()             # sorts the triangles by depth (Axes3D.draw does it)
                axis.draw_artist(artist)

        if mp4:
            # yuv420p (set by matplotlib for h264) needs even sizes: pad odd ones by a pixel
            writer = _BlitFFMpegWriter(fps=rate, extra_args=["-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2"])
        else:
            writer = _BlitPillowWriter(fps=rate)
            draw(times.size - 1)  # every colour appears in the last frame (full trail)
            writer.choose_palette(figure)
        with atomic_path(path) as temporary:
            with writer.saving(figure, temporary, dpi):
                for frame in range(times.size):
                    draw(frame)
                    writer.grab_canvas()
    except (OSError, subprocess.CalledProcessError) as error:
        raise CmbsError(f"{path}: writing the animation failed ({error})") from None
    finally:
        plt.close(figure)
    return path


class _Shaded:
    """A robot's surfaces (:attr:`Frames.surfaces`) in a 3-D axis: one ``Poly3DCollection`` of all
    their triangles, placed at each frame by the link poses (p_world = o + R p), depth-sorted by
    matplotlib (painter's algorithm on the triangles' mean depth) and flat-shaded: a triangle of
    colour c with unit normal n is drawn ``c (a + (1 - a) |n · l|)``, a = :data:`AMBIENT`, l the
    unit direction from the scene to the viewer (a light at the eye)."""

    def __init__(self, surfaces: tuple[Surface, ...], poses: BodyPoses):
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection

        self.surfaces, self.poses = surfaces, poses
        self.index = {name: k for k, name in enumerate(poses.names)}
        self.colours = np.concatenate([np.tile(surface.colour, (len(surface.triangles), 1)) for surface in surfaces])
        self.collection = Poly3DCollection(np.zeros((0, 3, 3)), linewidths=0.3, gid="surfaces")

    def placed(self, frame: int) -> list[np.ndarray]:
        """The surfaces' vertices in world coordinates at ``frame``."""
        placed = []
        for surface in self.surfaces:
            if surface.link is None:
                placed.append(surface.vertices)
            else:
                k = self.index[surface.link]
                placed.append(surface.vertices @ self.poses.rotations[frame, k].T + self.poses.origins[frame, k])
        return placed

    def extent(self, count: int) -> np.ndarray:
        """(count, 2, 3): the corners of the box around the vertices at each frame."""
        boxes = []
        for frame in range(count):
            vertices = np.concatenate(self.placed(frame))
            boxes.append([vertices.min(axis=0), vertices.max(axis=0)])
        return np.array(boxes)

    def pose(self, frame: int, axis: plt.Axes) -> None:
        """The triangles at ``frame``, shaded for the axis' view."""
        corners = np.concatenate([vertices[surface.triangles]
                                  for vertices, surface in zip(self.placed(frame), self.surfaces)])
        normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        lengths = np.linalg.norm(normals, axis=1)
        normals /= np.where(lengths > 0, lengths, 1.0)[:, None]
        elevation, azimuth = np.radians(axis.elev), np.radians(axis.azim)
        eye = np.array([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
        light = AMBIENT + (1 - AMBIENT) * np.abs(normals @ eye)
        colours = np.clip(self.colours * light[:, None], 0.0, 1.0)
        self.collection.set_verts(corners)
        self.collection.set_facecolor(colours)
        self.collection.set_edgecolor(colours)         # no hairline gaps between neighbouring triangles


class _BlitPillowWriter(animation.PillowWriter):
    """matplotlib's PillowWriter, fed from the figure's canvas as it stands (after blitting)
    instead of a full ``savefig`` per frame.  Frames are kept as palette images (what a GIF
    stores anyway; a third of the memory of RGB) sharing one 256-colour palette taken from a
    reference frame, which is quicker than quantizing every frame and keeps colours steady."""

    palette: Image.Image | None = None

    @staticmethod
    def _canvas_image(figure: plt.Figure) -> Image.Image:
        canvas = figure.canvas
        width, height = canvas.get_width_height()
        return Image.frombuffer("RGBA", (width, height), bytes(canvas.buffer_rgba()), "raw", "RGBA", 0, 1) \
            .convert("RGB")

    def choose_palette(self, figure: plt.Figure) -> None:
        """Take the palette from the figure's canvas as it stands now."""
        self.palette = self._canvas_image(figure).quantize(256, method=Image.Quantize.FASTOCTREE)

    def grab_canvas(self) -> None:
        image = self._canvas_image(self.fig)
        self._frames.append(image.quantize(palette=self.palette, dither=Image.Dither.NONE) if self.palette
                            else image.quantize(256, method=Image.Quantize.FASTOCTREE))


class _BlitFFMpegWriter(animation.FFMpegWriter):
    """matplotlib's FFMpegWriter, fed the figure's canvas pixels (RGBA) as they stand after
    blitting instead of a full ``savefig`` per frame."""

    def grab_canvas(self) -> None:
        canvas = self.fig.canvas
        if canvas.get_width_height() != self.frame_size:
            raise CmbsError(f"canvas size {canvas.get_width_height()} differs from the video's {self.frame_size}")
        self._proc.stdin.write(bytes(canvas.buffer_rgba()))


def _coordinates_of(model: Model, trajectory: Trajectory, what: str) -> np.ndarray:
    """The q of ``trajectory`` (called ``what`` in messages) with columns in the model's
    coordinate order."""
    if set(trajectory.names) != set(model.coordinate_names) or len(trajectory.names) != model.n:
        raise CmbsError(f"the {what}'s coordinates ({', '.join(trajectory.names)}) are not those of model "
                        f"{model.name!r} ({', '.join(model.coordinate_names)})")
    q = np.asarray(trajectory.q, dtype=float)[:, [trajectory.names.index(name) for name in model.coordinate_names]]
    if not np.all(np.isfinite(q)):
        raise CmbsError(f"cannot animate a {what} with non-finite coordinates")
    return q


def _time_span(trajectory: Trajectory, what: str) -> tuple[float, float]:
    """First and last time of ``trajectory`` (called ``what`` in messages), checked."""
    t = np.asarray(trajectory.t, dtype=float)
    if t.size == 0:
        raise CmbsError(f"cannot animate an empty {what} (no samples)")
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0):
        raise CmbsError(f"cannot animate a {what} whose times are not finite and increasing")
    return float(t[0]), float(t[-1])


def _interpolated(times: np.ndarray, sample_times: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(frames, n): the coordinates ``q`` (samples, n) interpolated linearly between
    ``sample_times`` to ``times``."""
    return np.column_stack([np.interp(times, sample_times, column) for column in q.T]) \
        if q.shape[1] else np.zeros((times.size, 0))


def _points(model: Model, frames_q: np.ndarray, what: str) -> np.ndarray:
    """(frames, points, 2) point positions (x, z) at the coordinates ``frames_q``, (frames,
    points, 3) for a spatial model."""
    points = np.array([point_array(model, row) for row in frames_q])
    if not np.all(np.isfinite(points)):
        raise CmbsError(f"cannot animate model {model.name!r}: non-finite point positions along the {what}")
    return points


def _place(line: Line2D, rows: np.ndarray) -> None:
    """Put ``line`` through the points ``rows`` (k, 2) in the plane (x, z) or (k, 3) in space."""
    if rows.shape[1] == 3:
        line.set_data_3d(rows[:, 0], rows[:, 1], rows[:, 2])
    else:
        line.set_data(rows[:, 0], rows[:, 1])


def _cube_limits(axis: plt.Axes, points: np.ndarray) -> None:
    """Limits of a 3-D axis: the cube around every frame's points with a margin, so that x, y
    and z have the same scale; the view stays fixed."""
    rows = points.reshape(-1, 3)
    low, high = rows.min(axis=0), rows.max(axis=0)
    half = 0.54 * float(max(high - low)) if float(max(high - low)) > 0 else 0.5 * max(1.0, float(np.abs(low).max()))
    for centre, limits in zip(0.5 * (low + high), (axis.set_xlim, axis.set_ylim, axis.set_zlim)):
        limits(centre - half, centre + half)
    axis.set_box_aspect((1.0, 1.0, 1.0))
    axis.set_autoscale_on(False)


def _fixed_limits(axis: plt.Axes, figure: plt.Figure, points: np.ndarray) -> None:
    """Limits covering every frame's points with a margin, widened to the axes' shape so that
    x and z have the same scale."""
    low, high = points.reshape(-1, 2).min(axis=0), points.reshape(-1, 2).max(axis=0)
    size = float(max(high - low))
    margin = 0.08 * size if size > 0 else 0.5 * max(1.0, float(np.max(np.abs(low))))
    low, high = low - margin, high + margin
    box = axis.get_position()
    width, height = box.width * figure.get_figwidth(), box.height * figure.get_figheight()
    center, span = (low + high) / 2, high - low
    if span[0] / span[1] < width / height:
        span[0] = span[1] * width / height
    else:
        span[1] = span[0] * height / width
    axis.set_xlim(center[0] - span[0] / 2, center[0] + span[0] / 2)
    axis.set_ylim(center[1] - span[1] / 2, center[1] + span[1] / 2)
    axis.set_aspect("equal", adjustable="datalim")
    axis.set_autoscale_on(False)


def _check_positive(**values: float) -> None:
    for name, value in values.items():
        if not (isinstance(value, (int, float, np.integer, np.floating)) and math.isfinite(value) and value > 0):
            raise CmbsError(f"{name} must be a positive number, got {value!r}")
