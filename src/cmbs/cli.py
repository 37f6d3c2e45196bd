"""The ``cmbs`` command: a thin argparse layer over the public API.

User mistakes (a bad model file, an unknown name, a bad option) print one line and exit with
status 2; a run that fails on a valid input (e.g. assembly that does not converge) exits 1.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Iterable, Sequence

import numpy as np

import cmbs
from cmbs.errors import CmbsError, CmbsWarning
from cmbs.files_io import checked_output
from cmbs.units import bracketed, coordinate_unit, force_unit

if TYPE_CHECKING:
    from cmbs.control.study import TrackingRun
from cmbs.model.limits import MAX_MAGNITUDE


class _UsageError(CmbsError):
    """A bad command-line option."""


class _Terminated(BaseException):
    """SIGTERM arrived: unwinds like KeyboardInterrupt, so that a write in progress removes its
    temporary file (:func:`cmbs.files_io.atomic_path`)."""


def _terminate(signum: int, frame: object) -> None:
    raise _Terminated


#: words read as a yes/no value in ``key=value`` options
FLAGS = {"true": True, "yes": True, "on": True, "false": False, "no": False, "off": False}


def _parameter(text: str, option: str = "--param") -> tuple[str, object]:
    """``key=value`` with value read as bool (true/false, yes/no, on/off), int, float or string."""
    key, sep, raw = text.partition("=")
    if not sep or not key:
        raise _UsageError(f"{option} expects key=value, got {text!r}")
    lowered = raw.strip().lower()
    if lowered in FLAGS:
        return key, FLAGS[lowered]
    for kind in (int, float):
        try:
            return key, kind(raw)
        except ValueError:
            pass
    return key, raw


class Offset(float):
    """An offset given on the command line with an optional unit: a plain number is in the
    coordinate's own unit (rad for an angle, m for a length), ``5deg`` is in degrees."""

    unit: str = ""

    @classmethod
    def parse(cls, text: str) -> "Offset":
        """argparse type of ``VALUE`` or ``VALUEdeg``."""
        number, degrees = (text[:-3], "deg") if text.strip().endswith("deg") else (text, "")
        try:
            offset = cls(float(number))
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, optionally in degrees as 5deg, got {text!r}") \
                from None
        offset.unit = degrees
        return offset

    def text(self) -> str:
        """As given: ``0.1`` or ``5deg``."""
        return f"{float(self):g}{self.unit}"

    def in_unit_of(self, unit: str, option: str, coordinate: str) -> float:
        """The offset in the coordinate's unit ``unit`` (:func:`cmbs.units.coordinate_unit`);
        _UsageError for degrees on a coordinate that is not an angle."""
        if self.unit != "deg":
            return float(self)
        if unit != "rad":
            raise _UsageError(f"{option} {self.text()}: {coordinate!r} is not an angle "
                              f"({unit or 'its unit is not known'}); give the offset in its own unit")
        return math.radians(self)


def unique_pairs(pairs: Iterable[tuple[str, object]], option: str) -> dict[str, object]:
    """``(key, value)`` pairs of a repeatable option as a dict; a key given twice is a mistake (the
    first value would otherwise be dropped without a word)."""
    result: dict[str, object] = {}
    for key, value in pairs:
        if key in result:
            raise _UsageError(f"{option} {key} given twice ({key}={result[key]!r} and {key}={value!r}): give it once")
        result[key] = value
    return result


#: numeric options checked after parsing (every command that has them): what each must be
NUMBER_RULES = {
    "t_end": "positive", "dt": "positive", "rtol": "fraction", "atol": "positive", "sample_rate": "positive",
    "kp": "non-negative", "kd": "non-negative", "ki": "non-negative", "kf": "non-negative",
    "initial_error": "finite", "worker_timeout": "positive", "projection_tolerance": "positive",
}


def _check_numbers(args: argparse.Namespace) -> None:
    """Every numeric option of NUMBER_RULES given on the command line is finite (and > 0, >= 0, or
    in (0, 1) for a relative tolerance: an rtol of 1 accepts a 100 % error) and of magnitude at
    most MAX_MAGNITUDE, as the numbers of a model: an infinite --t-end would otherwise fail deep
    inside as an overflow."""
    wanted = {"positive": "a finite number > 0", "non-negative": "a finite number >= 0", "finite": "a finite number",
              "fraction": "a finite number > 0 and < 1"}
    for name, rule in NUMBER_RULES.items():
        value = getattr(args, name, None)
        if value is None:
            continue
        ok = math.isfinite(value) and {"positive": value > 0, "non-negative": value >= 0, "finite": True,
                                       "fraction": 0 < value < 1}[rule]
        if not ok:
            raise _UsageError(f"--{name.replace('_', '-')} must be {wanted[rule]}, got {value!r}")
        if abs(value) > MAX_MAGNITUDE:    # e.g. a gain of 1e300 shrinks an adaptive step without end
            raise _UsageError(f"--{name.replace('_', '-')} = {value!r} is out of range: |{name}| must be <= "
                              f"{MAX_MAGNITUDE:g}")


def _load(args: argparse.Namespace) -> cmbs.Model:
    model = cmbs.load(args.model, **unique_pairs((_parameter(p) for p in args.param), "--param"))
    return model.without_drivers() if getattr(args, "undriven", False) else model


def _formulation_options(args: argparse.Namespace) -> dict[str, object]:
    """``--option key=value`` pairs; tuples of names for matrix-r's ``independent``."""
    options = unique_pairs((_parameter(text, "--option") for text in args.option), "--option")
    if isinstance(options.get("independent"), str):
        options["independent"] = tuple(options["independent"].split(","))
    return options


