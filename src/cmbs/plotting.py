"""Figures of a :class:`~cmbs.trajectory.Trajectory` (a leaf: compute first, then plot)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from cmbs.errors import CmbsError  # noqa: E402
from cmbs.files_io import atomic_path, checked_output  # noqa: E402
from cmbs.kinematics import point_array  # noqa: E402
from cmbs.model.model import Model  # noqa: E402
from cmbs.trajectory import Trajectory  # noqa: E402

if TYPE_CHECKING:
    from cmbs.sweep import SweepResult


def plot_trajectory(trajectory: Trajectory, *, model: Model | None = None,
                    coordinates: Sequence[str] | None = None, snapshots: int = 8) -> plt.Figure:
    """Coordinates, velocities and accelerations against time, one row per unit of the
    coordinates with ``model`` (m, rad: :func:`cmbs.units.coordinate_unit`; a single row
    without); with ``model``, also the mechanism drawn at ``snapshots`` instants (lighter =
    earlier) beside them."""
    names = list(coordinates) if coordinates else list(trajectory.names)
    unknown = [name for name in names if name not in trajectory.names]
    if unknown:
        raise CmbsError(f"no coordinate(s) {', '.join(unknown)}; coordinates: {', '.join(trajectory.names)}")
    groups = _unit_groups(names, _coordinate_units(model, names))
    columns = 3 + (model is not None)
    figure = plt.figure(figsize=(4.2 * columns, 3.8 * len(groups)), layout="constrained")
    grid = figure.add_gridspec(len(groups), columns)
    for row, (unit, group) in enumerate(groups):
        index = [trajectory.names.index(name) for name in group]
        for column, (data, label, per) in enumerate(zip((trajectory.q, trajectory.qd, trajectory.qdd),
                                                        ("position", "velocity", "acceleration"),
                                                        ("", "/s", "/s²"))):
            axis = figure.add_subplot(grid[row, column])
            for k, name in zip(index, group):
                axis.plot(trajectory.t, data[:, k], label=name)
            axis.set_xlabel("t [s]")
            axis.set_title(label + (f" [{unit}{per}]" if unit else ""))
            axis.grid(alpha=0.3)
            if column == 0:
                axis.legend(fontsize="small")
    if model is not None:
        draw_snapshots(figure.add_subplot(grid[:, -1]), model, trajectory, snapshots)
    figure.suptitle(trajectory.info.get("model", ""))
    return figure


#: The number of coordinates :func:`plot_simulation` draws when none are chosen.
MAX_DEFAULT_COORDINATES = 8


def plot_simulation(trajectory: Trajectory, *, model: Model | None = None,
                    coordinates: Sequence[str] | None = None, snapshots: int = 8) -> plt.Figure:
    """An overview of a simulation, one panel per quantity the trajectory holds.

    Panels, in this order, laid out at most three to a row:

    * **coordinates** against time: the chosen ``coordinates``, or by default all of them,
      but at most the first :data:`MAX_DEFAULT_COORDINATES` (the title then says so); with
      ``model``, one panel per unit (m, rad: :func:`cmbs.units.coordinate_unit`);
    * **energy** T + V against time (extra ``energy``), and **energy drift** E(t) - E(0)
      in its own panel, titled with max |E - E(0)|; with ``model``, when moving drivers or
      inputs do work W (:func:`cmbs.simulate.supplied_work`), the **energy balance**
      E(t) - E(0) - W(t) instead;
    * **constraint errors** max|Φ| and max|Φ̇| against time on a log scale (extras
      ``constraint_error`` and ``velocity_constraint_error``).  Samples that are exactly zero
      cannot be drawn on a log scale: they are left out and the legend counts them; a
      quantity that is zero throughout is not drawn and the title says so (if nothing is
      positive the panel falls back to a linear scale and draws the zeros).  The scale stops
      at the rounding level eps max(|q|, 1) (a projected run reaches 1e-30); an adaptive run
      draws its ``atol`` as a dashed line;
    * with ``model``, the **mechanism** at ``snapshots`` instants (:func:`draw_snapshots`), x
      and z in m.

    Panels whose extras the trajectory lacks (e.g. a kinematic analysis has no energy) are
    left out, so ``len(figure.axes)`` is the number of panels shown; the panels of a shorter
    last row share its width (no empty cell).  A failed run
    (``info["status"] == "failed"``) says so in the figure title.
    """
    if len(trajectory.t) == 0:
        raise CmbsError("cannot plot an empty trajectory (no samples)")
    if coordinates is not None:
        names = list(coordinates)
        if not names:
            raise CmbsError(f"no coordinates chosen; coordinates: {', '.join(trajectory.names)}")
        unknown = [name for name in names if name not in trajectory.names]
        if unknown:
            raise CmbsError(f"no coordinate(s) {', '.join(unknown)}; coordinates: {', '.join(trajectory.names)}")
        note = ""
    else:
        names = list(trajectory.names[:MAX_DEFAULT_COORDINATES])
        hidden = len(trajectory.names) - len(names)
        note = f" (first {len(names)} of {len(trajectory.names)}; choose with coordinates=)" if hidden > 0 else ""

    panels = []
    units = _coordinate_units(model, names)
    for unit, group in _unit_groups(names, units):
        panels.append(lambda axis, unit=unit, group=group: _draw_coordinates(axis, trajectory, group, note, unit))
    if "energy" in trajectory.extras:
        energy = np.asarray(trajectory.extras["energy"], dtype=float).reshape(len(trajectory.t), -1)[:, 0]
        panels.append(lambda axis: _draw_energy(axis, trajectory.t, energy))
        work = None if "energy_drift" in trajectory.info else _supplied_work(model, trajectory)
        if work is None or not np.any(work != 0):
            panels.append(lambda axis: _draw_energy_drift(axis, trajectory.t, energy,
                                                          trajectory.info.get("energy_drift")))
        else:
            panels.append(lambda axis: _draw_energy_balance(axis, trajectory.t, energy, work))
    errors = [(label, key) for label, key in ((r"position $\max|\Phi|$", "constraint_error"),
                                              (r"velocity $\max|\dot\Phi|$", "velocity_constraint_error"))
              if key in trajectory.extras]
    if errors:
        panels.append(lambda axis: _draw_constraint_errors(axis, trajectory, errors))
    if model is not None:
        panels.append(lambda axis: draw_snapshots(axis, model, trajectory, snapshots))

    figure, cells = _panel_grid(len(panels))
    for draw, axis in zip(panels, cells):
        draw(axis)
    title = trajectory.info.get("model", "")
    how = ", ".join(str(trajectory.info[key]) for key in ("analysis", "formulation", "integrator")
                    if trajectory.info.get(key))
    title = f"{title} ({how})" if how and title else title or how
    if trajectory.info.get("status") == "failed":
        message = trajectory.info.get("message", "")
        title += f" - run FAILED at t = {trajectory.t[-1]:.6g} s" + (f": {message}" if message else "")
    figure.suptitle(title)
    return figure


def _panel_grid(count: int) -> tuple[plt.Figure, list[plt.Axes]]:
    """A figure of ``count`` panels, at most three to a row, with no empty cell: the panels of a
    shorter last row share its width."""
    columns = min(3, count)
    rows = -(-count // columns)
    figure = plt.figure(figsize=(4.4 * columns, 3.6 * rows), layout="constrained")
    width = 6                                   # a multiple of every row length (1, 2 or 3 panels)
    grid = figure.add_gridspec(rows, width)
    cells = []
    for row in range(rows):
        in_row = min(columns, count - row * columns)
        span = width // in_row
        cells += [figure.add_subplot(grid[row, k * span:(k + 1) * span]) for k in range(in_row)]
    return figure, cells


def _coordinate_units(model: Model | None, names: Sequence[str]) -> list[str]:
    """The unit of each coordinate (:func:`cmbs.units.coordinate_unit`); "" without a model."""
    if model is None:
        return [""] * len(names)
    from cmbs.units import coordinate_unit

    return [coordinate_unit(model, name) for name in names]


def _supplied_work(model: Model | None, trajectory: Trajectory) -> np.ndarray | None:
    """The work of the drivers and inputs of a simulation (:func:`cmbs.simulate.supplied_work`),
    None without a model or when other forces do work."""
    if model is None or not {"constraint_force", "u"} <= set(trajectory.extras):
        return None
    from cmbs.simulate import supplied_work

    return supplied_work(model, trajectory)


def _draw_coordinates(axis: plt.Axes, trajectory: Trajectory, names: list[str], note: str, unit: str = "") -> None:
    for name in names:
        axis.plot(trajectory.t, trajectory.q[:, trajectory.names.index(name)], label=name)
    axis.set_xlabel("t [s]")
    if unit:
        axis.set_ylabel(f"[{unit}]")
    axis.set_title(("coordinates" if not unit else f"coordinates [{unit}]") + note, fontsize="medium")
    axis.legend(fontsize="small")
    axis.grid(alpha=0.3)


def _draw_energy(axis: plt.Axes, t: np.ndarray, energy: np.ndarray) -> None:
    axis.plot(t, energy, color="C3")
    axis.set_xlabel("t [s]")
    axis.set_ylabel("E = T + V [J]")
    axis.set_title(f"total energy, E(0) = {energy[0]:.6g} J", fontsize="medium")
    axis.ticklabel_format(axis="y", useOffset=False)
    axis.grid(alpha=0.3)


def _draw_energy_drift(axis: plt.Axes, t: np.ndarray, energy: np.ndarray, relative: float | None) -> None:
    """E(t) - E(0); titled a drift, with the run's relative drift max |E - E0| / max T, when it
    was judged (a conservative model: ``info["energy_drift"]``), else a change."""
    drift = energy - energy[0]
    axis.plot(t, drift, color="C3")
    axis.axhline(0.0, color="0.5", linewidth=0.8)
    axis.set_xlabel("t [s]")
    axis.set_ylabel("E(t) - E(0) [J]")
    worst = np.nanmax(np.abs(drift)) if np.any(np.isfinite(drift)) else float("nan")
    # raised above the axis' power-of-ten label (e.g. "1e-6"), which matplotlib puts at its top left
    share = "" if relative is None else f"\n= {relative:.2g} of the largest kinetic energy"
    what = "energy drift" if relative is not None else "energy change"     # a drift only where E is conserved
    axis.set_title(f"{what}, max |E - E(0)| = {worst:.3g} J{share}", fontsize="medium", pad=14)
    axis.grid(alpha=0.3)


def _draw_energy_balance(axis: plt.Axes, t: np.ndarray, energy: np.ndarray, work: np.ndarray) -> None:
    """E(t) - E(0) - W(t), W the work of the drivers and inputs: zero for the exact motion."""
    balance = energy - energy[0] - work
    axis.plot(t, balance, color="C3")
    axis.axhline(0.0, color="0.5", linewidth=0.8)
    axis.set_xlabel("t [s]")
    axis.set_ylabel("E(t) - E(0) - W(t) [J]")
    axis.set_title(f"energy balance, max |E - E(0) - W| = {np.nanmax(np.abs(balance)):.3g} J\n"
                   f"(W: work of the drivers and inputs, up to {np.nanmax(np.abs(work)):.3g} J)", fontsize="medium",
                   pad=14)
    axis.grid(alpha=0.3)


def _error_floor(trajectory: Trajectory) -> float:
    """The smallest constraint error worth drawing: the rounding level of the run's coordinates,
    eps max(|q|, 1); a smaller |Φ| is rounding noise (a projected run reaches 1e-30)."""
    scale = float(np.nanmax(np.abs(trajectory.q), initial=1.0))
    return float(np.finfo(float).eps * max(scale, 1.0))


def _tolerance(trajectory: Trajectory) -> float | None:
    """The absolute tolerance of an adaptive run (``info["atol"]``), else None."""
    from cmbs.integrate.tableaus import NAMES as EXPLICIT

    info = trajectory.info
    adaptive = info.get("integrator") in EXPLICIT and info.get("integrator") != "rk4"
    return float(info["atol"]) if adaptive and "atol" in info else None


def _draw_constraint_errors(axis: plt.Axes, trajectory: Trajectory, errors: list[tuple[str, str]]) -> None:
    series = []
    for (label, key), color in zip(errors, ("C0", "C1")):
        values = np.asarray(trajectory.extras[key], dtype=float).reshape(len(trajectory.t), -1)[:, 0]
        series.append((label, values, color))
    any_positive = any(np.any(np.isfinite(v) & (v > 0)) for _, v, _ in series)
    notes = []
    for label, values, color in series:
        short = label.split()[0]
        if not np.any(np.isfinite(values)):
            notes.append(f"{short}: no finite values")
            continue
        if np.all(values == 0):
            notes.append(f"{short}: all exactly 0")
            if any_positive:
                continue  # nothing to draw on the log scale; the title says it
        if any_positive:
            shown = np.where(np.isfinite(values) & (values > 0), values, np.nan)
            left_out = int(np.sum(values == 0))
            if left_out:
                label += f" ({left_out} exact zero{'s' if left_out > 1 else ''} not shown)"
        else:
            shown = values
        axis.plot(trajectory.t, shown, "-", marker=".", markersize=2, linewidth=1, color=color, label=label)
    if any_positive:
        axis.set_yscale("log")
        floor = _error_floor(trajectory)
        if any(np.any((v > 0) & (v < floor)) for _, v, _ in series):
            axis.set_ylim(bottom=floor)
            notes.append(f"floor {floor:.0e}: rounding")
        tolerance = _tolerance(trajectory)
        if tolerance is not None:
            axis.axhline(tolerance, color="0.4", linestyle="--", linewidth=0.8, label=f"atol {tolerance:.0e}")
    axis.set_xlabel("t [s]")
    axis.set_title("constraint errors" + (" (log)" if any_positive else "") + ("\n" + "; ".join(notes) if notes
                                                                              else ""), fontsize="medium")
    if axis.lines:
        axis.legend(fontsize="small")
    axis.grid(alpha=0.3, which="both" if any_positive else "major")


def draw_snapshots(axis: plt.Axes, model: Model, trajectory: Trajectory, count: int) -> None:
    """The model's segments at ``count`` evenly spaced samples of the trajectory: in the plane
    (x, z), or for a spatial model in a 3-D panel that takes the place of ``axis``."""
    samples = np.linspace(0, len(trajectory.t) - 1, max(count, 1)).round().astype(int)
    poses = [point_array(model, trajectory.q[k]) for k in samples]
    if poses and poses[0].shape[1] == 3:
        _draw_snapshots_3d(axis, model, poses)
        return
    for shade, points in zip(np.linspace(0.25, 1.0, len(samples)), poses):
        for i, j in model.lines:
            axis.plot(points[[i, j], 0], points[[i, j], 1], "-o", color=plt.cm.Blues(shade), markersize=3)
    axis.set_aspect("equal", adjustable="datalim")
    metres = any(kind != "generic" for kind in model.coordinate_kinds)   # a user's own equations: unknown
    axis.set(xlabel="x [m]" if metres else "x", ylabel="z [m]" if metres else "z")
    axis.set_title("mechanism (x, z)")
    axis.grid(alpha=0.3)


def _draw_snapshots_3d(axis: plt.Axes, model: Model, poses: list[np.ndarray]) -> None:
    """:func:`draw_snapshots` of a spatial model: a 3-D panel in ``axis``'s place, equal scales."""
    figure = axis.figure
    spec = axis.get_subplotspec()
    axis.remove()
    axis = figure.add_subplot(spec, projection="3d")
    for shade, points in zip(np.linspace(0.25, 1.0, len(poses)), poses):
        for i, j in model.lines:
            axis.plot(points[[i, j], 0], points[[i, j], 1], points[[i, j], 2], "-o", color=plt.cm.Blues(shade),
                      markersize=3)
    every = np.concatenate(poses)
    low, high = every.min(axis=0), every.max(axis=0)
    half = 0.5 * max(float(np.max(high - low)), 1e-9)
    for centre, limits in zip(0.5 * (low + high), (axis.set_xlim, axis.set_ylim, axis.set_zlim)):
        limits(centre - half, centre + half)
    axis.set_box_aspect((1.0, 1.0, 1.0))
    axis.set(xlabel="x [m]", ylabel="y [m]", zlabel="z [m]")
    axis.set_title("mechanism (x, y, z)")


