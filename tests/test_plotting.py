"""Figures (plot_simulation, plot_trajectory) and animations (GIF, mp4), written atomically."""

import matplotlib
import matplotlib.animation
import matplotlib.pyplot as plt
import numpy as np
import pytest
from PIL import Image

import cmbs
from cmbs import animate as animate_module
from cmbs.animate import MAX_FRAMES, animate, frame_times
from cmbs.errors import CmbsError
from cmbs.plotting import plot_simulation, plot_trajectory, save_figure
from cmbs.simulate import simulate
from cmbs.trajectory import Trajectory

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def pendulum():
    model = cmbs.load("double-pendulum")
    return model, simulate(model, t_end=1.0, dt=0.01)


@pytest.fixture(scope="module")
def four_bar():
    model = cmbs.load("four-bar")
    return model, cmbs.kinematic_analysis(model, np.linspace(0.0, 1.0, 51))


def synthetic(n=2, k=11, extras=None, info=None):
    t = np.linspace(0.0, 1.0, k)
    q = np.column_stack([np.sin(t + j) for j in range(n)])
    return Trajectory(t, q, np.cos(q), -q, tuple(f"c{j}" for j in range(n)), extras or {}, info or {})


def titles(figure):
    return [axis.get_title() for axis in figure.axes]


# ------------------------------------------------------------------ plot_simulation
def test_simulation_figure_saved_as_png(pendulum, tmp_path):
    model, run = pendulum
    figure = plot_simulation(run, model=model)
    names = titles(figure)
    assert len(figure.axes) == 6  # coordinates in m, in rad, energy, energy drift, constraint errors, mechanism
    assert names[:2] == ["coordinates [m]", "coordinates [rad]"]
    assert names[2].startswith("total energy") and names[3].startswith("energy drift")
    assert names[3].endswith(f"J\n= {run.info['energy_drift']:.2g} of the largest kinetic energy")  # conservative
    assert names[4].startswith("constraint errors (log)") and figure.axes[4].get_yscale() == "log"
    assert names[5] == "mechanism (x, z)"
    assert len(figure.axes[0].lines) + len(figure.axes[1].lines) == model.n
    drift = figure.axes[3].lines[0].get_ydata()
    np.testing.assert_allclose(drift, run.extras["energy"] - run.extras["energy"][0])
    path = save_figure(figure, tmp_path / "run.png")
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    with Image.open(path) as image:
        assert image.format == "PNG" and image.size[0] > image.size[1] > 100
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.png"]


def test_exact_zeros_are_left_out_and_counted(pendulum):
    model, run = pendulum
    assert run.extras["velocity_constraint_error"][0] == 0.0  # consistent initial velocities
    axis = plot_simulation(run).axes[3]           # without a model: one panel of coordinates
    labels = [line.get_label() for line in axis.lines]
    assert any("velocity" in label and "(1 exact zero not shown)" in label for label in labels)
    velocity = next(line for line in axis.lines if "velocity" in line.get_label())
    shown = np.asarray(velocity.get_ydata(), dtype=float)
    assert np.isnan(shown[0]) and np.all(shown[1:] > 0)
    plt.close("all")


def test_all_zero_constraint_error_is_said_in_the_title():
    zeros, small = np.zeros(11), np.linspace(1e-12, 1e-10, 11)
    figure = plot_simulation(synthetic(extras={"constraint_error": zeros, "velocity_constraint_error": small}))
    axis = figure.axes[1]  # after the coordinates
    assert "position: all exactly 0" in axis.get_title() and axis.get_yscale() == "log"
    assert [line.get_label().split()[0] for line in axis.lines] == ["velocity"]
    both = plot_simulation(synthetic(extras={"constraint_error": zeros, "velocity_constraint_error": zeros})).axes[1]
    assert "position: all exactly 0" in both.get_title() and "velocity: all exactly 0" in both.get_title()
    assert both.get_yscale() == "linear"
    plt.close("all")


def test_missing_extras_leave_panels_out_and_many_coordinates_are_capped():
    figure = plot_simulation(synthetic(n=10))
    assert len(figure.axes) == 1
    assert "first 8 of 10" in figure.axes[0].get_title() and len(figure.axes[0].lines) == 8
    chosen = plot_simulation(synthetic(n=10), coordinates=["c9", "c0"])
    assert len(chosen.axes[0].lines) == 2 and "first" not in chosen.axes[0].get_title()
    energy_only = plot_simulation(synthetic(extras={"energy": np.ones(11)}))
    assert len(energy_only.axes) == 3
    plt.close("all")


