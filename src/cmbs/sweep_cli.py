"""The ``cmbs sweep`` command: a grid of library-model parameters, segment masses and initial
speeds, run by :func:`cmbs.sweep.sweep` (batched, local processes or a Dask cluster)."""

from __future__ import annotations

import argparse
import sys
from itertools import product
from typing import Callable

import numpy as np

from cmbs.errors import CmbsError, check_in_range, did_you_mean


class SweepUsageError(CmbsError):
    """A bad ``cmbs sweep`` option."""


def add_sweep_command(commands, model_command: Callable, dynamics_options: Callable) -> None:
    """Register ``cmbs sweep`` on the ``commands`` sub-parsers."""
    command = model_command("sweep", "many runs of one model: a grid of parameters, segment masses and initial "
                                     "speeds, batched, in local processes or on a Dask cluster")
    command.add_argument("--formulation", help="formulation of every run (default lagrange; none with an implicit "
                                               "integrator, which brings its own)")
    dynamics_options(command)
    command.add_argument("--vary", action="append", default=[], metavar="KEY=V1,V2,...",
                         help="library-model parameter values to sweep (repeatable: the grid of all of them)")
    command.add_argument("--mass", action="append", default=[], metavar="SEGMENT=F1,F2,...",
                         help="mass factors of a segment (natural coordinates; repeatable, part of the grid)")
    command.add_argument("--speed", metavar="COORDINATE=V1,V2,...",
                         help="initial velocity of one coordinate, the others made consistent (part of the grid)")
    command.add_argument("--every", type=int, default=1, help="record every N-th step of --dt (default 1)")
    command.add_argument("--workers", type=int, help="local worker processes (default: the CPUs; 1: this process)")
    command.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="run on this Dask scheduler")
    command.add_argument("--worker-timeout", type=float, default=60.0, metavar="SECONDS",
                         help="Dask: give up when the cluster has had no worker this long; the variants not done "
                              "fail")
    command.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                         help="progress bar on stderr (default: when stderr is a terminal)")
    command.add_argument("--coordinate", help="coordinate of the figure (default: the first)")
    command.add_argument("--out", help="sweep result (.npz)")
    command.add_argument("--plot", help="figure: the coordinate in every variant, energy changes (.png, .pdf, .svg)")
    command.set_defaults(run=_sweep)


def _values(text: str, option: str) -> tuple[str, list]:
    key, sep, raw = text.partition("=")
    if not sep or not key or not raw:
        raise SweepUsageError(f"{option} expects NAME=V1,V2,..., got {text!r}")
    from cmbs.cli import FLAGS

    values = []
    for item in raw.split(","):
        lowered = item.strip().lower()
        if lowered in FLAGS:
            values.append(FLAGS[lowered])
            continue
        try:
            values.append(int(item) if item.strip().lstrip("-").isdigit() else float(item))
        except ValueError:
            values.append(item.strip())
    return key, values


def _numbers(key: str, values: list, option: str) -> list[float]:
    if not all(isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)
               for value in values):
        raise SweepUsageError(f"{option} {key}: expected numbers, got {values}")
    check_in_range(values, f"{option} {key}")
    return [float(value) for value in values]


def variants_from(args: argparse.Namespace, model) -> list:
    """The grid of ``--vary``, ``--mass`` and ``--speed`` as :class:`~cmbs.sweep.Variant` s."""
    from cmbs.kinematics import velocities
    from cmbs.sweep import Variant

    from cmbs.library import check_parameters, names

    from cmbs.cli import unique_pairs

    fixed = _fixed_parameters(args.param)
    unique_pairs((_values(text, "--vary") for text in args.vary), "--vary")
    unique_pairs((_values(text, "--mass") for text in args.mass), "--mass")
    axes = [("parameter", *_values(text, "--vary")) for text in args.vary]
    if axes and args.model in names():
        for _, key, values in axes:              # each value of the grid, checked before any run
            for value in values:
                check_parameters(args.model, **{**fixed, key: value})
    axes += [("mass", key, _numbers(key, values, "--mass")) for key, values in
             (_values(text, "--mass") for text in args.mass)]
    for kind, key, factors in axes:
        if kind == "mass" and min(factors) <= 0:
            raise SweepUsageError(f"--mass {key}: mass factors must be > 0, got {factors}")
    if args.speed:
        key, values = _values(args.speed, "--speed")
        if key not in model.coordinate_names:
            raise SweepUsageError(f"--speed: model {model.name!r} has no coordinate {key!r}"
                                  f"{did_you_mean(key, model.coordinate_names)}; coordinates: "
                                  f"{_listing(model.coordinate_names)}")
        axes.append(("speed", key, _numbers(key, values, "--speed")))
    if not axes:
        raise SweepUsageError("cmbs sweep needs at least one of --vary, --mass or --speed")
    variants = []
    for choice in product(*(axis[2] for axis in axes)):
        parameters, masses, qd0, label = dict(fixed), {}, None, []
        for (kind, key, _), value in zip(axes, choice):
            label.append(_label(model, kind, key, value))
            if kind == "parameter":
                parameters[key] = value
            elif kind == "mass":
                masses[key] = value
            else:
                guess = np.zeros(model.n)
                guess[model.coordinate_names.index(key)] = value
                qd0 = velocities(model, model.q0, qd=guess, fixed=[key])
        variants.append(Variant(parameters=parameters, masses=masses, qd0=qd0, label=", ".join(label)))
    return variants


