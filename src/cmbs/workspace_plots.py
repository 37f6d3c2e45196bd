"""Figures of the workspace sweeps (:mod:`cmbs.workspace`): the coordinates that follow an input
along its branch, and the grid of two inputs with the distance to the branch's limits."""

from __future__ import annotations

import numpy as np

from cmbs.plotting import plt
from cmbs.workspace import Workspace, WorkspaceGrid


def plot_workspace(result: Workspace) -> plt.Figure:
    """The coordinates that follow (every one but the input and the held ones) against the input
    over the values reached, the branch's limits as dashed vertical lines."""
    figure, axis = plt.subplots(figsize=(8, 4.5))
    names = [name for name in result.coordinate_names if name != result.coordinate and name not in result.held]
    values = result.values[result.reached]
    for name in names:
        k = result.coordinate_names.index(name)
        axis.plot(values, result.q[result.reached, k], ".-", label=name)
    for number, limit in enumerate(result.limits):
        axis.axvline(limit.value, color="black", linestyle="--", linewidth=0.8,
                     label="limit of the branch" if number == 0 else None)
    held = ", ".join(f"{name} = {value:.4g}" for name, value in result.held.items())
    axis.set_title(f"sweep of {result.coordinate}" + (f" ({held})" if held else ""))
    axis.set_xlabel(result.coordinate)
    axis.set_ylabel("coordinate")
    axis.grid(True, alpha=0.3)
    axis.legend(fontsize=8)
    figure.tight_layout()
    return figure


def plot_workspace_grid(result: WorkspaceGrid) -> plt.Figure:
    """The grid of the two inputs: each point reached coloured by log10 of σ_min/σ_max of A over
    the coordinates that follow (near the limits it falls: the inputs lock), the limits located
    on the grid lines as black dots and the start as a white star."""
    figure, axis = plt.subplots(figsize=(7, 6))
    a, b = result.values
    shown = np.ma.masked_invalid(np.log10(np.where(result.reached, result.relative_sigma, np.nan)))
    mesh = axis.pcolormesh(a, b, shown.T, shading="nearest", cmap="viridis")
    figure.colorbar(mesh, ax=axis, label="log10 σ_min/σ_max of A, inputs held")
    if result.limit_points.size:
        axis.plot(result.limit_points[:, 0], result.limit_points[:, 1], "k.", markersize=3, label="limit of the branch")
    axis.plot(a[result.start[0]], b[result.start[1]], "w*", markersize=12, markeredgecolor="black", label="start")
    held = ", ".join(f"{name} = {value:.4g}" for name, value in result.held.items())
    axis.set_title(f"workspace of {result.inputs[0]} and {result.inputs[1]}" + (f" ({held})" if held else "")
                   + f": {int(result.reached.sum())} of {result.reached.size} reached")
    axis.set_xlabel(result.inputs[0])
    axis.set_ylabel(result.inputs[1])
    axis.legend(fontsize=8, loc="upper right")
    figure.tight_layout()
    return figure