def _simulation_settings(args: argparse.Namespace) -> dict[str, object]:
    settings = {"t_end": args.t_end, "integrator": args.integrator, "dt": args.dt, "rtol": args.rtol,
                "atol": args.atol, "project": args.project}
    if args.projection_tolerance is not None:
        if not args.project:
            raise _UsageError("--projection-tolerance sets the drift projection's tolerance: give --project too")
        settings["projection_tolerance"] = args.projection_tolerance
    return settings


def run_seconds(info: dict) -> float:
    """A run's time without the time it spent compiling kernels (``wall_time - compile_time``)."""
    return info["wall_time"] - info.get("compile_time", 0.0)


def timing(info: dict) -> str:
    """``run R s, compile C s`` of a run's (or a sweep's) ``info``: the compile time, which only
    a first use pays, apart from the run's own time."""
    return f"run {run_seconds(info):.3g} s, compile {info.get('compile_time', 0.0):.3g} s"


#: How :func:`cmbs.simulate.simulate` begins the note saying why a run took the Python loop.
_PYTHON_LOOP_NOTE = "Python loop: "


def _loop_statement(info: dict) -> str:
    """``compiled``, or ``Python loop`` with the reason the run's note gives, in a few words (up to
    its first parenthesis), e.g. ``Python loop (t_end is not a multiple of dt)``."""
    if info.get("compiled"):
        return "compiled"
    for note in info.get("note", "").split("; "):
        if note.startswith(_PYTHON_LOOP_NOTE):
            return f"Python loop ({note[len(_PYTHON_LOOP_NOTE):].split(' (')[0]})"
    return "Python loop"


def _models(args: argparse.Namespace) -> int:
    from cmbs.library import entry, names

    width = max(len(name) for name in names())
    for name in names():
        library_entry = entry(name)
        parameters = library_entry.parameters()
        extra = f"  [{', '.join(f'{k}={v}' for k, v in parameters.items())}]" if parameters else ""
        print(f"{name:<{width}}  {library_entry.summary}{extra}")
    return 0


def _describe(args: argparse.Namespace) -> int:
    model = _load(args)
    report = cmbs.constraint_report(model, model.q0, 0.0)
    print(f"model        {model.name}")
    if model.description:
        print(f"description  {model.description}")
    if model.source:
        print(f"source       {model.source}")
    print(f"coordinates  n = {model.n}")
    for name, kind, value in zip(model.coordinate_names, model.coordinate_kinds, model.q0):
        print(f"  {name:<18} {kind:<9} q0 = {value: .6g}")
    print(f"constraints  m = {model.m} ({int(np.sum(model.drivers))} driver(s))")
    for name, is_driver in zip(model.constraint_names, model.drivers):
        print(f"  {name}{'   [driver]' if is_driver else ''}")
    print(f"rank of A    {report.rank} at q0 (smallest singular value {min(report.singular_values, default=0.0):.3g})")
    print(f"DOF          {report.dof}" + (f" (velocity DOF {report.velocity_dof}: nonholonomic constraints)"
                                            if report.velocity_dof != report.dof else ""))
    print(f"redundant    {', '.join(report.redundant) if report.redundant else 'none'}")
    if model.actuator_names:
        print(f"actuators    {', '.join(model.actuator_names)}")
    if model.segment_masses:
        masses = ", ".join(f"{name} {mass:g}" for name, mass in model.segment_masses)
        print(f"masses [kg]  {masses}; total {model.total_mass:g}")
    print(f"energy at q0 T = {model.kinetic_energy(model.q0, model.qd0):.6g} J, "
          f"V = {model.potential_energy(model.q0):.6g} J")
    sources = model.work_sources
    print("work done by " + ("(not stated by these equations)" if sources is None else ", ".join(sources) if sources
                             else "gravity and springs only: T + V is conserved with zero inputs"))
    return 0


def _kinematics(args: argparse.Namespace) -> int:
    from cmbs.plotting import plot_trajectory, save_figure

    times = _check_time_grid_and_outputs(args)
    model = _load(args)
    motion = cmbs.kinematic_analysis(model, times)
    singular = cmbs.singular_configurations(model, motion)
    saved = f" -> {_save(model, motion, args.out)}" if args.out else ""
    print(f"{model.name}: kinematics of {len(times)} instants over [0, {args.t_end:g}] s{saved}")
    for name in model.coordinate_names:
        column = motion[name]
        print(f"  {name:<18} min {column.min(): .5g}  max {column.max(): .5g}")
    for configuration in singular:
        print(f"  singular configuration at t = {configuration.t:.6g} s: rank {configuration.rank} "
              f"< {configuration.nominal_rank}")
    if args.plot:
        print(f"  figure -> {save_figure(plot_trajectory(motion, model=model), args.plot)}")
    return 0


def _workspace(args: argparse.Namespace) -> int:
    if len(args.sweep) > 2:
        raise _UsageError(f"--sweep: at most two inputs (a grid of two), got {len(args.sweep)}")
    sweeps = [(sweep[0], _sweep_values(sweep)) for sweep in args.sweep]
    for path, suffixes, option in ((args.out, (".npz", ".csv"), "--out"), (args.plot, (".png", ".pdf", ".svg"),
                                                                            "--plot")):
        if path:
            _check_output(path, suffixes, option)
    model = _load(args)
    if len(sweeps) == 1:
        result = _print_sweep(model, *sweeps[0], args.hold)
    else:
        result = _print_grid(model, sweeps, args.hold)
    if args.out:
        print(f"  result -> {result.save(args.out)}")
    if args.plot:
        from cmbs.plotting import save_figure
        from cmbs.workspace_plots import plot_workspace, plot_workspace_grid

        figure = plot_workspace(result) if len(sweeps) == 1 else plot_workspace_grid(result)
        print(f"  figure -> {save_figure(figure, args.plot)}")
    return 0


