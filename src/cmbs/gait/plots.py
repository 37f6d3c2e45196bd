"""Figures of the gait analyses (a leaf: compute first, then plot)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from cmbs.gait.inverse import Comparison  # noqa: E402
from cmbs.trajectory import Trajectory  # noqa: E402

_LABELS = {"hip": "(a) wrench at the hip", "grf": "(b) GRF at the CoPs"}


def plot_lab_comparison(reference: Trajectory, comparisons: dict[str, Comparison]) -> plt.Figure:
    """Leg torques in the lab's convention (hip/knee extensor, ankle plantarflexor > 0) [N m/kg]
    of each analysis in ``comparisons`` ({mode: Comparison}) vs the lab's moments, over the
    right gait cycle; right leg top row, left leg bottom row."""
    figure, axes = plt.subplots(2, 3, figsize=(12, 6.5), sharex=True)
    phase = 100 * np.asarray(reference["phase"])
    first = next(iter(comparisons.values()))
    for j, joint in enumerate(first.joints):
        axis = axes[j // 3, j % 3]
        axis.plot(phase, first.lab[:, j], "k", lw=2, label="lab (C3D)")
        for mode, comparison in comparisons.items():
            axis.plot(phase, comparison.model[:, j], lw=1.2,
                      label=f"{_LABELS.get(mode, mode)}, r = {comparison.correlation[j]:.2f}")
        axis.axhline(0.0, color="0.7", lw=0.5)
        axis.set_title(joint)
        axis.legend(fontsize=7)
        if j // 3 == 1:
            axis.set_xlabel("% of the right gait cycle")
        if j % 3 == 0:
            axis.set_ylabel("moment [N m/kg]")
    figure.tight_layout()
    return figure


def plot_tracking(runs: dict[str, Trajectory], reference: Trajectory, coordinates: tuple[str, ...]) -> plt.Figure:
    """Tracking errors z - z_ref of each run in ``runs`` ({label: run}) on ``coordinates``
    (hip in mm, angles in degrees) against the reference spline, one panel per coordinate."""
    from scipy.interpolate import CubicSpline

    columns = [reference.names.index(name) for name in coordinates]
    spline = CubicSpline(reference.t, reference.q[:, columns], axis=0)
    rows = int(np.ceil(len(coordinates) / 4))
    figure, axes = plt.subplots(rows, 4, figsize=(14, 2.6 * rows), sharex=True, squeeze=False)
    for label, run in runs.items():
        error = run.q[:, [run.names.index(name) for name in coordinates]] - spline(run.t)
        for j, name in enumerate(coordinates):
            scale = 1e3 if name.startswith("hip.") else 180.0 / np.pi
            axes[j // 4, j % 4].plot(run.t, scale * error[:, j], lw=1, label=label)
    for j, axis in enumerate(axes.flat):
        if j >= len(coordinates):
            axis.set_visible(False)
            continue
        name = coordinates[j]
        axis.axhline(0.0, color="0.7", lw=0.5)
        axis.set_title(name, fontsize=9)
        axis.set_ylabel("error [mm]" if name.startswith("hip.") else "error [deg]", fontsize=8)
    axes.flat[0].legend(fontsize=7)
    for axis in axes[-1]:
        axis.set_xlabel("t [s]")
    figure.tight_layout()
    return figure