def test_failed_run_and_bad_coordinates():
    failed = plot_simulation(synthetic(info={"model": "m", "status": "failed", "message": "singular"}))
    assert "FAILED at t = 1 s: singular" in failed.get_suptitle()
    with pytest.raises(CmbsError, match="no coordinate"):
        plot_simulation(synthetic(), coordinates=["nope"])
    with pytest.raises(CmbsError, match="no coordinates chosen"):
        plot_simulation(synthetic(), coordinates=[])
    plt.close("all")


def test_kinematics_without_energy_still_plots(four_bar, tmp_path):
    model, motion = four_bar
    assert "energy" not in motion.extras
    figure = plot_simulation(motion, model=model)
    assert titles(figure) == ["coordinates [m]", "coordinates [rad]", "mechanism (x, z)"]
    assert save_figure(figure, tmp_path / "kin.png").read_bytes()[:8] == PNG_SIGNATURE
    old = plot_trajectory(motion, model=model)  # the kinematics CLI's figure
    assert len(old.axes) == 7          # position, velocity, acceleration in m and in rad; the mechanism
    assert save_figure(old, tmp_path / "old.svg").read_text().lstrip().startswith("<?xml")


# ------------------------------------------------------------------ animations
def test_gif_frame_count_and_size(pendulum, tmp_path):
    model, run = pendulum
    times, rate = frame_times(run, fps=20)
    assert len(times) == 21 and rate == 20  # round(20 * 1.0 / 1) + 1
    path = animate(model, run, tmp_path / "run.gif", fps=20, dpi=40, trail="P2")
    with Image.open(path) as image:
        assert image.format == "GIF"
        assert image.n_frames == 21
        assert image.size == (256, 192)  # int(6.4 * 40) x int(4.8 * 40)
        assert image.info["duration"] == 50  # 1000 / 20 ms
    assert [p.name for p in tmp_path.iterdir()] == ["run.gif"]


def segment_pixels(image):
    """(rows, columns) of the pixels in the segments' colour (matplotlib's C0 blue)."""
    rgb = np.asarray(image.convert("RGB"), dtype=int)
    return np.nonzero(np.abs(rgb - [31, 119, 180]).sum(axis=-1) < 60)


def test_gif_limits_cover_the_whole_motion(pendulum, tmp_path):
    model, run = pendulum
    path = animate(model, run, tmp_path / "run.gif", fps=10, dpi=40)
    # the axes occupy (0.1, 0.1, 0.85, 0.8) of the 256 x 192 figure
    left, right, top, bottom = 0.1 * 256, 0.95 * 256, 0.1 * 192, 0.9 * 192
    columns, rows = [], []
    with Image.open(path) as image:
        for frame in range(image.n_frames):
            image.seek(frame)
            r, c = segment_pixels(image)
            assert r.size > 20  # the mechanism is drawn ...
            assert c.min() > left + 2 and c.max() < right - 2  # ... and never clipped
            assert r.min() > top + 2 and r.max() < bottom - 2
            columns.extend([c.min(), c.max()])
            rows.extend([r.min(), r.max()])
    # the limits are no wider than needed: the motion fills the box in one direction
    assert max((max(columns) - min(columns)) / (right - left), (max(rows) - min(rows)) / (bottom - top)) > 0.7


def test_slow_motion_frames_stay_distinct(pendulum, tmp_path):
    # A mechanism at rest, 0.2 s at speed 0.1 and 30 fps: 61 frames 3.3 ms apart.  Only the time
    # label changes; with two-decimal labels Pillow would merge frames that repeat.
    model, run = pendulum
    still = np.repeat(run.q[:1], 21, axis=0)
    short = Trajectory(run.t[:21], still, 0 * still, 0 * still, run.names)
    with Image.open(animate(model, short, tmp_path / "slow.gif", speed=0.1, dpi=30)) as image:
        assert image.n_frames == 61


def test_long_runs_are_capped_at_a_lower_frame_rate(monkeypatch, tmp_path):
    model = cmbs.load("four-bar")
    motion = cmbs.kinematic_analysis(model, np.linspace(0.0, 100.0, 201))
    times, rate = frame_times(motion, fps=30)
    assert len(times) == MAX_FRAMES and rate == pytest.approx((MAX_FRAMES - 1) / 100.0)
    monkeypatch.setattr(animate_module, "MAX_FRAMES", 11)
    with Image.open(animate(model, motion, tmp_path / "long.gif", dpi=20)) as image:
        assert image.n_frames == 11
        assert image.info["duration"] == 10_000  # 10 frame intervals over 100 s


