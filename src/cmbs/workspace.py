"""The range of an input coordinate of a closed chain, and its singular configurations.

A sweep moves one coordinate of a mechanism (the input, e.g. a motor's angle) over given values
while other coordinates are held (the other inputs) and the rest follow by position analysis on
the assembly branch of the start configuration (:func:`cmbs.kinematics.follow_branch`; the
model's own drivers are removed).  The branch covers the values up to its limits: there the
input cannot go further without the mechanism jumping to another assembly mode, which by the
implicit function theorem happens only where A restricted to the coordinates that follow (A_f,
the held ones and the input left out) loses rank — a fold of the branch, a singular
configuration of the position analysis (Gosselin & Angeles, *Singularity analysis of
closed-loop kinematic chains*, IEEE Trans. Robot. Autom. 6(3):281-290, 1990: with the inputs
locked the chain can still move, their type 2; a four-bar's dead centres, a five-bar's distal
bars aligned).  Each limit is located by bisection on the input between the last value reached
and the first one not reached, to ``xtol`` (relative; each trial is :func:`cmbs.assemble` from the
last configuration reached, whose Newton iteration fails beyond the fold), and reported with
σ_min/σ_max of A_f
(which falls like the square root of the distance to a fold) and of the whole A (small too
where the closed chain itself changes rank, i.e. gains a DOF: its constraints become dependent).
Between the values reached, :func:`cmbs.kinematics.singular_configurations` finds the rank drops
of A_f along the branch (a branch through a bifurcation point), with the input value in place
of time (q̇ = dq/ds, the input's rate 1, the held ones' 0).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from cmbs.errors import CmbsError, ConvergenceError
from cmbs.files_io import atomic_path, checked_output
from cmbs.kinematics import (SingularConfiguration, assemble, follow_branch, numerical_rank, singular_configurations,
                             velocities)
from cmbs.model.model import Model
from cmbs.trajectory import Trajectory

__all__ = ["BranchLimit", "Workspace", "WorkspaceGrid", "workspace", "workspace_grid"]


@dataclass(frozen=True)
class BranchLimit:
    """An end of the branch inside the swept values: the input ``value`` (the last one reached,
    within the bisection's tolerance), the configuration ``q`` there, σ_min/σ_max of A over the
    coordinates that follow (``relative_sigma``, near 0: the inputs lock) and of the whole A
    (``chain_relative_sigma``, near 0 too where the closed chain gains a DOF)."""

    value: float
    q: np.ndarray
    relative_sigma: float
    chain_relative_sigma: float


@dataclass(frozen=True)
class Workspace:
    """A sweep (:func:`workspace`): the input ``coordinate``, the ``held`` coordinates and their
    values, the swept ``values`` (k,), the configurations ``q`` (k, n) reached on the branch
    (rows of NaN where not), ``reached`` (k,), the input range the branch covers, ``low`` to
    ``high`` (its limits where it ends inside the values, else the values' ends), the branch's
    ``limits`` in ascending order, the ``singular`` configurations between the values reached
    (``t`` the input's value there), and the model's ``coordinate_names`` (the columns of q)."""

    coordinate: str
    held: dict[str, float]
    values: np.ndarray
    q: np.ndarray
    reached: np.ndarray
    low: float
    high: float
    limits: tuple[BranchLimit, ...]
    singular: tuple[SingularConfiguration, ...]
    coordinate_names: tuple[str, ...] = ()

    def save(self, path: str | Path) -> Path:
        """Write the sweep to ``path``: ``.npz`` (arrays ``values``, ``q``, ``reached``, ``low``,
        ``high``, the limits' ``limit_values``, ``limit_q``, ``limit_relative_sigma``,
        ``limit_chain_relative_sigma``, and ``names``) or ``.csv`` (a row per value: the input,
        whether reached, the coordinates); atomically."""
        return _save(path, {"values": self.values, "q": self.q, "reached": self.reached, "low": self.low,
                            "high": self.high, **_limit_arrays(self.limits, len(self.coordinate_names)),
                            "input": self.coordinate, "names": np.array(self.coordinate_names)},
                     [f"swept.{self.coordinate}", "reached", *self.coordinate_names],
                     np.column_stack([self.values, self.reached, self.q]))


def workspace(model: Model, coordinate: str, values: Sequence[float], *, held: Sequence[str] = (),
              q: np.ndarray | None = None, xtol: float = 1e-10) -> Workspace:
    """Sweep ``coordinate`` over ``values`` (strictly increasing) with the ``held`` coordinates at
    their start values, following the assembly branch of ``q`` (default ``model.q0``, assembled
    without the model's drivers) in both directions from the input's start value (module
    docstring).

    Raises
    ------
    CmbsError
        An unknown coordinate, values that are not at least 2 finite increasing numbers, or a
        sweep that leaves degrees of freedom (hold more coordinates).
    ConvergenceError
        The start does not assemble.
    """
    fixed = [coordinate, *held]
    values = _increasing(values, coordinate)
    free, start, ranks = _start(model, fixed, q)
    columns = free.coordinate_indices(fixed)
    Q = np.full((values.size, free.n), np.nan)
    limits: list[BranchLimit] = []
    s0 = start[columns[0]]
    for order in (np.flatnonzero(values >= s0), np.flatnonzero(values < s0)[::-1]):
        current, value = start, s0
        for i in order:
            try:
                current = _follow(free, current, fixed, values[i])
            except ConvergenceError:
                limits.append(_limit(free, current, value, values[i], fixed, ranks, xtol))
                break
            Q[i], value = current, values[i]
    limits.sort(key=lambda limit: limit.value)
    reached = ~np.isnan(Q[:, 0])
    if not reached.any():
        span = [limit.value for limit in limits] or [s0]
        low, high = min(span), max(span)
    else:
        low = min([limit.value for limit in limits if limit.value < values[reached][0]], default=values[reached][0])
        high = max([limit.value for limit in limits if limit.value > values[reached][-1]], default=values[reached][-1])
    return Workspace(coordinate, {name: float(start[free.coordinate_index(name)]) for name in held}, values, Q,
                     reached, float(low), float(high), tuple(limits),
                     tuple(_singular(free, values[reached], Q[reached], fixed)), free.coordinate_names)


@dataclass(frozen=True)
class WorkspaceGrid:
    """A sweep of two inputs over a grid (:func:`workspace_grid`): the ``inputs`` (a, b), their
    ``values`` (k_a,) and (k_b,), the ``held`` coordinates and their values; the configurations
    ``q`` (k_a, k_b, n) reached on the branch of the start (NaN where not), ``reached``
    (k_a, k_b), and σ_min/σ_max of A over the coordinates that follow (``relative_sigma``,
    (k_a, k_b), NaN where not reached: it falls to 0 at the branch's limits); ``start`` the grid
    point the sweep began at; the branch's ``limits`` located on the grid lines between a point
    reached and a neighbour never reached (``limit_inputs[k]`` the input that varies along that
    line: 0 for a, 1 for b; ``limit_points[k]`` the (a, b) values there); the model's
    ``coordinate_names`` (the last axis of q)."""

    inputs: tuple[str, str]
    values: tuple[np.ndarray, np.ndarray]
    held: dict[str, float]
    q: np.ndarray
    reached: np.ndarray
    relative_sigma: np.ndarray
    start: tuple[int, int]
    limits: tuple[BranchLimit, ...]
    limit_inputs: np.ndarray
    limit_points: np.ndarray
    coordinate_names: tuple[str, ...] = ()

    def save(self, path: str | Path) -> Path:
        """Write the grid to ``path``: ``.npz`` (``values_a``, ``values_b``, ``q`` (k_a, k_b, n),
        ``reached``, ``relative_sigma``, ``start``, the limits' ``limit_inputs``,
        ``limit_points``, ``limit_q``, ``limit_relative_sigma``, ``limit_chain_relative_sigma``,
        ``inputs`` and ``names``) or ``.csv`` (a row per grid point: both inputs, whether reached,
        σ_min/σ_max, the coordinates); atomically."""
        a, b = np.meshgrid(*self.values, indexing="ij")
        n = len(self.coordinate_names)
        return _save(path, {"values_a": self.values[0], "values_b": self.values[1], "q": self.q,
                            "reached": self.reached, "relative_sigma": self.relative_sigma,
                            "start": np.array(self.start), "limit_inputs": self.limit_inputs,
                            "limit_points": self.limit_points, **_limit_arrays(self.limits, n),
                            "inputs": np.array(self.inputs), "names": np.array(self.coordinate_names)},
                     [*(f"swept.{name}" for name in self.inputs), "reached", "relative_sigma", *self.coordinate_names],
                     np.column_stack([a.ravel(), b.ravel(), self.reached.ravel(), self.relative_sigma.ravel(),
                                      self.q.reshape(-1, n)]))


def workspace_grid(model: Model, first: tuple[str, Sequence[float]], second: tuple[str, Sequence[float]], *,
                   held: Sequence[str] = (), q: np.ndarray | None = None, xtol: float = 1e-10,
                   locate: bool = True) -> WorkspaceGrid:
    """Sweep two inputs, ``first`` = (coordinate a, values) and ``second`` = (b, values), over the
    grid of their values with the ``held`` coordinates at their start values, following the
    assembly branch of ``q`` (default ``model.q0``, assembled without the model's drivers).

    The branch is carried from the start to the nearest grid point, then from each point reached
    to its four grid neighbours, one input moving at a time (:func:`cmbs.kinematics.follow_branch`:
    continuously, never jumping to another assembly mode), breadth first.  A neighbour that no
    reached point leads to is outside the branch's region on the grid; with ``locate``, the
    branch's limit on each grid line between a point reached and such a neighbour is found by
    bisection on the input that varies along it, as :func:`workspace` does (a type-2 singularity
    of Gosselin & Angeles where the inputs lock, or a configuration where the chain gains a DOF).
    A region reached around a cusp of the singularity curve can hold two assembly modes met
    without crossing it; each grid point keeps the configuration it was first reached with.

    Raises
    ------
    CmbsError
        An unknown coordinate or one given twice, values that are not at least 2 finite
        increasing numbers, or inputs that leave degrees of freedom (hold more coordinates).
    ConvergenceError
        The start does not assemble.
    """
    (a, values_a), (b, values_b) = first, second
    values = (_increasing(values_a, a), _increasing(values_b, b))
    fixed = [a, b, *held]
    free, start, ranks = _start(model, fixed, q)
    columns = free.coordinate_indices(fixed)
    shape = (values[0].size, values[1].size)
    Q = np.full((*shape, free.n), np.nan)
    begin = tuple(int(np.argmin(np.abs(values[k] - start[columns[k]]))) for k in range(2))
    try:
        target = start[columns].copy()
        target[:2] = values[0][begin[0]], values[1][begin[1]]
        Q[begin] = follow_branch(free, start, 0.0, 0.0, fixed=fixed, fixed_to=target)
    except ConvergenceError:
        pass
    missed: list[tuple[tuple[int, int], tuple[int, int], int]] = []
    queue = deque([begin] if not np.isnan(Q[begin][0]) else [])
    while queue:
        point = queue.popleft()
        for varying, step in ((0, -1), (0, 1), (1, -1), (1, 1)):
            neighbour = (point[0] + step, point[1]) if varying == 0 else (point[0], point[1] + step)
            if not (0 <= neighbour[varying] < shape[varying]) or not np.isnan(Q[neighbour][0]):
                continue
            order = fixed if varying == 0 else [b, a, *held]
            try:
                Q[neighbour] = _follow(free, Q[point], order, values[varying][neighbour[varying]])
            except ConvergenceError:
                missed.append((point, neighbour, varying))
                continue
            queue.append(neighbour)
    reached = ~np.isnan(Q[..., 0])
    following = np.ones(free.n, dtype=bool)
    following[columns] = False
    sigma = np.full(shape, np.nan)
    for index in zip(*np.nonzero(reached)):
        singular_values = np.linalg.svd(free.jacobian(Q[index])[:, following], compute_uv=False)
        sigma[index] = singular_values[ranks[0] - 1] / singular_values[0] if ranks[0] else 1.0
    limits, limit_inputs, limit_points = [], [], []
    for point, neighbour, varying in (missed if locate else []):
        if reached[neighbour]:
            continue                        # reached from another side: not the branch's end
        order = fixed if varying == 0 else [b, a, *held]
        limit = _limit(free, Q[point], values[varying][point[varying]], values[varying][neighbour[varying]], order,
                       ranks, xtol)
        limits.append(limit)
        limit_inputs.append(varying)
        limit_points.append(limit.q[columns[:2]])
    return WorkspaceGrid((a, b), values, {name: float(start[free.coordinate_index(name)]) for name in held}, Q,
                         reached, sigma, begin, tuple(limits), np.array(limit_inputs, dtype=np.int64),
                         np.array(limit_points, dtype=float).reshape(-1, 2), free.coordinate_names)


def _limit_arrays(limits: Sequence[BranchLimit], n: int) -> dict[str, np.ndarray]:
    """The limits' input values, configurations and σ ratios as arrays (for a result file)."""
    return {"limit_values": np.array([limit.value for limit in limits], dtype=float),
            "limit_q": np.array([limit.q for limit in limits], dtype=float).reshape(-1, n),
            "limit_relative_sigma": np.array([limit.relative_sigma for limit in limits], dtype=float),
            "limit_chain_relative_sigma": np.array([limit.chain_relative_sigma for limit in limits], dtype=float)}


def _save(path: str | Path, arrays: dict[str, object], header: list[str], rows: np.ndarray) -> Path:
    """``arrays`` to a ``.npz`` file, or ``rows`` under ``header`` to a ``.csv`` file, atomically."""
    path = checked_output(path, (".npz", ".csv"), "workspace result")
    with atomic_path(path) as temporary:
        if path.suffix.lower() == ".npz":
            with open(temporary, "wb") as stream:
                np.savez(stream, **arrays)
        else:
            np.savetxt(temporary, rows, delimiter=",", header=",".join(header), comments="", fmt="%.17g")
    return path


def _increasing(values: Sequence[float], coordinate: str) -> np.ndarray:
    """``values`` as an array, checked: at least 2 finite numbers in increasing order."""
    values = np.asarray(values, dtype=float)
    if values.ndim != 1 or values.size < 2 or not np.all(np.isfinite(values)) or np.any(np.diff(values) <= 0):
        raise CmbsError(f"sweep of {coordinate!r}: the values must be at least 2 finite numbers in increasing order")
    return values


def _start(model: Model, fixed: list[str], q: np.ndarray | None) -> tuple[Model, np.ndarray, tuple[int, int]]:
    """The model without its drivers, its start assembled with the ``fixed`` coordinates (the
    inputs, then the held ones) at their values in ``q`` (default ``model.q0``), and the ranks of
    A over the coordinates that follow and of A there.  Raises when a coordinate is unknown or
    given twice, when the inputs leave degrees of freedom, or when they are not independent (A
    over the coordinates that follow has a lower rank than A: the constraints restrict them)."""
    free = model.without_drivers() if model.drivers.any() else model
    columns = free.coordinate_indices(fixed)
    if len(set(fixed)) != len(fixed):
        raise CmbsError(f"sweep of {fixed[0]!r}: a coordinate is given twice (swept twice, swept and held, or held "
                        "twice)")
    start = assemble(free, model.q0 if q is None else q, 0.0, fixed=fixed)
    following = np.ones(free.n, dtype=bool)
    following[columns] = False
    A = free.jacobian(start)
    ranks = (numerical_rank(A[:, following], 1e-9)[0], numerical_rank(A, 1e-9)[0])
    dof = int(following.sum()) - ranks[0]
    if dof > 0:
        raise CmbsError(f"model {model.name!r}: with {', '.join(fixed)} given, {dof} degree(s) of freedom are left: "
                        f"hold {dof} more coordinate(s)")
    if ranks[0] < ranks[1]:
        raise CmbsError(f"model {model.name!r}: with {', '.join(fixed)} given, the other coordinates cannot follow "
                        f"every value near the start (A over them has rank {ranks[0]}, the chain's A {ranks[1]}): the "
                        "given coordinates are not independent inputs; hold fewer, or start away from a singular "
                        "configuration")
    return free, start, ranks


def _follow(model: Model, q: np.ndarray, fixed: list[str], value: float) -> np.ndarray:
    """q carried along its branch to the input (``fixed[0]``) at ``value``, the others held."""
    target = q[model.coordinate_indices(fixed)].copy()
    target[0] = value
    return follow_branch(model, q, 0.0, 0.0, fixed=fixed, fixed_to=target)


def _limit(model: Model, q: np.ndarray, reached: float, missed: float, fixed: list[str], ranks: tuple[int, int],
           xtol: float) -> BranchLimit:
    """The branch's end between the input value ``reached`` (configuration ``q``) and ``missed``,
    by bisection to ``xtol · max(1, |value|)`` (module docstring), with σ_r/σ_1 there of A over the
    coordinates that follow and of A, r their ``ranks`` at the start."""
    columns = model.coordinate_indices(fixed)
    while abs(missed - reached) > xtol * max(1.0, abs(reached)):
        middle = 0.5 * (reached + missed)
        guess = q.copy()
        guess[columns[0]] = middle
        try:
            q, reached = assemble(model, guess, 0.0, fixed=fixed), middle
        except ConvergenceError:
            missed = middle
    following = np.ones(model.n, dtype=bool)
    following[model.coordinate_indices(fixed)] = False
    A = model.jacobian(q)
    ratios = [float(sigma[rank - 1] / sigma[0]) for sigma, rank in
              ((np.linalg.svd(A[:, following], compute_uv=False), ranks[0]), (np.linalg.svd(A, compute_uv=False),
                                                                              ranks[1]))]
    return BranchLimit(float(reached), q, ratios[0], ratios[1])


def _singular(model: Model, values: np.ndarray, Q: np.ndarray, fixed: list[str]) -> list[SingularConfiguration]:
    """:func:`cmbs.kinematics.singular_configurations` of A over the coordinates that follow,
    along the configurations ``Q`` reached at the input ``values`` (q̇ = dq/ds)."""
    if values.size < 2:
        return []
    rate = np.zeros(model.n)
    rate[model.coordinate_index(fixed[0])] = 1.0
    QD = np.array([velocities(model, q, 0.0, qd=rate, fixed=fixed) for q in Q])
    branch = Trajectory(values, Q, QD, np.zeros_like(Q), model.coordinate_names, info={"analysis": "workspace"})
    return singular_configurations(model, branch, fixed=fixed)
