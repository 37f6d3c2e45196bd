"""Figures of a :class:`~cmbs.trajectory.Trajectory` (a leaf: compute first, then plot)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from cmbs.errors import CmbsError  # noqa: E402
from cmbs.files_io import atomic_path, checked_output  # noqa: E402
from cmbs.model.model import Model  # noqa: E402
from cmbs.trajectory import Trajectory  # noqa: E402


def plot_trajectory(trajectory: Trajectory, *, model: Model | None = None,
                    coordinates: Sequence[str] | None = None, snapshots: int = 8) -> plt.Figure:
    """Coordinates, velocities and accelerations against time; with ``model``, also the
    mechanism drawn at ``snapshots`` instants (lighter = earlier)."""
    names = list(coordinates) if coordinates else list(trajectory.names)
    unknown = [name for name in names if name not in trajectory.names]
    if unknown:
        raise CmbsError(f"no coordinate(s) {', '.join(unknown)}; coordinates: {', '.join(trajectory.names)}")
    index = [trajectory.names.index(name) for name in names]
    panels = 3 + (model is not None)
    figure, axes = plt.subplots(1, panels, figsize=(4.2 * panels, 3.8), constrained_layout=True)
    for axis, data, label in zip(axes, (trajectory.q, trajectory.qd, trajectory.qdd),
                                 ("position", "velocity", "acceleration")):
        for k, name in zip(index, names):
            axis.plot(trajectory.t, data[:, k], label=name)
        axis.set_xlabel("t [s]")
        axis.set_title(label)
        axis.grid(alpha=0.3)
    axes[0].legend(fontsize="small")
    if model is not None:
        draw_snapshots(axes[-1], model, trajectory, snapshots)
    figure.suptitle(trajectory.info.get("model", ""))
    return figure


def draw_snapshots(axis: plt.Axes, model: Model, trajectory: Trajectory, count: int) -> None:
    """The model's segments at ``count`` evenly spaced samples of the trajectory."""
    samples = np.linspace(0, len(trajectory.t) - 1, max(count, 1)).round().astype(int)
    for shade, k in zip(np.linspace(0.25, 1.0, len(samples)), samples):
        points = model.point_positions(trajectory.q[k])
        for i, j in model.lines:
            axis.plot(points[[i, j], 0], points[[i, j], 1], "-o", color=plt.cm.Blues(shade), markersize=3)
    axis.set_aspect("equal", adjustable="datalim")
    axis.set_title("mechanism (x, z)")
    axis.grid(alpha=0.3)


def save_figure(figure: plt.Figure, path: str | os.PathLike) -> Path:
    """Write a figure atomically (temp file in the same folder, then rename)."""
    path = checked_output(path, (".png", ".pdf", ".svg"), "figure")
    try:
        with atomic_path(path) as temporary:
            figure.savefig(temporary, dpi=120, format=path.suffix.lower()[1:])
    finally:
        plt.close(figure)
    return path