def test_mp4_works_or_says_to_use_gif(pendulum, tmp_path):
    model, run = pendulum
    short = Trajectory(run.t[:11], run.q[:11], run.qd[:11], run.qdd[:11], run.names)
    if matplotlib.animation.writers.is_available("ffmpeg"):
        path = animate(model, short, tmp_path / "run.mp4", dpi=33)  # odd width: padded
        assert path.read_bytes()[4:8] == b"ftyp"
        assert [p.name for p in tmp_path.iterdir()] == ["run.mp4"]
    else:
        with pytest.raises(CmbsError, match=r"needs ffmpeg.*\.gif"):
            animate(model, short, tmp_path / "run.mp4")
        assert list(tmp_path.iterdir()) == []


def test_mp4_without_ffmpeg_raises(monkeypatch, pendulum, tmp_path):
    model, run = pendulum
    monkeypatch.setattr(matplotlib.animation.writers, "is_available", lambda name: False)
    with pytest.raises(CmbsError, match=r"run\.mp4: writing \.mp4 needs ffmpeg.*write a \.gif instead"):
        animate(model, run, tmp_path / "run.mp4")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name, options, message", [
    ("run.avi", {}, "must end in .gif or .mp4"),
    ("run", {}, "no extension"),
    ("missing/run.gif", {}, "does not exist"),
    ("run.gif", {"trail": "nowhere"}, "no point 'nowhere'.*points: O, P1, P2"),
    ("run.gif", {"fps": 0}, "fps must be a positive number"),
    ("run.gif", {"speed": -1.0}, "speed must be a positive number"),
])
def test_bad_requests_raise_before_writing(pendulum, tmp_path, name, options, message):
    model, run = pendulum
    with pytest.raises(CmbsError, match=message):
        animate(model, run, tmp_path / name, **options)
    assert list(tmp_path.iterdir()) == []


def test_trajectory_of_another_model_is_refused(pendulum, four_bar, tmp_path):
    model, _ = pendulum
    _, motion = four_bar
    with pytest.raises(CmbsError, match="not those of model 'double-pendulum'"):
        animate(model, motion, tmp_path / "x.gif")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("stage", ["frame", "finish"])
def test_failed_write_leaves_nothing_half_written(monkeypatch, pendulum, tmp_path, stage):
    model, run = pendulum
    good = tmp_path / "run.gif"
    good.write_bytes(b"an earlier animation")
    calls = []

    def fail_on_third(self):
        calls.append(1)
        if len(calls) == 3:
            raise OSError("No space left on device")
        original_grab(self)

    def fail_half_written(self):
        with open(self.outfile, "wb") as stream:
            stream.write(b"GIF89a partial")
        raise OSError("No space left on device")

    original_grab = animate_module._BlitPillowWriter.grab_canvas
    if stage == "frame":
        monkeypatch.setattr(animate_module._BlitPillowWriter, "grab_canvas", fail_on_third)
    else:
        monkeypatch.setattr(animate_module._BlitPillowWriter, "finish", fail_half_written)
    with pytest.raises(CmbsError, match="writing the animation failed.*No space left"):
        animate(model, run, good, dpi=20)
    assert [p.name for p in tmp_path.iterdir()] == ["run.gif"]
    assert good.read_bytes() == b"an earlier animation"
    assert plt.get_fignums() == []  # the figure was closed


def test_limits_cover_the_motion_with_equal_scales():
    figure = plt.figure(figsize=(6.4, 4.8))
    axis = figure.add_axes((0.1, 0.1, 0.85, 0.8))
    points = np.array([[[0.0, 0.0], [3.0, -1.0]], [[-2.0, 0.5], [1.0, 7.0]]])
    animate_module._fixed_limits(axis, figure, points)
    (x0, x1), (z0, z1) = axis.get_xlim(), axis.get_ylim()
    assert x0 < -2.0 and x1 > 3.0 and z0 < -1.0 and z1 > 7.0
    width = 0.85 * 6.4
    height = 0.8 * 4.8
    assert (x1 - x0) / (z1 - z0) == pytest.approx(width / height)
    plt.close(figure)
