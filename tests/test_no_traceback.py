"""No traceback and no late failure: every user mistake found by fuzzing the CLI and the model
files ends in one line (exit 2) before any work, and a run that fails at its first instant ends
with the library's own message (exit 1)."""

import os
import textwrap

import numpy as np
import pytest

import cmbs
from cmbs.cli import main
from cmbs.errors import CmbsError, ModelError
from cmbs.files_io import PARTIAL

PENDULUM = """
[points]
O = { x = 0.0, z = 0.0, fixed = true }
P = { x = 1.0, z = 0.0 }

[segments.rod]
points = ["O", "P"]
mass = 1.0
com = [0.5, 0.0]
inertia = 0.1
"""


def write(tmp_path, text, name="model.toml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def one_error_line(capsys, prefix="cmbs: error: "):
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith(prefix), lines[0]
    return lines[0]


# ------------------------------------------------------------- a run that fails at its first instant
def test_a_run_that_fails_at_its_first_instant_prints_the_library_message(capsys):
    """Aghili's slider-crank (equal crank and rod) with the crank at 90 degrees: the slider sits
    under the crank pin, the rank of A drops at t = 0 and lagrange cannot start; the user reads
    why and what to use instead."""
    assert main(["simulate", "slider-crank", "--t-end", "0.1", "--param", "crank_angle=90"]) == 1
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    assert "failed at t = 0 s (no instant computed)" in captured.out
    assert "cmbs: simulation failed: " in captured.err
    assert "rank 4 < 5" in captured.err and "dependent: rigid rod" in captured.err
    assert "Use formulation 'projection'" in captured.err


def test_a_start_the_formulation_cannot_solve_compiles_no_loop_and_ends_as_the_compiled_loop_does():
    """The dead centre stops Lagrange at t = 0: the run takes the Python loop (no loop compiled for
    an instant), with the status, instants and message of the compiled loop's run."""
    model = cmbs.load("slider-crank", crank_angle=90)
    run = cmbs.simulate(model, t_end=0.1)
    compiled = cmbs.simulate(model, t_end=0.1, compiled=True)
    assert run.info["note"].startswith("Python loop: the formulation cannot solve the start state")
    assert compiled.info["compiled"] and not run.info.get("compiled")
    assert run.info["status"] == compiled.info["status"] == "failed" and run.t.size == compiled.t.size == 0
    assert run.info["message"] == compiled.info["message"]
    assert "rank 4 < 5" in run.info["message"]


def test_a_run_that_fails_at_its_first_instant_still_writes_its_empty_result(tmp_path, capsys):
    """What it computed (nothing) goes to --out; a figure or animation of no instant is not drawn,
    and the output says so."""
    out, plot, animation = tmp_path / "r.npz", tmp_path / "r.png", tmp_path / "r.gif"
    assert main(["simulate", "slider-crank", "--t-end", "0.1", "--param", "crank_angle=90", "--out", str(out),
                 "--plot", str(plot), "--animate", str(animation)]) == 1
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err and "dependent: rigid rod" in captured.err
    assert cmbs.Trajectory.load(out).t.size == 0
    assert not plot.exists() and not animation.exists()
    assert "figure -> not written: no instant computed" in captured.out
    assert "animation -> not written: no instant computed" in captured.out


def test_compare_with_a_run_that_fails_at_its_first_instant(capsys):
    assert main(["compare", "slider-crank", "--t-end", "0.1", "--param", "crank_angle=90",
                 "--formulations", "lagrange,projection"]) == 1
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    assert "dependent: rigid rod" in captured.out


# ------------------------------------------------------------- models without coordinates
@pytest.mark.parametrize("text", ["", "# only a comment\n", "[model]\nname = 'x'\n"],
                         ids=["empty", "comments-only", "header-only"])
def test_an_empty_model_file_is_a_model_error(tmp_path, capsys, text):
    path = write(tmp_path, text)
    assert main(["describe", str(path)]) == 2
    assert one_error_line(capsys) == f"cmbs: error: {path}: points: the file defines no points (an empty model)"


def test_a_model_whose_points_are_all_fixed_is_a_model_error(tmp_path, capsys):
    path = write(tmp_path, """
        [points]
        A = { x = 0.0, z = 0.0, fixed = true }
        B = { x = 1.0, z = 0.0, fixed = true }
        """)
    for command in (["describe"], ["simulate", "--t-end", "0.1"]):
        assert main([command[0], str(path), *command[1:]]) == 2
        line = one_error_line(capsys)
        assert line.startswith(f"cmbs: error: {path}: points: the model has no coordinates")


def test_the_builder_refuses_a_model_without_coordinates():
    builder = cmbs.NaturalModelBuilder("still")
    builder.add_point("A", 0.0, 0.0, fixed=True)
    with pytest.raises(ModelError, match="the model has no coordinates"):
        builder.build()


# ------------------------------------------------------------- numbers out of range
def pendulum(x="1.0", gravity="[0.0, -9.81]", mass="1.0", inertia="0.1", length=None):
    length_line = f"length = {length}\n" if length is not None else ""
    return f"""
[model]
gravity = {gravity}

[points]
O = {{ x = 0.0, z = 0.0, fixed = true }}
P = {{ x = {x}, z = 0.0 }}

[segments.rod]
points = ["O", "P"]
mass = {mass}
com = [0.5, 0.0]
inertia = {inertia}
{length_line}"""


@pytest.mark.parametrize("text, entry, problem", [
    (pendulum(x="1e-320"), "segments.rod", "is below 1e-12 of the model size 1 "),   # 1e-320 is denormal
    (pendulum(x="1e-13"), "segments.rod", "length 1e-13 is below 1e-12"),
    (pendulum(length="1e-300"), "segments.rod", "length 1e-300 is below 1e-12"),
    (pendulum(x="1e6", length="1e-7"), "segments.rod", "length 1e-07 is below 1e-12 of the model size 1e+06"),
    (pendulum(x="1e200"), "points.P", "x = 1e+200 is out of range: |x| must be <= 1e+12"),
    (pendulum(gravity="[0.0, -1e308]"), "model", "gravity = -1e+308 is out of range"),
    (pendulum(mass="1e13"), "segments.rod", "mass = 1e+13 is out of range"),
    (pendulum(inertia="-1e300"), "segments.rod", "inertia = -1e+300 is out of range"),
], ids=["tiny-point-distance", "below-absolute-floor", "tiny-given-length", "tiny-relative-length",
        "huge-coordinate", "huge-gravity", "huge-mass", "huge-inertia"])
def test_numbers_out_of_range_are_named_at_load(tmp_path, capsys, text, entry, problem):
    path = write(tmp_path, text)
    assert main(["simulate", str(path), "--t-end", "0.1"]) == 2
    line = one_error_line(capsys)
    assert line.startswith(f"cmbs: error: {path}: {entry}: "), line
    assert problem in line


def test_a_table_value_out_of_range_is_named(tmp_path, capsys):
    path = write(tmp_path, PENDULUM + """
[angles.th]
segment = "rod"

[drivers.d]
coordinate = "th"
table = { t = [0.0, 1.0], value = [0.0, 1e200] }
interpolation = "linear"
""")
    assert main(["describe", str(path)]) == 2
    assert one_error_line(capsys) == (f"cmbs: error: {path}: drivers.d.table: table has a time or value of "
                                      "magnitude above 1e+12 (out of range)")


def test_table_times_too_close_are_refused():
    """Times 1e-320 apart gave infinite slopes (an overflow warning, then a failure at t = 0)."""
    with pytest.raises(ModelError, match=r"table times must be at least 1e-12 apart .* got two 9.99989e-321 apart"):
        cmbs.Table(np.array([0.0, 1e-320, 1.0]), np.array([0.0, 1.0, 2.0]), "linear")


@pytest.mark.parametrize("model, key, value, shown", [
    ("human", "height", "1e300", "1e+300"), ("slider-crank", "crank_speed", "1e300", "1e+300"),
    ("chaplygin-sleigh", "inertia", "1e300", "1e+300"), ("chain", "links", "10000000000000", "10000000000000"),
])
def test_a_library_parameter_out_of_range_is_named(capsys, model, key, value, shown):
    """human height=1e300 overflowed in its builder; the others loaded a model of infinite energy."""
    assert main(["describe", model, "--param", f"{key}={value}"]) == 2
    assert one_error_line(capsys) == (f"cmbs: error: model {model!r}: parameter {key} = {shown} is out of range: "
                                      f"|{key}| must be <= 1e+12")


def test_a_chain_too_long_to_build_is_refused_before_any_work(capsys):
    """links=100000000 ran for minutes and filled the memory (5,000 links: 5 min, 5.6 GB)."""
    assert main(["describe", "chain", "--param", "links=100000000"]) == 2
    assert one_error_line(capsys).startswith("cmbs: error: chain: links must be at most 1000, got 100000000")


def test_the_builder_refuses_the_same_numbers():
    builder = cmbs.NaturalModelBuilder("big", gravity=(0.0, -9.81))
    with pytest.raises(ModelError, match=r"points.P: x = 1e\+200 is out of range"):
        builder.add_point("P", 1e200, 0.0)
    with pytest.raises(ModelError, match=r"springs.s: stiffness = 1e\+20 is out of range"):
        builder.add_spring("s", "A", "B", stiffness=1e20)
    with pytest.raises(ModelError, match=r"model: gravity = 1e\+308 is out of range"):
        cmbs.NaturalModelBuilder("g", gravity=(1e308, 0.0)).build()


def test_a_sensible_small_and_large_model_still_loads(tmp_path):
    """A 1 mm rod of 1 g and a 1 km rod of 1e6 kg are inside the limits: the limits do not
    reject real mechanisms."""
    for x, mass, inertia in (("1e-3", "1e-3", "1e-10"), ("1e3", "1e6", "1e11")):
        model = cmbs.load(write(tmp_path, pendulum(x=x, mass=mass, inertia=inertia)))
        np.testing.assert_allclose(model.q0, [float(x), 0.0])


def test_a_csv_driver_file_name_longer_than_the_system_allows(tmp_path, capsys):
    path = write(tmp_path, PENDULUM + f"""
[angles.th]
segment = "rod"

[drivers.d]
coordinate = "th"
file = "{'a' * 300}.csv"
""")
    assert main(["describe", str(path)]) == 2
    line = one_error_line(capsys)
    assert line.startswith(f"cmbs: error: {path}: drivers.d.file: ")
    assert "cannot be read" in line


def test_a_model_file_name_longer_than_the_system_allows(tmp_path, capsys):
    path = tmp_path / ("m" * 300 + ".toml")
    assert main(["describe", str(path)]) == 2
    assert "cannot be read" in one_error_line(capsys)


def test_the_singular_message_survives_a_failing_diagnosis():
    """_singular_message re-runs the Python solver to name the dependent constraints; a
    LinAlgError there (e.g. an SVD that does not converge on a non-finite state) must not
    replace the run's failure by a traceback."""
    from cmbs.simulate import _singular_message

    class Broken:
        def accelerations(self, *args):
            raise np.linalg.LinAlgError("SVD did not converge")

    model = cmbs.load("pendulum")
    message = _singular_message(model, Broken(), model.q0, model.qd0, 0.25, np.zeros(0))
    assert message.startswith("singular system at t=0.25")
    assert "SVD did not converge" in message


# ------------------------------------------------------------- output paths, before any work
@pytest.mark.parametrize("command", [
    ["simulate", "pendulum", "--t-end", "0.05", "--out", "{bad}.npz"],
    ["simulate", "pendulum", "--t-end", "0.05", "--plot", "{bad}.png"],
    ["simulate", "pendulum", "--t-end", "0.05", "--animate", "{bad}.gif"],
    ["simulate", "pendulum", "--t-end", "0.05", "--animate", "{bad}.html"],
    ["kinematics", "slider-crank", "--t-end", "0.05", "--dt", "0.01", "--out", "{bad}.csv"],
    ["inverse", "slider-crank", "--t-end", "0.05", "--dt", "0.01", "--plot", "{bad}.png"],
    ["track", "four-bar", "--t-end", "0.05", "--out", "{bad}.npz"],
    ["sweep", "pendulum", "--t-end", "0.05", "--speed", "P.x=0,1", "--out", "{bad}.npz"],
], ids=["simulate-out", "simulate-plot", "simulate-animate", "simulate-viewer", "kinematics-out", "inverse-plot", "track-out",
        "sweep-out"])
@pytest.mark.parametrize("bad", ["/proc/cmbs-x", "{tmp}/a-directory", "{tmp}/" + "n" * 300],
                         ids=["unwritable", "directory", "name-too-long"])
def test_an_output_path_that_cannot_be_written_is_refused_before_any_work(tmp_path, capsys, monkeypatch, command,
                                                                           bad):
    def no_work(*args, **kwargs):
        raise AssertionError("the model was loaded before the output path was checked")

    monkeypatch.setattr(cmbs, "load", no_work)
    (tmp_path / "a-directory.npz").mkdir()
    for suffix in (".png", ".gif", ".html", ".csv"):
        (tmp_path / f"a-directory{suffix}").mkdir()
    arguments = [part.format(bad=bad.format(tmp=tmp_path)) for part in command]
    before = sorted(tmp_path.rglob("*"))
    assert main(arguments) == 2
    line = one_error_line(capsys)
    assert bad.format(tmp=tmp_path)[:40] in line
    assert sorted(tmp_path.rglob("*")) == before


def test_an_interrupted_write_leaves_no_temporary(tmp_path):
    from cmbs.files_io import atomic_path

    target = tmp_path / "result.npz"
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(target) as temporary:
            with open(temporary, "wb") as stream:
                stream.write(b"half")
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


def test_a_later_write_removes_the_stale_temporaries_of_its_target(tmp_path):
    """A write killed outright (SIGKILL, power loss) cannot clean up; its temporary has the
    target's recognisable name and the dead writer's process id, so the next write to the same
    target removes it (and leaves another target's and a live writer's temporaries alone)."""
    from cmbs.files_io import atomic_path, temporary_prefix

    target = tmp_path / "result.npz"
    dead = _dead_pid()
    stale = tmp_path / f"{temporary_prefix(target, dead)}abcd1234.npz"
    live = tmp_path / f"{temporary_prefix(target, os.getppid())}abcd1234.npz"
    other = tmp_path / f"{temporary_prefix(tmp_path / 'other.npz', dead)}abcd1234.npz"
    for path in (stale, live, other):
        path.write_bytes(b"x" * 100)
    with atomic_path(target) as temporary:
        with open(temporary, "wb") as stream:
            stream.write(b"done")
    assert target.read_bytes() == b"done"
    assert sorted(tmp_path.iterdir()) == sorted([target, live, other])


def _dead_pid() -> int:
    """The id of a process that has exited (its own child, waited for)."""
    import subprocess
    import sys

    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


# ------------------------------------------------------------- options
def test_a_negative_mass_fault_is_refused(capsys):
    assert main(["track", "four-bar", "--t-end", "0.05", "--fault", "mass:coupler:-1"]) == 2
    assert "mass factor must be > 0" in one_error_line(capsys)


def test_mass_fault_refuses_a_factor_that_is_not_positive():
    from cmbs.control.faults import mass_fault

    model = cmbs.load("four-bar")
    for factor in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(CmbsError, match="mass factor must be > 0"):
            mass_fault(model, "coupler", factor=factor)


@pytest.mark.parametrize("command", [
    ["simulate", "pendulum", "--t-end", "0.05"],
    ["sweep", "pendulum", "--t-end", "0.05", "--speed", "P.x=0,1"],
], ids=["simulate", "sweep"])
def test_a_relative_tolerance_of_one_or_more_is_refused(capsys, command):
    assert main([*command, "--rtol", "2"]) == 2
    assert "--rtol must be a finite number > 0 and < 1, got 2.0" in one_error_line(capsys)


def test_simulate_refuses_a_relative_tolerance_of_one_or_more():
    with pytest.raises(CmbsError, match="rtol must be < 1, got 2"):
        cmbs.simulate(cmbs.load("pendulum"), t_end=0.1, rtol=2.0)


@pytest.mark.parametrize("command", [
    ["describe", "slider-crank", "--param", "crank_angle=10", "--param", "crank_angle=20"],
    ["simulate", "pendulum", "--t-end", "0.05", "--formulation", "penalty", "--option", "alpha=1e6",
     "--option", "alpha=1e7"],
    ["sweep", "slider-crank", "--t-end", "0.05", "--param", "crank_angle=10", "--param", "crank_angle=20",
     "--vary", "crank_speed=1,2"],
], ids=["param", "option", "sweep-param"])
def test_a_repeated_key_is_refused(capsys, command):
    assert main(command) == 2
    assert "given twice" in one_error_line(capsys)


def test_sigterm_during_a_write_leaves_no_temporary(tmp_path):
    """The CLI turns SIGTERM into an unwinding exception: a write in progress removes its
    temporary and the command exits 143."""
    import signal
    import subprocess
    import sys

    script = textwrap.dedent(f"""
        import sys, time
        from pathlib import Path
        import cmbs.cli, cmbs.trajectory
        from cmbs.files_io import atomic_path

        def slow_save(self, path):
            with atomic_path(Path(path)) as temporary, open(temporary, "wb") as stream:
                stream.write(b"half a result")
                stream.flush()
                print("writing", flush=True)
                time.sleep(60)

        cmbs.trajectory.Trajectory.save = slow_save
        sys.exit(cmbs.cli.main(["simulate", "pendulum", "--t-end", "0.01", "--out", {str(tmp_path / 'r.npz')!r}]))
        """)
    child = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True)
    try:
        for line in child.stdout:
            if line.startswith("writing"):
                break
        assert any(PARTIAL in path.name for path in tmp_path.iterdir())
        child.send_signal(signal.SIGTERM)
        assert child.wait(timeout=30) == 143
    finally:
        child.kill()
    assert child.stderr.read().strip().endswith("cmbs: terminated")
    assert list(tmp_path.iterdir()) == []