def _sweep_values(sweep: list[str]) -> np.ndarray:
    """The values of one ``--sweep JOINT START STOP N``."""
    _, start, stop, count = sweep
    try:
        values = np.linspace(float(start), float(stop), int(count))
    except ValueError:
        raise _UsageError(f"--sweep expects JOINT START STOP N (numbers, N an integer), got {' '.join(sweep)}") \
            from None
    if not (np.all(np.isfinite(values)) and int(count) >= 2 and float(stop) > float(start)):
        raise _UsageError(f"--sweep: need START < STOP, finite, and N >= 2, got {' '.join(sweep)}")
    return values


def _print_sweep(model: cmbs.Model, joint: str, values: np.ndarray, hold: list[str]) -> object:
    """Sweep one input and print the range reached, the limits and the singular configurations."""
    from cmbs.workspace import workspace

    result = workspace(model, joint, values, held=hold)
    held = ", ".join(f"{name} held at {value:.6g}" for name, value in result.held.items())
    print(f"{model.name}: sweep of {joint} over [{values[0]:.6g}, {values[-1]:.6g}] ({values.size} values)"
          + (f", {held}" if held else ""))
    print(f"  reached {joint} in [{result.low:.10g}, {result.high:.10g}] ({int(result.reached.sum())} of "
          f"{values.size} values) on the branch of the start")
    for limit in result.limits:
        print(f"  limit at {joint} = {limit.value:.10g}: singular, {_locks(limit)} (sigma_min/sigma_max "
              f"{limit.relative_sigma:.2g} with the inputs held, {limit.chain_relative_sigma:.2g} of the chain)")
    for configuration in result.singular:
        print(f"  singular configuration at {joint} = {configuration.t:.10g}: rank {configuration.rank} < "
              f"{configuration.nominal_rank} with the inputs held")
    _print_ranges(model, result.q[result.reached], [joint, *result.held])
    return result


def _print_grid(model: cmbs.Model, sweeps: list[tuple[str, np.ndarray]], hold: list[str]) -> object:
    """Sweep a grid of two inputs and print the points reached, the limits and the smallest σ ratio."""
    from cmbs.workspace import workspace_grid

    result = workspace_grid(model, *sweeps, held=hold)
    held = ", ".join(f"{name} held at {value:.6g}" for name, value in result.held.items())
    (a, values_a), (b, values_b) = sweeps
    print(f"{model.name}: grid of {a} over [{values_a[0]:.6g}, {values_a[-1]:.6g}] ({values_a.size} values) and {b} "
          f"over [{values_b[0]:.6g}, {values_b[-1]:.6g}] ({values_b.size} values)" + (f", {held}" if held else ""))
    reached = result.reached
    print(f"  reached {int(reached.sum())} of {reached.size} grid points on the branch of the start")
    for k, (name, values) in enumerate(sweeps):
        hit = values[reached.any(axis=1 - k)]
        if hit.size:
            print(f"  {name:<18} reached from {hit[0]:.6g} to {hit[-1]:.6g}")
    kinds: dict[str, list] = {}
    for limit in result.limits:
        kinds.setdefault(_locks(limit), []).append(limit)
    for kind, limits in kinds.items():
        print(f"  {len(limits)} limits located on the grid lines: singular, {kind} (sigma_min/sigma_max with the "
              f"inputs held at most {max(limit.relative_sigma for limit in limits):.2g}, of the chain at least "
              f"{min(limit.chain_relative_sigma for limit in limits):.2g})")
    if reached.any():
        index = np.unravel_index(np.nanargmin(result.relative_sigma), reached.shape)
        print(f"  smallest sigma_min/sigma_max with the inputs held at a grid point reached: "
              f"{result.relative_sigma[index]:.2g} at {a} = {values_a[index[0]]:.6g}, {b} = {values_b[index[1]]:.6g}")
    _print_ranges(model, result.q[reached], [a, b, *result.held])
    return result


def _locks(limit: object) -> str:
    """What happens at a branch's limit: the chain gains a DOF, or the inputs lock."""
    return "the chain gains a DOF" if limit.chain_relative_sigma < 1e-3 else "the inputs lock"


def _print_ranges(model: cmbs.Model, reached: np.ndarray, given: list[str]) -> None:
    """The range of each coordinate that follows over the configurations ``reached``."""
    for k, name in enumerate(model.coordinate_names):
        if reached.size and name not in given:
            print(f"  {name:<18} min {reached[:, k].min(): .6g}  max {reached[:, k].max(): .6g}")