def save_figure(figure: plt.Figure, path: str | os.PathLike) -> Path:
    """Write a figure atomically (temp file in the same folder, then rename)."""
    path = checked_output(path, (".png", ".pdf", ".svg"), "figure")
    try:
        with atomic_path(path) as temporary:
            figure.savefig(temporary, dpi=120, format=path.suffix.lower()[1:])
    finally:
        plt.close(figure)
    return path


def plot_driver_forces(trajectory: Trajectory, driven: Sequence[str], *, model: Model | None = None) -> plt.Figure:
    """Inverse dynamics: the generalized force on each driven coordinate against time, and the
    prescribed coordinates themselves; with ``model``, one panel per unit (torques in N m on
    angles, forces in N on lengths; coordinates in rad and m, :mod:`cmbs.units`)."""
    from cmbs.units import FORCE

    forces = np.asarray(trajectory.extras["driver_forces"])
    units = _coordinate_units(model, driven)
    force_groups = _unit_groups(driven, [FORCE.get(unit, "") for unit in units])
    motion_groups = _unit_groups(driven, units)
    panels = len(force_groups) + len(motion_groups)
    figure, axes = plt.subplots(panels, 1, figsize=(8, 3 * panels), sharex=True, constrained_layout=True,
                                squeeze=False)
    axes = list(axes[:, 0])
    for axis, (unit, names) in zip(axes, force_groups):
        for name in names:
            axis.plot(trajectory.t, forces[:, list(driven).index(name)], label=f"on {name}")
        kind = {"N m": "torques", "N": "forces"}.get(unit, "forces / torques")
        axis.set(title=f"driving {kind} (inverse dynamics)", ylabel=f"{kind}{_bracketed(unit, 'N or N m')}")
    for axis, (unit, names) in zip(axes[len(force_groups):], motion_groups):
        for name in names:
            axis.plot(trajectory.t, trajectory[name], label=name)
        axis.set(title="prescribed motion", ylabel=f"coordinates{_bracketed(unit, 'm or rad')}")
    axes[-1].set_xlabel("t [s]")
    for axis in axes:
        axis.grid(alpha=0.3)
        axis.legend(fontsize="small")
    figure.suptitle(f"{trajectory.info.get('model', '')} ({trajectory.info.get('method', '')})")
    return figure