def test_tracking_that_fails_at_its_first_instant_is_a_failed_run_not_a_traceback():
    """The slider-crank at its dead centre: lagrange cannot start, so the tracking run has no
    instant; its measures are NaN (nothing to measure) and it is reported as failed."""
    from cmbs.control.study import format_table, track

    plant = cmbs.load("slider-crank", crank_angle=90)
    times = np.array([0.0, 0.01, 0.02])
    zeros = np.zeros((3, plant.n))
    motion = cmbs.Trajectory(times, np.tile(plant.q0, (3, 1)), zeros, zeros, plant.coordinate_names)
    result = track(plant, lambda t, q, qd: np.zeros(plant.n_u), motion, ["theta1"], t_end=0.02)
    assert not result.succeeded and result.run.t.size == 0
    assert "dependent: rigid rod" in result.run.info["message"]
    assert np.isnan(result.nrmse).all() and np.isnan(result.rms_norm) and np.isnan(result.peak_norm)
    assert "failed" in format_table([result])


@pytest.mark.parametrize("command, problem", [
    (["track", "four-bar", "--t-end", "0.1", "--kp", "1e300"], "--kp = 1e+300 is out of range: |kp| must be <= 1e+12"),
    (["track", "four-bar", "--t-end", "0.1", "--fault", "scale:1e300"],
     "fault 'scale:1e300': 1e+300 is out of range: values must be <= 1e+12 in magnitude"),
    (["sweep", "pendulum", "--t-end", "0.1", "--speed", "P.x=0,1e300"],
     "--speed P.x: 1e+300 is out of range: values must be <= 1e+12 in magnitude"),
], ids=["gain", "fault", "sweep-speed"])
def test_an_option_out_of_range_is_refused_before_any_work(capsys, command, problem):
    """A gain or fault of 1e300 made the adaptive step shrink without end (the run never
    finished); a speed of 1e300 failed every variant at t = 0."""
    assert main(command) == 2
    assert problem in one_error_line(capsys)