def _simulate(args: argparse.Namespace) -> int:
    from cmbs.simulate import simulate

    for path, suffixes, option in ((args.out, (".npz", ".csv"), "--out"), (args.plot, (".png", ".pdf", ".svg"),
                                   "--plot")):
        if path:
            _check_output(path, suffixes, option)
    if args.animate:
        from cmbs.animate import checked_animation_path

        checked_animation_path(args.animate, "--animate")
    model = _load(args)
    formulation = None if args.formulation is None and args.integrator not in ("rk23", "rk45", "rk4") else \
        (args.formulation or "lagrange")
    run = simulate(model, formulation=formulation, formulation_options=_formulation_options(args),
                   every=args.every, progress=True, **_simulation_settings(args))
    info = run.info
    error = run["constraint_error"]
    print(f"{model.name}: {info['formulation']} + {info['integrator']}, {info['status']} {_reached(run)} "
          f"({info['steps']} steps, {timing(info)}), {_loop_statement(info)}")
    if run.t.size:
        print(f"  max constraint error {error.max(initial=0.0):.3g}, max velocity constraint error "
              f"{run['velocity_constraint_error'].max(initial=0.0):.3g}, {energy_statement(model, run)}")
    if info.get("note"):
        print(f"  note: {info['note']}")
    if args.out:
        print(f"  result -> {_save(model, run, args.out)}")
    if args.plot:
        from cmbs.plotting import plot_simulation, save_figure

        print(f"  figure -> {save_figure(plot_simulation(run, model=model), args.plot) if run.t.size else NOTHING}")
    if args.animate:
        from cmbs.animate import animate

        print(f"  animation -> {animate(model, run, args.animate) if run.t.size else NOTHING}")
    if info["status"] != "success":
        print(f"cmbs: simulation failed: {info['message']}", file=sys.stderr)
        return 1
    return 0


def _save(model: cmbs.Model, run: cmbs.Trajectory, path: str) -> Path:
    """Write ``run`` to the result file ``path`` with the poses of a spatial model's bodies or a
    robot's moving links (:func:`cmbs.kinematics.with_body_poses`); its path."""
    from cmbs.kinematics import with_body_poses

    return with_body_poses(model, run).save(path)


def _energy_balance(model: cmbs.Model, run: cmbs.Trajectory) -> str:
    """max |E - E0 - W| of a run (W the work of its drivers and inputs; 0 for a conservative model
    with zero inputs), or "-" when the model has other sources of work."""
    from cmbs.simulate import supplied_work

    work = supplied_work(model, run) if run.t.size else None
    if work is None:
        return "-"
    energy = run["energy"]
    return f"{np.abs(energy - energy[0] - work).max(initial=0.0):.3g}"


def energy_statement(model: cmbs.Model, run: cmbs.Trajectory) -> str:
    """What a run's energy says: for a conservative model its change max |E - E0| (an error of
    the run); when drivers and inputs do work W (:func:`cmbs.simulate.supplied_work`) the energy
    balance max |E - E0 - W| (an error) beside W; else the change E - E0 with what did the work
    (not an error)."""
    from cmbs.simulate import supplied_work

    energy = run["energy"]
    change = energy - energy[0]
    if "energy_drift" in run.info:
        return (f"max |E - E0| {np.abs(change).max(initial=0.0):.3g} J ({run.info['energy_drift']:.2g} of the "
                f"largest kinetic energy)")
    work = supplied_work(model, run)
    if work is not None and np.any(work != 0):
        return (f"energy balance max |E - E0 - W| {np.abs(change - work).max(initial=0.0):.3g} J (W, the work of "
                f"the drivers and inputs, reaches {np.abs(work).max():.4g} J)")
    if work is not None:
        return f"max |E - E0| {np.abs(change).max(initial=0.0):.3g} J"
    sources = model.work_sources
    doers = ", ".join(sources) if sources else "forces these equations do not name"
    return f"E - E0 {change[-1]:.6g} J at the end (work of {doers}; not an error)"


#: what a run that failed before its first output instant shows instead of a figure or animation
NOTHING = "not written: no instant computed"


def _reached(run: cmbs.Trajectory) -> str:
    """Where a run stopped: its last output instant, or t = 0 when it failed before its first."""
    return f"at t = {run.t[-1]:.6g} s" if run.t.size else "at t = 0 s (no instant computed)"


def _compare(args: argparse.Namespace) -> int:
    from cmbs.dynamics import FORMULATIONS
    from cmbs.simulate import EXPLICIT, simulate

    if args.integrator not in EXPLICIT:
        raise _UsageError(f"--integrator {args.integrator} brings its own formulation; compare runs formulations side "
                          f"by side with an explicit integrator ({', '.join(EXPLICIT)}): use cmbs simulate for it")
    names = list(FORMULATIONS) if args.formulations is None else \
        [name.strip() for name in args.formulations.split(",") if name.strip()]
    if not names:
        raise _UsageError("--formulations needs at least one name, e.g. lagrange,projection")
    model = _load(args)
    runs = {name: simulate(model, formulation=name, **_simulation_settings(args)) for name in names}
    reference = runs[names[0]]
    print(f"{model.name}: {args.integrator}, t_end = {args.t_end:g} s; deviation against {names[0]}")
    print(f"{'formulation':<16}{'status':<9}{'max |dq|':>11}{'max |phi|':>12}{'max|E-E0-W| J':>15}{'drift':>10}"
          f"{'run s':>9}{'compile s':>11}")
    failed = False
    for name, run in runs.items():
        common = min(len(run.t), len(reference.t))
        deviation = np.abs(run.q[:common] - reference.q[:common]).max(initial=0.0)
        drift = f"{run.info['energy_drift']:.3g}" if "energy_drift" in run.info else "-"
        print(f"{name:<16}{run.info['status']:<9}{deviation:>11.3g}{run['constraint_error'].max(initial=0.0):>12.3g}"
              f"{_energy_balance(model, run):>15}{drift:>10}{run_seconds(run.info):>9.3g}"
              f"{run.info['compile_time']:>11.3g}")
        failed |= run.info["status"] != "success"
        if run.info["status"] != "success":
            print(f"  {name}: {run.info['message']}")
    return 1 if failed else 0


