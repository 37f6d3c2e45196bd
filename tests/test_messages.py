"""Messages, units and consistency: what the library and the command line say about a run
(names, units, times) says it right."""

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import cmbs
from cmbs import jit
from cmbs.cli import main
from cmbs.errors import CmbsError
from cmbs.trajectory import Trajectory


def test_force_on_an_undriven_coordinate_names_the_driven_ones():
    result = cmbs.inverse_dynamics(cmbs.load("four-bar"), np.array([0.0, 0.1]))
    with pytest.raises(CmbsError, match=r"no driver force on 'hip'.*driven coordinates are alpha"):
        result.force("hip")
    with pytest.raises(CmbsError, match=r"did you mean 'alpha'"):
        result.force("alfa")


README = Path(__file__).resolve().parents[1] / "README.md"
#: names the README's prose lists under a package it names once (`cmbs.inverse` also has ...)
README_PROSE = ["cmbs.inverse.pidc_torque", "cmbs.inverse.passive_joint_torque", "cmbs.inverse.is_decoupled",
                "cmbs.inverse.joint_reactions", "cmbs.inverse.servo_inverse_dynamics", "cmbs.control.PD",
                "cmbs.control.ComputedTorque", "cmbs.control.PIDC", "cmbs.control.Hybrid",
                "cmbs.control.UdwadiaKalabaTracking", "cmbs.control.ZeroOrderHold", "cmbs.control.robustness_study",
                "cmbs.model.equations.from_callables"]