def _unit_groups(names: Sequence[str], units: Sequence[str]) -> list[tuple[str, list[str]]]:
    """``names`` grouped by their ``units``, in the order each unit first appears."""
    groups: dict[str, list[str]] = {}
    for name, unit in zip(names, units):
        groups.setdefault(unit, []).append(name)
    return list(groups.items())


def _bracketed(unit: str, unknown: str) -> str:
    """`` [unit]``, or `` [unknown]`` when the unit is not known."""
    return f" [{unit or unknown}]"


def plot_sweep(result: "SweepResult", coordinate: str) -> plt.Figure:
    """The runs of a sweep: ``coordinate`` against time for every variant, and each variant's
    energy change E(t) - E(0) (failed variants dashed, up to their last output)."""
    series = result.coordinate(coordinate)
    figure, (upper, lower) = plt.subplots(2, 1, figsize=(8, 7), sharex=True, layout="constrained")
    labelled = len(result) <= 12
    for v, variant in enumerate(result.variants):
        style = "-" if result.status[v] == "success" else "--"
        upper.plot(result.t, series[v], style, linewidth=1.0, label=variant["label"] if labelled else None)
        lower.plot(result.t, result.energy[v] - result.energy[v, 0], style, linewidth=1.0)
    failed = int(np.count_nonzero(result.status != "success"))
    upper.set_title(f"{coordinate} in {len(result)} variants ({result.info.get('mode')}; {failed} failed)",
                    fontsize="medium")
    upper.set_ylabel(coordinate)
    if labelled:
        upper.legend(fontsize="small")
    lower.set_xlabel("t [s]")
    lower.set_ylabel("E(t) - E(0) [J]")
    lower.set_title("energy change of each variant", fontsize="medium")
    for axis in (upper, lower):
        axis.grid(alpha=0.3)
    return figure