def _inverse(args: argparse.Namespace) -> int:
    from cmbs.inverse import inverse_dynamics

    times = _check_time_grid_and_outputs(args)
    model = _load(args)
    if args.motion:
        model = _prescribed(model, args)
    actuated = [name.strip() for name in args.actuated.split(",")] if args.actuated is not None else None
    result = inverse_dynamics(model, times, method=args.method, actuated=actuated, **_formulation_options(args))
    print(f"{model.name}: inverse dynamics ({result.method}) over {len(times)} instants")
    for name in result.driven_coordinates:
        force = result.force(name) + 0.0         # + 0.0: no "-0" for a zero force
        print(f"  force on {name + bracketed(force_unit(model, name)):<20} min {force.min(): .6g}  "
              f"max {force.max(): .6g}  RMS {np.sqrt(np.mean(force**2)):.6g}")
    motion = result.motion
    if args.reactions:
        from cmbs.inverse import joint_reaction_history

        extras = dict(motion.extras)
        for label, value, unit in _reaction_series(model, joint_reaction_history(model, motion)):
            extras[label] = value
            size = np.linalg.norm(value, axis=1) if value.ndim == 2 else np.abs(value)
            print(f"  {label:<32} max {size.max():.6g} {unit}")
        motion = cmbs.Trajectory(motion.t, motion.q, motion.qd, motion.qdd, motion.names, extras, motion.info)
    if args.out:
        print(f"  result -> {_save(model, motion, args.out)}")
    if args.plot:
        from cmbs.plotting import plot_driver_forces, save_figure

        figure = plot_driver_forces(result.motion, result.driven_coordinates, model=model)
        print(f"  figure -> {save_figure(figure, args.plot)}")
    return 0


def _prescribed(model: cmbs.Model, args: argparse.Namespace) -> cmbs.Model:
    """The model driven by ``--motion`` (expressions or a file) on ``--coordinates``."""
    from cmbs.motion import prescribe, read_motion

    coordinates = [name.strip() for name in args.coordinates.split(",")] if args.coordinates else None
    functions = read_motion(args.motion, model, coordinates=coordinates)
    for name, function in functions.items():
        times = getattr(function, "times", None)
        if times is not None and not (times[0] <= 0.0 and args.t_end <= times[-1] + 1e-12):
            raise _UsageError(f"--motion {args.motion}: column {name!r} covers t = {times[0]:g}..{times[-1]:g} s, "
                              f"not 0..{args.t_end:g} s (--t-end)")
    return prescribe(model, functions)


def _reaction_series(model: cmbs.Model, reactions: dict) -> list[tuple[str, np.ndarray, str]]:
    """(label, history, unit) of every joint reaction, for printing and saving; natural-coordinate
    models report forces per segment end (spatial ones: per body point, and couples through its
    unit vectors), joint-coordinate models and robots per link or joint (the force and the moment
    about the joint of the parent on the link; the torque in N m at a revolute joint, the force in
    N along a prismatic one)."""
    if "joint_forces" in reactions:
        return ([(f"reaction on {link}", force, "N") for link, force in reactions["forces"].items()]
                + [(f"moment on {link}", moment, "N m") for link, moment in reactions["moments"].items()]
                + [(f"joint force {name}", force, force_unit(model, name))
                   for name, force in reactions["joint_forces"].items()]
                + [(f"closure force {name}", force, "N") for name, force in reactions["closures"].items()])
    return ([(f"reaction {segment}@{point}", force, "N") for (segment, point), force in reactions["forces"].items()]
            + [(f"couple {body}@{vector}", couple, "N m")
               for (body, vector), couple in reactions.get("vector_couples", {}).items()]
            + [(f"joint torque {angle}", torque, "N m") for angle, torque in reactions["torques"].items()]
            + [(f"slider force {slider}", force, "N") for slider, force in reactions["sliders"].items()])


def _track(args: argparse.Namespace) -> int:
    from cmbs.control import Reference
    from cmbs.control.study import Fault, format_table, robustness_study, track
    from cmbs.inverse.ida import driven_columns

    times = _check_time_grid_and_outputs(args)
    driven = _load(args)
    if args.reference:
        args.motion = args.reference
        driven = _prescribed(driven, args)
    if not driven.drivers.any():
        raise _UsageError(f"model {driven.name!r} has no drivers: give the reference motion with --reference "
                          "or use a driven model")
    faults = [Fault.parse(text) for text in args.fault]
    coordinates = [driven.coordinate_names[c] for c in driven_columns(driven)]
    offset = args.initial_error.in_unit_of(coordinate_unit(driven, coordinates[0]), "--initial-error",
                                           coordinates[0])
    start_error = [Fault.parse(f"initial:{offset!r}")] if offset else []
    motion = cmbs.kinematic_analysis(driven, times)
    plant = driven.without_drivers()
    reference = Reference(motion, coordinates)
    law = _controller(args, plant, reference)
    if args.sample_rate:
        from cmbs.control import ZeroOrderHold

        law = ZeroOrderHold(law, 1.0 / args.sample_rate)
    options = {"rtol": args.rtol, "atol": args.atol, "integrator": args.integrator}
    if args.study:   # each --fault alone; --initial-error in every case
        runs = robustness_study(plant, law, motion, coordinates, t_end=args.t_end, faults=faults, common=start_error,
                                **options)
        print(format_table(runs, f"{plant.name}: {args.controller} robustness study"
                                 + (f" (all cases: {start_error[0].text})" if start_error else "")))
        return 0 if all(run.succeeded for run in runs) else 1
    faults = start_error + faults
    result = track(plant, law, motion, coordinates, t_end=args.t_end, faults=faults,
                   label=", ".join(f.text for f in faults) or "nominal", **options)
    run = result.run
    print(f"{plant.name}: {args.controller} tracking of {', '.join(coordinates)}, {run.info['status']} "
          f"{_reached(run)}")
    nrmse = ", ".join(f"{name} {100 * value:.4g} %" for name, value in zip(coordinates, result.nrmse))
    print(f"  NRMSE (of the reference's range) {nrmse}; settling time (1 %) {_settling(result, motion)}")
    print(f"  actuation RMS norm {result.rms_norm:.6g}, peak norm {result.peak_norm:.6g}")
    if args.out:
        print(f"  result -> {_save(plant, run, args.out)}")
    if args.plot:
        from cmbs.plotting import plot_simulation, save_figure

        print(f"  figure -> {save_figure(plot_simulation(run, model=plant), args.plot) if run.t.size else NOTHING}")
    if not result.succeeded:
        print(f"cmbs: tracking failed: {run.info['message']}", file=sys.stderr)
    return 0 if result.succeeded else 1


