"""Animations with a reference ("ghost") figure: drawn at the reference's interpolated pose in
every frame, frames over the common time only, limits covering both, clear refusals."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

import cmbs
from cmbs import animate as animate_module
from cmbs.animate import animate, frame_times
from cmbs.errors import CmbsError
from cmbs.simulate import simulate
from cmbs.trajectory import Trajectory

SHIFT = 0.3     # the reference is the same run, 0.3 s later


@pytest.fixture(scope="module")
def pendulum():
    model = cmbs.load("double-pendulum")
    return model, simulate(model, t_end=1.0, dt=0.01)


def shifted(run, dt=SHIFT, dx=0.0):
    """The run delayed by ``dt``, its point x coordinates moved by ``dx``."""
    q = run.q.copy()
    q[:, [run.names.index(name) for name in run.names if name.endswith(".x")]] += dx
    return Trajectory(run.t + dt, q, run.qd, run.qdd, run.names)


def poses(model, run, times):
    """(frames, points, 2) of ``run`` at ``times``, interpolated here independently."""
    q = np.column_stack([np.interp(times, run.t, column) for column in run.q.T])
    return np.array([model.point_positions(row) for row in q])


def capture_frames(monkeypatch):
    """Record, at every frame handed to the GIF writer, the data of the figure's lines by gid,
    the legend's texts and the axis limits."""
    frames = []
    grab = animate_module._BlitPillowWriter.grab_canvas

    def recording(self):
        axis = self.fig.axes[0]
        lines = {gid: [np.array(line.get_data()).T for line in axis.get_lines() if line.get_gid() == gid]
                 for gid in ("trajectory", "reference")}
        legend = axis.get_legend()
        frames.append({**lines, "legend": [text.get_text() for text in legend.get_texts()] if legend else [],
                       "limits": (axis.get_xlim(), axis.get_ylim())})
        grab(self)

    monkeypatch.setattr(animate_module._BlitPillowWriter, "grab_canvas", recording)
    return frames


def test_ghost_is_drawn_at_the_interpolated_reference_pose(monkeypatch, pendulum, tmp_path):
    model, run = pendulum
    reference = shifted(run)
    frames = capture_frames(monkeypatch)
    path = animate(model, run, tmp_path / "ghost.gif", fps=20, dpi=30, reference=reference)
    times = np.linspace(SHIFT, 1.0, 15)                  # common interval 0.7 s at 20 fps: 15 frames
    assert np.allclose(frame_times(run, fps=20, reference=reference)[0], times)
    with Image.open(path) as image:
        assert image.n_frames == 15
    assert len(frames) == 15
    expected_ghost, expected_figure = poses(model, reference, times), poses(model, run, times)
    assert np.abs(expected_ghost - expected_figure).max() > 0.3    # the two figures differ
    for frame, ghost, figure in zip(frames, expected_ghost, expected_figure):
        assert len(frame["reference"]) == len(frame["trajectory"]) == len(model.lines)
        for (i, j), drawn_ghost, drawn_figure in zip(model.lines, frame["reference"], frame["trajectory"]):
            assert np.allclose(drawn_ghost, ghost[[i, j]], atol=1e-12)
            assert np.allclose(drawn_figure, figure[[i, j]], atol=1e-12)
        assert frame["legend"] == ["simulated", "reference"]


def test_limits_cover_both_figures(monkeypatch, pendulum, tmp_path):
    model, run = pendulum
    reference = shifted(run, dt=0.0, dx=3.0)             # a ghost 3 m to the right
    frames = capture_frames(monkeypatch)
    animate(model, run, tmp_path / "ghost.gif", fps=10, dpi=30, reference=reference)
    (x0, x1), (z0, z1) = frames[0]["limits"]
    for points in (poses(model, run, run.t), poses(model, reference, run.t)):
        assert x0 < points[..., 0].min() and points[..., 0].max() < x1
        assert z0 < points[..., 1].min() and points[..., 1].max() < z1


def test_without_reference_nothing_changes(monkeypatch, pendulum, tmp_path):
    model, run = pendulum
    frames = capture_frames(monkeypatch)
    animate(model, run, tmp_path / "plain.gif", fps=10, dpi=30)
    assert len(frames) == 11 and all(frame["reference"] == [] and frame["legend"] == [] for frame in frames)


@pytest.mark.parametrize("reference, message", [
    (lambda run: shifted(run, dt=2.0), r"reference \(2 to 3 s\) does not overlap the trajectory \(0 to 1 s\)"),
    (lambda run: Trajectory(run.t, run.q[:, :4], run.qd[:, :4], run.qdd[:, :4], run.names[:4]),
     "the reference's coordinates .* are not those of model 'double-pendulum'"),
    (lambda run: Trajectory(run.t, run.q * np.nan, run.qd, run.qdd, run.names),
     "cannot animate a reference with non-finite coordinates"),
    (lambda run: Trajectory(run.t[:0], run.q[:0], run.qd[:0], run.qdd[:0], run.names),
     "cannot animate an empty reference"),
])
def test_bad_references_are_refused_before_writing(pendulum, tmp_path, reference, message):
    model, run = pendulum
    with pytest.raises(CmbsError, match=message):
        animate(model, run, tmp_path / "ghost.gif", reference=reference(run))
    assert list(tmp_path.iterdir()) == []


def test_touching_intervals_give_one_frame(pendulum):
    _, run = pendulum
    times, rate = frame_times(run, fps=25, reference=shifted(run, dt=1.0))
    assert np.array_equal(times, [1.0]) and rate == 25