def _label(model, kind: str, key: str, value: object) -> str:
    """How a variant's value reads in tables and figures: ``crank_speed=2`` for a parameter,
    ``mass(crank)×1.1`` for a mass factor, ``dalpha/dt=-2 rad/s`` for an initial speed."""
    from cmbs.units import coordinate_unit

    if kind == "mass":
        return f"mass({key})×{value:g}"
    if kind == "speed":
        unit = coordinate_unit(model, key)
        return f"d{key}/dt={value:g}" + (f" {unit}/s" if unit else "")
    return f"{key}={value}"


def _work_done_by(model) -> str:
    """What changes the energy of a variant whose drift is not judged: the model's work sources,
    else its inputs."""
    sources = model.work_sources
    if sources is None:
        return "work of forces its equations do not name"
    return "work of " + (", ".join(sources) if sources else "the inputs")


def _listing(names, shown: int = 12) -> str:
    """The first ``shown`` names, and how many there are in all when more."""
    names = list(names)
    return ", ".join(names[:shown]) + (f", ... ({len(names)} in all)" if len(names) > shown else "")


def _fixed_parameters(texts: list[str]) -> dict[str, object]:
    """The ``--param`` options as a dict (each key once)."""
    from cmbs.cli import unique_pairs

    return unique_pairs((_fixed(text) for text in texts), "--param")


def _fixed(text: str) -> tuple[str, object]:
    key, values = _values(text, "--param")
    if len(values) != 1:
        raise SweepUsageError(f"--param takes one value (use --vary for several), got {text!r}")
    return key, values[0]


def _sweep(args: argparse.Namespace) -> int:
    from cmbs import load
    from cmbs.files_io import checked_output
    from cmbs.simulate import ENERGY_NOTE
    from cmbs.sweep import sweep

    for path, suffixes, option in ((args.out, (".npz",), "--out"), (args.plot, (".png", ".pdf", ".svg"), "--plot")):
        if path:
            checked_output(path, suffixes, option)
    if args.every < 1 or (args.workers is not None and args.workers < 1):
        raise SweepUsageError(f"--every and --workers must be >= 1 (got {args.every}, {args.workers})")
    from cmbs.dynamics import FORMULATIONS

    if args.formulation is not None and args.formulation not in FORMULATIONS:
        hint = did_you_mean(args.formulation, FORMULATIONS)
        raise SweepUsageError(f"--formulation: unknown {args.formulation!r}{hint}; choose one of "
                              f"{', '.join(FORMULATIONS)}")
    if args.undriven and args.vary:
        raise SweepUsageError("--undriven cannot be combined with --vary (the varied model is rebuilt by name)")
    parameters = _fixed_parameters(args.param)
    nominal = load(args.model, **parameters)
    nominal = nominal.without_drivers() if args.undriven else nominal
    variants = variants_from(args, nominal)
    target = args.model if args.vary else nominal   # parameter variants rebuild the model by name
    if args.coordinate and args.coordinate not in nominal.coordinate_names:
        raise SweepUsageError(f"--coordinate: no coordinate {args.coordinate!r}; coordinates: "
                              f"{_listing(nominal.coordinate_names)}")
    result = sweep(target, variants, t_end=args.t_end, formulation=args.formulation, integrator=args.integrator,
                   dt=args.dt, rtol=args.rtol, atol=args.atol, project=args.project, every=args.every,
                   workers=args.workers, scheduler=args.scheduler, worker_timeout=args.worker_timeout,
                   progress=sys.stderr.isatty() if args.progress is None else args.progress)
    failed = int(np.count_nonzero(result.status != "success"))
    mode, used = result.info["mode"], result.info["workers"]
    where = {"dask": f"scheduler {used}", "batched": f"{used} threads"}.get(
        mode, "in this process" if used == 1 or len(result) == 1 else f"{used} worker processes")
    from cmbs.cli import timing

    workers_compiled = result.info.get("worker_compile_time")
    compiled_elsewhere = "" if workers_compiled is None else f" (the workers compiled for {workers_compiled:.3g} s)"
    print(f"{nominal.name}: {len(result)} variants, {mode} ({where}), {timing(result.info)}{compiled_elsewhere}, "
          f"{failed} failed")
    work = _work_done_by(nominal)
    for v, variant in enumerate(result.variants):
        energy = result.energy[v, :result.recorded[v]]
        change = float(np.abs(energy - energy[0]).max()) if energy.size else float("nan")
        judged = not np.isnan(result.energy_drift[v])
        drift = f"{result.energy_drift[v]:.2g}" if judged else "-"
        note = "" if judged else f"  (E - E0: {work}, not an error)"
        note += "" if result.status[v] == "success" else f"  FAILED: {result.message[v]}"
        print(f"  {variant['label']:<40} max|Φ| {np.nanmax(result.constraint_error[v]):9.2e}  max|E - E0| "
              f"{change:9.3g} J  drift {drift:>7}{note}")
    drifting = np.flatnonzero(result.energy_drift > ENERGY_NOTE)
    if drifting.size:
        print(f"  note: {drifting.size} conservative variant(s) changed their energy T + V by more than "
              f"{100 * ENERGY_NOTE:g} % of their largest kinetic energy (drift = max|E - E0| / max T): a smaller "
              f"--dt (or --rtol) reduces the integration error")
    if args.out:
        print(f"  result -> {result.save(args.out)}")
    if args.plot:
        from cmbs.plotting import plot_sweep, save_figure

        figure = plot_sweep(result, args.coordinate or nominal.coordinate_names[0])
        print(f"  figure -> {save_figure(figure, args.plot)}")
    return 1 if failed else 0