def _settling(result: TrackingRun, motion: cmbs.Trajectory) -> str:
    """A tracking run's settling time to 1 % of its initial error, or why there is none: no
    initial error, or the error that remains (its largest share of the initial error over the
    last half of the run: a fault the controller does not know leaves a steady error)."""
    settling = result.settling_time
    if np.isnan(settling):
        return "- (no initial error)"
    if np.isfinite(settling):
        return f"{settling:.4g} s"
    run = result.run
    reference = motion.q[:run.t.size, [motion.names.index(name) for name in result.coordinates]]
    error = np.abs(reference - run.q[:, [run.names.index(name) for name in result.coordinates]])
    late = error[run.t >= run.t[-1] / 2]
    return (f"never: |error| still reaches {100 * late.max() / error[0].max():.3g} % of the initial error in the "
            f"last half of the run")


def _controller(args: argparse.Namespace, plant: cmbs.Model, reference):
    """The control law named by --controller, on the nominal plant."""
    from cmbs.control import PD, PIDC, ComputedTorque, CoordinateOutput, Hybrid, TrackingTask, UdwadiaKalabaTracking

    if args.controller == "pd":
        return PD(plant, reference, kp=args.kp, kd=args.kd)
    if args.controller == "ctc":
        return ComputedTorque(plant, reference, kp=args.kp, kd=args.kd)
    if args.controller == "pidc":
        return PIDC(plant, reference, kp=args.kp, kd=args.kd)
    if args.controller == "hybrid":
        try:
            force = [float(value) for value in args.force.split(",")]
        except ValueError:
            raise _UsageError(f"--force {args.force!r}: expected numbers separated by commas") from None
        return Hybrid(plant, reference, kp=args.kp, kd=args.kd, force_reference=np.array(force), kf=args.kf,
                      ki=args.ki, period=1.0 / args.sample_rate if args.sample_rate else 1e-3)
    task = TrackingTask(CoordinateOutput(plant, reference.coordinates), reference)
    return UdwadiaKalabaTracking(plant, task, kp=args.kp, kd=args.kd)


def _grid(args: argparse.Namespace) -> np.ndarray:
    """The output instants of --t-end and --dt, as ``cmbs.simulate`` records them (0, dt, 2 dt, ...,
    and --t-end)."""
    from cmbs.simulate import output_times

    try:
        return output_times(args.t_end, args.dt, ("--t-end", "--dt"))
    except CmbsError as error:
        raise _UsageError(str(error)) from None


def _check_time_grid_and_outputs(args: argparse.Namespace) -> np.ndarray:
    """The output instants (:func:`_grid`); --out and --plot paths valid (checked before any work)."""
    times = _grid(args)
    for path, suffixes, option in ((args.out, (".npz", ".csv"), "--out"),
                                   (args.plot, (".png", ".pdf", ".svg"), "--plot")):
        if path:
            _check_output(path, suffixes, option)
    return times


def _check_output(path: str, suffixes: tuple[str, ...], option: str) -> None:
    """Check an output path before any work is done, so that a bad --plot cannot fail after the
    result file has already been written."""
    checked_output(path, suffixes, option)