def _is_module(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except ModuleNotFoundError:      # a parent is a module, not a package
        return False


def _readme_names() -> dict[str, list[str]]:
    """Every dotted cmbs name of the README (and README_PROSE), grouped by the module path they
    go through (``cmbs.model.joints`` for cmbs.model.joints.JointModelBuilder)."""
    names = set(re.findall(r"\bcmbs(?:\.[A-Za-z_]\w*)+", README.read_text())) | set(README_PROSE)
    groups: dict[str, list[str]] = {}
    for name in sorted(names):
        parts = name.split(".")
        depth = 1
        while depth < len(parts) - 1 and _is_module(".".join(parts[:depth + 1])):
            depth += 1
        groups.setdefault(".".join(parts[:depth]), []).append(name)
    return groups


def test_every_name_the_readme_shows_resolves_after_a_plain_import_cmbs():
    """Each group in a fresh interpreter: ``import cmbs`` and then the attribute path, as written."""
    groups = _readme_names()
    assert {"cmbs.model.equations", "cmbs.model.joints", "cmbs.inverse"} <= set(groups)
    processes = {prefix: subprocess.Popen([sys.executable, "-c", "import cmbs\n" + "\n".join(
        f"assert {name} is not None" for name in names)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for prefix, names in groups.items()}
    failures = {}
    for prefix, process in processes.items():
        error = process.communicate()[1]
        if process.returncode != 0:
            failures[prefix] = error.strip().splitlines()[-1:]
    assert failures == {}


def _free_mass(conservative: bool = False) -> cmbs.Model:
    """A 1 kg point on a line, pushed by its input: q̈ = u (``conservative``: its author states
    that nothing else does work)."""
    from cmbs.model.equations import from_callables

    return from_callables("pushed-mass", coordinate_names=["x"], mass_matrix=lambda q: np.eye(1),
                          forces=lambda q, qd, t, u: np.array([u[0]]), n_inputs=1, q0=[0.0],
                          conservative=conservative)


@pytest.mark.skipif(not jit.COMPILED, reason="numba is not installed: nothing compiles")
def test_a_run_reports_the_time_it_spent_compiling_apart_from_its_run_time():
    """A numba input law defined here compiles at its first call, inside the first run only."""
    import numba

    @numba.njit
    def push(t):
        return np.sin(t)

    model = _free_mass()
    first = cmbs.simulate(model, t_end=0.1, dt=0.01, u=lambda t, q, qd: np.array([push(t)]))
    assert 0 < first.info["compile_time"] <= first.info["wall_time"]
    second = cmbs.simulate(model, t_end=0.1, dt=0.01, u=lambda t, q, qd: np.array([push(t)]))
    assert second.info["compile_time"] == 0.0


def _pretend_compiling(monkeypatch, seconds: float) -> None:
    """cmbs.simulate.simulate as it is, but reporting ``seconds`` more of compiling and of wall time."""
    module = sys.modules["cmbs.simulate"]
    original = module.simulate

    def compiling(*args, **kwargs):
        run = original(*args, **kwargs)
        run.info["wall_time"] += seconds
        run.info["compile_time"] += seconds
        return run

    monkeypatch.setattr(module, "simulate", compiling)


def test_simulate_and_compare_print_the_compile_time_apart_from_the_run_time(monkeypatch, capsys):
    _pretend_compiling(monkeypatch, 100.0)
    assert main(["simulate", "pendulum", "--t-end", "0.1", "--integrator", "rk4"]) == 0
    line = capsys.readouterr().out.splitlines()[0]
    run_time, compile_time = re.search(r"run (\S+) s, compile (\S+) s", line).groups()
    assert float(run_time) < 50 and float(compile_time) >= 100
    assert main(["compare", "pendulum", "--t-end", "0.1", "--formulations", "lagrange,projection"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].split()[-4:] == ["run", "s", "compile", "s"]
    for row in lines[2:]:
        assert float(row.split()[-2]) < 50 and float(row.split()[-1]) >= 100


@pytest.fixture
def unbatched(monkeypatch):
    """``cmbs sweep`` with its variants run one at a time (the single-run loops other tests
    compile): these tests read what it prints, the same for either path; the batched path is
    tests/test_sweep.py's."""
    module = sys.modules["cmbs.sweep"]
    original = module.sweep
    monkeypatch.setattr(module, "sweep", lambda *args, **kwargs: original(*args, **{**kwargs, "batched": False}))


def test_a_sweep_prints_the_compile_time_apart_from_the_run_time(unbatched, monkeypatch, capsys):
    module = sys.modules["cmbs.sweep"]
    original = module.sweep

    def compiling(*args, **kwargs):
        result = original(*args, **kwargs)
        result.info["wall_time"] += 100.0
        result.info["compile_time"] += 100.0
        return result

    monkeypatch.setattr(module, "sweep", compiling)
    assert main(["sweep", "pendulum", "--undriven", "--speed", "P.z=0,1", "--t-end", "0.1", "--dt", "0.01",
                 "--integrator", "rk4", "--workers", "1"]) == 0
    run_time, compile_time = re.search(r"run (\S+) s, compile (\S+) s", capsys.readouterr().out).groups()
    assert float(run_time) < 50 and float(compile_time) >= 100


def test_a_study_table_shows_run_and_compile_time_apart():
    from cmbs.control.study import TrackingRun, format_table

    run = cmbs.simulate(_free_mass(), t_end=0.1, dt=0.01)
    table = format_table([TrackingRun("nominal", run, ("x",), np.array([0.01]), 0.5, 1.0, 2.0, wall_time=3.0,
                                      compile_time=2.5)])
    header, row = table.splitlines()[0], table.splitlines()[2]
    assert header.split()[-5:] == ["run", "s", "compile", "s", "status"]
    assert row.split()[-3:] == ["0.5", "2.5", "success"]


def test_the_work_of_a_constant_push_is_force_times_distance():
    """q̈ = F from rest: x = F t²/2, so W = F x = F² t²/2 = T; the mass stated conservative."""
    from cmbs.simulate import supplied_work

    model = _free_mass(conservative=True)
    force = 3.0
    run = cmbs.simulate(model, t_end=1.0, dt=0.01, u=np.array([force]), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(supplied_work(model, run), force**2 * run.t**2 / 2, atol=1e-9)
    unstated = _free_mass()
    assert supplied_work(unstated, cmbs.simulate(unstated, t_end=0.1, u=np.array([force]))) is None


def test_a_driven_run_prints_its_energy_balance_not_the_drivers_work_as_an_error(capsys):
    """The driven four-bar's crank driver does ~95 J of work and takes it back: E - E0 - W is the
    run's error (rtol 1e-10: below 1e-4 J), E - E0 is not."""
    from cmbs.simulate import supplied_work

    model = cmbs.load("four-bar")
    run = cmbs.simulate(model, t_end=2.0, rtol=1e-10, atol=1e-12)
    change = run["energy"] - run["energy"][0]
    assert np.abs(change).max() > 50
    assert np.abs(change - supplied_work(model, run)).max() < 1e-4
    assert main(["simulate", "four-bar", "--t-end", "2", "--rtol", "1e-10", "--atol", "1e-12"]) == 0
    balance = re.search(r"energy balance max \|E - E0 - W\| (\S+) J", capsys.readouterr().out)
    assert balance and float(balance.group(1)) < 1e-4


def test_coordinate_and_force_units_follow_what_each_coordinate_is():
    from cmbs.model.joints import JointModelBuilder
    from cmbs.units import coordinate_unit, force_unit

    four_bar = cmbs.load("four-bar")
    assert [coordinate_unit(four_bar, name) for name in ("P1.x", "P1.z", "alpha")] == ["m", "m", "rad"]
    assert [force_unit(four_bar, name) for name in ("P1.x", "alpha")] == ["N", "N m"]
    builder = JointModelBuilder("arm on a rail")
    builder.add_link("carriage", parent=None, joint="prismatic", coordinate="s", length=0.2, mass=1.0,
                     com=(0.1, 0.0), inertia=0.01)
    builder.add_link("arm", parent="carriage", coordinate="theta", length=0.5, mass=1.0, com=(0.25, 0.0),
                     inertia=0.02)
    rail = builder.build()
    assert [force_unit(rail, name) for name in ("s", "theta")] == ["N", "N m"]
    assert coordinate_unit(_free_mass(), "x") == ""                 # the user's own equations do not say


def test_inverse_prints_and_plots_each_force_with_its_unit(tmp_path, capsys):
    import matplotlib.pyplot as plt

    from cmbs.plotting import plot_driver_forces

    assert main(["inverse", "slider-crank-joint", "--motion", "theta1 = pi/4 + 2*t", "--t-end", "0.2", "--dt",
                 "0.01", "--reactions"]) == 0
    out = capsys.readouterr().out
    assert "force on theta1 [N m]" in out and "N or N m" not in out
    assert re.search(r"joint force theta1 +max \S+ N m\n", out)
    model = cmbs.load("four-bar")
    ida = cmbs.inverse_dynamics(model, np.linspace(0.0, 0.2, 21))
    figure = plot_driver_forces(ida.motion, ida.driven_coordinates, model=model)
    assert [axis.get_ylabel() for axis in figure.axes] == ["torques [N m]", "coordinates [rad]"]
    plt.close(figure)


def test_sweep_labels_read_as_a_mass_factor_and_a_speed(unbatched, capsys):
    assert main(["sweep", "four-bar", "--undriven", "--speed", "alpha=-2,0", "--t-end", "0.01", "--dt", "1e-3",
                 "--integrator", "rk4"]) == 0
    out = capsys.readouterr().out
    assert "dalpha/dt=-2 rad/s" in out and "dalpha/dt=0 rad/s" in out
    assert main(["sweep", "slider-crank", "--mass", "crank=1.1", "--t-end", "0.01", "--dt", "1e-3",
                 "--integrator", "rk4", "--formulation", "matrix-r", "--workers", "1"]) == 0
    assert "mass(crank)×1.1" in capsys.readouterr().out


def test_track_reports_nrmse_in_percent_and_takes_the_initial_error_in_degrees_or_coordinate_units(capsys):
    """5.7296deg is 0.1 rad: the same run as --initial-error 0.1 (alpha is an angle)."""
    common = ["track", "four-bar", "--t-end", "0.5", "--dt", "0.01"]
    assert main([*common, "--initial-error", "0.1"]) == 0
    in_radians = capsys.readouterr().out
    assert main([*common, "--initial-error", f"{float(np.degrees(0.1))!r}deg"]) == 0
    assert capsys.readouterr().out == in_radians
    nrmse = float(re.search(r"NRMSE \(of the reference's range\) alpha (\S+) %", in_radians).group(1))
    assert 1 < nrmse < 100                      # 0.1 rad off a 1.57 rad range: percent, not a fraction
    assert main(["track", "four-bar", "--reference", "P1.x = 0.1 * t", "--t-end", "0.1",
                 "--initial-error", "5deg"]) == 2
    assert "'P1.x' is not an angle (m)" in capsys.readouterr().err


def test_a_never_settling_error_says_how_much_of_it_remains(tmp_path, monkeypatch, capsys):
    """A coupler 2.5 % heavier from t = 2 s leaves CTC a steady periodic error above 1 % of the
    0.1 rad start: the run never settles, and the line says how large the error stays,
    checked against the saved run and the reference motion."""
    monkeypatch.chdir(tmp_path)
    assert main(["track", "four-bar", "--initial-error", "0.1", "--fault", "mass:coupler:1.025:2", "--t-end", "10",
                 "--out", "never.npz"]) == 0
    printed = re.search(r"never: \|error\| still reaches (\S+) % of the initial error", capsys.readouterr().out)
    run = Trajectory.load("never.npz")
    reference = cmbs.kinematic_analysis(cmbs.load("four-bar"), run.t)
    error = np.abs(reference["alpha"] - run["alpha"])
    assert float(printed.group(1)) == pytest.approx(100 * error[run.t >= 5].max() / 0.1, rel=1e-2)


def _parsers(parser, path=("cmbs",)):
    """Every command's parser, with its command path."""
    import argparse

    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, command in action.choices.items():
                yield from _parsers(command, (*path, name))


def test_every_option_with_a_default_shows_it_in_help():
    import argparse

    from cmbs.cli import build_parser

    missing = []
    for path, parser in _parsers(build_parser()):
        text = " ".join(parser.format_help().split())
        for action in parser._actions:
            default = action.default
            if not action.option_strings or default is None or default is False or default == [] \
                    or default is argparse.SUPPRESS:
                continue
            shown = f"(default: {default})" in text or ("default" in (action.help or "") and str(default) in text)
            if not shown:
                missing.append(f"{' '.join(path)} {action.option_strings[0]} (default {default})")
    assert missing == []


def test_gait_track_takes_the_initial_error_as_track_does_and_its_step_as_dt(prepared, capsys):
    """A plain number is in rad (as for `cmbs track`), degrees carry their unit; a plain 5 (the
    old degrees) is refused before any work rather than run as 5 rad."""
    common = ["gait", "track", "--controller", "ctc", "--t-end", "0.01", "--dt", "1e-3"]
    assert main([*common, "--initial-error", f"{float(np.radians(2.0))!r}"]) == 0
    assert "initial error 2 deg on the trunk and joint angles" in capsys.readouterr().out
    assert main([*common, "--initial-error", "2deg"]) == 0
    assert "initial error 2 deg on the trunk and joint angles" in capsys.readouterr().out
    assert main([*common, "--initial-error", "5"]) == 2
    assert "for degrees write the unit, e.g. 5deg" in capsys.readouterr().err


def test_the_summary_figure_splits_units_fills_its_grid_and_floors_rounding_noise():
    import matplotlib.pyplot as plt

    from cmbs.plotting import plot_simulation
    from cmbs.simulate import supplied_work

    free = cmbs.load("four-bar").without_drivers()
    run = cmbs.simulate(free, t_end=1.0, formulation="projection", rtol=1e-9, project=True)
    figure = plot_simulation(run, model=free)
    axes = {axis.get_title().split("\n")[0]: axis for axis in figure.axes}
    assert {line.get_label() for line in axes["coordinates [m]"].lines} == {"P1.x", "P1.z", "P2.x", "P2.z"}
    assert {line.get_label() for line in axes["coordinates [rad]"].lines} == {"alpha"}
    assert (axes["mechanism (x, z)"].get_xlabel(), axes["mechanism (x, z)"].get_ylabel()) == ("x [m]", "z [m]")
    errors = axes["constraint errors (log)"]
    rounding = np.finfo(float).eps * np.abs(run.q).max()
    assert run["velocity_constraint_error"][1:].min() < rounding          # projected: values down to 1e-30
    assert errors.get_ylim()[0] == pytest.approx(rounding)
    plt.close(figure)

    pendulum = cmbs.load("pendulum")                 # five panels: the last row's two share its width
    figure = plot_simulation(cmbs.simulate(pendulum, t_end=0.2), model=pendulum)
    boxes = [axis.get_position() for axis in figure.axes]
    assert len(boxes) == 5 and boxes[3].x0 == pytest.approx(boxes[0].x0, abs=0.02)
    assert boxes[4].x1 == pytest.approx(boxes[2].x1, abs=0.02)
    plt.close(figure)

    driven = cmbs.load("four-bar")                   # the driver's work is not drawn as a drift
    run = cmbs.simulate(driven, t_end=1.0)
    figure = plot_simulation(run, model=driven)
    balance = next(axis for axis in figure.axes if axis.get_title().startswith("energy balance"))
    expected = run["energy"] - run["energy"][0] - supplied_work(driven, run)
    np.testing.assert_allclose(balance.lines[0].get_ydata(), expected)
    plt.close(figure)


def test_the_inverse_dynamics_example_colours_each_method_alike_in_both_panels(tmp_path, monkeypatch):
    import runpy

    import matplotlib.pyplot as plt

    example = Path(__file__).resolve().parents[1] / "examples" / "four_bar_inverse_dynamics.py"
    monkeypatch.setattr(sys, "argv", [str(example), "--t-end", "0.2", "--out-dir", str(tmp_path)])
    runpy.run_path(str(example), run_name="__main__")
    top, bottom = plt.gcf().axes
    colours = {line.get_label(): line.get_color() for line in top.lines}
    for line in bottom.lines:
        method = line.get_label().strip("|").split(" - ")[0]
        assert line.get_color() == colours[method], method
    plt.close("all")


def test_a_python_loop_runs_blas_on_one_thread_and_gives_the_setting_back():
    """Multi-threaded OpenBLAS made Udwadia-Kalaba 60× slower on the four-bar's 5×5 matrices."""
    import scipy.linalg  # noqa: F401 -- its BLAS loaded, so that threadpoolctl sees both
    from threadpoolctl import threadpool_info, threadpool_limits

    seen = []

    def no_extra_work(t, q, qd):            # a non-ideal term of zero, to look inside the loop
        if not seen:
            seen.extend(pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas")
        return np.zeros(q.size)

    free = cmbs.load("four-bar").without_drivers()
    with threadpool_limits(limits=2, user_api="blas"):
        cmbs.simulate(free, t_end=0.01, formulation=cmbs.UdwadiaKalaba(nonideal=no_extra_work))
        after = [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]
    assert seen and set(seen) == {1}
    assert set(after) == {2}


def test_the_work_of_a_diverged_run_is_nan_from_its_first_non_finite_power_not_an_exception():
    from cmbs.simulate import supplied_work

    model = cmbs.load("four-bar")
    run = cmbs.simulate(model, t_end=0.1, dt=0.01)
    run.extras["constraint_force"][5:] = np.nan
    work = supplied_work(model, run)
    assert np.all(np.isfinite(work[:5])) and np.all(np.isnan(work[6:]))


def test_a_sweep_of_a_driven_model_says_its_energy_change_is_the_drivers_work(capsys):
    assert main(["sweep", "four-bar", "--mass", "coupler=1,1.1", "--t-end", "0.05", "--dt", "1e-3",
                 "--integrator", "rk4", "--workers", "1"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if "mass(coupler)" in line]
    assert len(rows) == 2 and all("(E - E0: work of driver 'crank', not an error)" in row for row in rows)


def test_the_kinematics_figure_puts_lengths_and_angles_on_their_own_axes():
    import matplotlib.pyplot as plt

    from cmbs.plotting import plot_trajectory

    model = cmbs.load("four-bar")
    figure = plot_trajectory(cmbs.kinematic_analysis(model, np.linspace(0.0, 0.5, 11)), model=model)
    lines = {axis.get_title(): {line.get_label() for line in axis.lines} for axis in figure.axes[:6]}
    assert lines["position [m]"] == {"P1.x", "P1.z", "P2.x", "P2.z"} and lines["velocity [rad/s]"] == {"alpha"}
    assert "acceleration [m/s²]" in lines and "acceleration [rad/s²]" in lines
    plt.close(figure)