class _DefaultsFormatter(argparse.HelpFormatter):
    """Help that ends each option's text with its default value (``(default: 0.01)``) when it has
    one worth saying (not None, False or empty) and the text does not already give it."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        worth_saying = not (default is None or default is False or default is argparse.SUPPRESS or default == [])
        if action.option_strings and worth_saying and "default" not in text:
            text += " (default: %(default)s)"
        return text


def _show_defaults(parser: argparse.ArgumentParser) -> None:
    """Give ``parser`` and every sub-command's parser, at any depth, the :class:`_DefaultsFormatter`."""
    parser.formatter_class = _DefaultsFormatter
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for command in action.choices.values():
                _show_defaults(command)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="cmbs", description=cmbs.__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"cmbs {cmbs.__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    listing = commands.add_parser("models", help="list the library models", description="List the library models.")
    listing.set_defaults(run=_models)

    def model_command(name: str, text: str) -> argparse.ArgumentParser:
        command = commands.add_parser(name, help=text, description=text)
        command.add_argument("model", metavar="MODEL", help="library model name or path to a .toml model file")
        command.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                             help="parameter of a library model, e.g. links=14 (repeatable)")
        return command

    describe = model_command("describe", "coordinates, constraints, DOF, rank, redundant constraints, masses")
    describe.set_defaults(run=_describe)

    kinematics = model_command("kinematics", "kinematic analysis of a fully driven model over time")
    kinematics.add_argument("--t-end", type=float, required=True, help="final time [s]")
    kinematics.add_argument("--dt", type=float, required=True, help="time step of the output grid [s]")
    kinematics.add_argument("--out", help="result file (.npz or .csv)")
    kinematics.add_argument("--plot", help="figure of the motion (.png, .pdf or .svg)")
    kinematics.set_defaults(run=_kinematics)

    sweep = model_command("workspace", "the range of an input coordinate (or a grid of two) on its assembly branch, "
                                       "the branch's limits and singular configurations")
    sweep.add_argument("--sweep", nargs=4, action="append", required=True, metavar=("JOINT", "START", "STOP", "N"),
                       help="the input coordinate and N values from START to STOP; twice: a grid of two inputs")
    sweep.add_argument("--hold", action="append", default=[], metavar="NAME",
                       help="a coordinate held at its start value (another input; repeatable)")
    sweep.add_argument("--out", help="result file (.npz or .csv)")
    sweep.add_argument("--plot", help="figure (.png, .pdf or .svg)")
    sweep.set_defaults(run=_workspace)

    def dynamics_options(command: argparse.ArgumentParser) -> None:
        from cmbs.simulate import INTEGRATORS

        command.add_argument("--t-end", type=float, required=True, help="final time [s]")
        command.add_argument("--integrator", default="rk45", choices=INTEGRATORS,
                             help="rk45/rk23/dop853 adaptive; rk4, trapezoidal, backward-euler, generalized-alpha "
                                  "fixed step")
        command.add_argument("--dt", type=float, default=0.01,
                             help="step of fixed-step integrators, output interval of adaptive ones [s]")
        command.add_argument("--rtol", type=float, default=1e-6, help="relative tolerance (adaptive)")
        command.add_argument("--atol", type=float, default=1e-9, help="absolute tolerance (adaptive)")
        command.add_argument("--project", action="store_true",
                             help="coordinate and velocity projection after each step and at each output instant")
        command.add_argument("--projection-tolerance", type=float, metavar="TOL",
                             help="with --project: max |constraint| the positions are projected to (default 1e-10; "
                                  "1e-12 keeps the n-four-bar on its branch, docs/formulations.md)")
        command.add_argument("--undriven", action="store_true", help="remove the model's driver constraints")

    simulate = model_command("simulate", "forward dynamics of a model")
    simulate.add_argument("--formulation", choices=_formulation_names(),
                          help="default lagrange (implicit integrators bring their own)")
    simulate.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                          help="formulation option, repeatable: " + _formulation_help())
    dynamics_options(simulate)
    simulate.add_argument("--every", type=int, default=1, metavar="K",
                          help="keep every K-th output instant (0, K dt, 2K dt, ..., --t-end; K divides the steps): "
                               "fixed-step runs still step by --dt but store and write only these")
    simulate.add_argument("--out", help="result file (.npz or .csv)")
    simulate.add_argument("--plot", help="figure: coordinates, energy, constraint error (.png, .pdf, .svg)")
    simulate.add_argument("--animate", help="animation of the mechanism (.gif; .mp4 with ffmpeg; .html: an interactive "
                                            "3-D viewer in one self-contained file)")
    simulate.set_defaults(run=_simulate)

    inverse = model_command("inverse", "inverse dynamics: the forces on the driven coordinates of a driven model")
    inverse.add_argument("--t-end", type=float, required=True, help="final time [s]")
    inverse.add_argument("--dt", type=float, required=True, help="time step of the output grid [s]")
    inverse.add_argument("--method", choices=("lagrange", "baumgarte", "penalty", "matrix-r", "projected"),
                         help="driver multipliers of a formulation, matrix-R Q_IDA, or a robot's joint torques "
                              "(projected; the default for a pose-driven robot, else lagrange)")
    inverse.add_argument("--actuated", metavar="A,B",
                         help="method projected: the joints that carry torque (default all: the minimum-norm "
                              "torques)")
    inverse.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                         help="option of the method's formulation, e.g. alpha=1e8 for penalty")
    inverse.add_argument("--motion", metavar="FILE|EXPR",
                         help="prescribed motion replacing the model's drivers: 'NAME = EXPR; ...' or a .npz/.csv "
                              "file (a cmbs result, or a table with header t,NAME,...)")
    inverse.add_argument("--coordinates", metavar="A,B",
                         help="with --motion FILE: the columns to prescribe (default: the model's driven "
                              "coordinates if the file has them, else every matching column)")
    inverse.add_argument("--reactions", action="store_true",
                         help="also the joint reactions: at every segment end, joint torques and slider forces "
                              "(natural coordinates; in 3-D at every body point, and couples through its unit "
                              "vectors); at every joint and closure (joint coordinates and robots: the force and moment of "
                              "the parent on the link, and the joint's torque or force)")
    inverse.add_argument("--out", help="result file (.npz or .csv) with the motion and driver_forces")
    inverse.add_argument("--plot", help="figure of the forces and the motion")
    inverse.set_defaults(run=_inverse)

    track = model_command("track", "closed-loop tracking of a driven model's motion by its actuators")
    track.add_argument("--controller", choices=("pd", "ctc", "pidc", "hybrid", "udwadia-kalaba"), default="ctc",
                       help="PD, computed torque, projected inverse dynamics (PIDC), hybrid motion/force, or "
                            "Udwadia-Kalaba tracking (docs/control.md)")
    track.add_argument("--force", default="0",
                       help="hybrid: desired constraint multipliers λ_d, one per constraint row (comma-separated)")
    track.add_argument("--kf", type=float, default=0.5, help="hybrid: proportional force gain (0 <= kf < 1)")
    track.add_argument("--ki", type=float, default=10.0, help="hybrid: integral force gain [1/s]")
    track.add_argument("--kp", type=float, default=100.0, help="proportional gain (ctc: s^-2; pd: force/unit)")
    track.add_argument("--kd", type=float, default=20.0, help="derivative gain (ctc: s^-1; pd: force s/unit)")
    track.add_argument("--reference", metavar="FILE|EXPR",
                       help="reference motion replacing the model's drivers: 'NAME = EXPR; ...' or a .npz/.csv file")
    track.add_argument("--coordinates", metavar="A,B", help="with --reference FILE: the columns to track")
    track.add_argument("--fault", action="append", default=[],
                       help="a fault (repeatable): mass:SEGMENT:FACTOR[:T0], offset:VALUE[:T0], scale:FACTOR[:T0], "
                            "noise:SIGMA[:SEED] or initial:DELTA")
    track.add_argument("--study", action="store_true",
                       help="robustness study: the nominal run and one run per --fault, as a table (thesis Table 7.2)")
    track.add_argument("--initial-error", type=Offset.parse, default=Offset(0.0), metavar="VALUE[deg]",
                       help="offset of the first driven coordinate at t = 0 (wrong initial state), in the "
                            "coordinate's unit (rad for an angle, m for a length) or in degrees as 5deg")
    track.add_argument("--t-end", type=float, required=True, help="final time [s]")
    track.add_argument("--dt", type=float, default=0.01,
                       help="output interval [s]; also the step of fixed-step integrators")
    track.add_argument("--integrator", default="rk45", choices=_integrator_names(), help="time integrator")
    track.add_argument("--sample-rate", type=float, metavar="HZ",
                       help="digital controller: sample and hold the law at this rate (e.g. 1000)")
    track.add_argument("--rtol", type=float, default=1e-8, help="relative tolerance (adaptive integrators)")
    track.add_argument("--atol", type=float, default=1e-10, help="absolute tolerance (adaptive integrators)")
    track.add_argument("--out", help="result file (.npz or .csv)")
    track.add_argument("--plot", help="figure (.png, .pdf, .svg)")
    track.set_defaults(run=_track)

    compare = model_command("compare", "run several formulations on the same model and tabulate them")
    compare.add_argument("--formulations", help="comma-separated names, the first is the reference (default: all "
                         "six, lagrange first)")
    dynamics_options(compare)
    compare.set_defaults(run=_compare)

    from cmbs.gait.commands import add_gait_commands
    from cmbs.sweep_cli import add_sweep_command

    add_sweep_command(commands, model_command, dynamics_options)
    add_gait_commands(commands)
    _show_defaults(parser)
    return parser


def _integrator_names() -> tuple[str, ...]:
    from cmbs.simulate import INTEGRATORS

    return INTEGRATORS


def _formulation_names() -> list[str]:
    from cmbs.dynamics import FORMULATIONS

    return list(FORMULATIONS)


def _formulation_help() -> str:
    import dataclasses

    from cmbs.dynamics import FORMULATIONS

    parts = []
    for name, cls in FORMULATIONS.items():
        fields = [f"{field.name}={field.default}" for field in dataclasses.fields(cls) if field.name != "nonideal"]
        parts.append(f"{name}: {', '.join(fields) or 'none'}")
    return "; ".join(parts)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``cmbs`` console script; returns the exit status.

    Called without ``argv``, as the console script and ``python -m cmbs.cli`` call it, it owns
    its process and keeps the garbage collector from walking the objects that live as long as
    the process (:func:`cmbs.collector.settle_the_command_process`: frozen after the imports, at
    numba's first compiled call and at exit).  Called with ``argv`` from a program, it leaves
    that program's collector alone."""
    if argv is None:
        from cmbs.collector import settle_the_command_process

        settle_the_command_process()
    parser = build_parser()
    args = parser.parse_args(argv)
    if sys.stderr.isatty():
        from cmbs.jit import announce_compilation

        announce_compilation(lambda line: print(line, file=sys.stderr, flush=True))
    previous = _catch_sigterm()
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warning(warnings.showwarning)
            _check_numbers(args)
            return args.run(args)
    except _Terminated:
        print("cmbs: terminated", file=sys.stderr)
        return 143
    except CmbsError as error:
        print(f"cmbs: error: {error}", file=sys.stderr)
        return error.exit_status
    except KeyboardInterrupt:
        print("cmbs: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:            # the reader of the output stopped (e.g. `| head`): not an error
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())   # no second error at exit
        return 0
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _one_line_warning(show):
    """``warnings.showwarning`` that prints a :class:`~cmbs.errors.CmbsWarning` as the line
    ``cmbs: warning: ...`` on standard error and hands other warnings to ``show``."""

    def shown(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, CmbsWarning):
            print(f"cmbs: warning: {message}", file=sys.stderr)
        else:
            show(message, category, filename, lineno, file, line)

    return shown


def _catch_sigterm():
    """Turn SIGTERM into :class:`_Terminated` (main thread only); the previous handler, or None."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGTERM, _terminate)


if __name__ == "__main__":
    sys.exit(main())
