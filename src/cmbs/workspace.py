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

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from cmbs.errors import CmbsError, ConvergenceError
from cmbs.kinematics import (SingularConfiguration, assemble, follow_branch, numerical_rank, singular_configurations,
                             velocities)
from cmbs.model.model import Model
from cmbs.trajectory import Trajectory

__all__ = ["BranchLimit", "Workspace", "workspace"]


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
    ``limits`` in ascending order, and the ``singular`` configurations between the values reached
    (``t`` the input's value there)."""

    coordinate: str
    held: dict[str, float]
    values: np.ndarray
    q: np.ndarray
    reached: np.ndarray
    low: float
    high: float
    limits: tuple[BranchLimit, ...]
    singular: tuple[SingularConfiguration, ...]


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
    free = model.without_drivers() if model.drivers.any() else model
    fixed = [coordinate, *held]
    columns = free.coordinate_indices(fixed)
    if len(set(fixed)) != len(fixed):
        raise CmbsError(f"sweep of {coordinate!r}: a coordinate is both swept and held, or held twice")
    values = np.asarray(values, dtype=float)
    if values.ndim != 1 or values.size < 2 or not np.all(np.isfinite(values)) or np.any(np.diff(values) <= 0):
        raise CmbsError(f"sweep of {coordinate!r}: the values must be at least 2 finite numbers in increasing order")
    start = assemble(free, model.q0 if q is None else q, 0.0, fixed=fixed)
    following = np.ones(free.n, dtype=bool)
    following[columns] = False
    A = free.jacobian(start)
    ranks = (numerical_rank(A[:, following], 1e-9)[0], numerical_rank(A, 1e-9)[0])
    dof = int(following.sum()) - ranks[0]
    if dof > 0:
        raise CmbsError(f"model {model.name!r}: with {', '.join(fixed)} given, {dof} degree(s) of freedom are left: "
                        f"hold {dof} more coordinate(s)")
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
                     tuple(_singular(free, values[reached], Q[reached], fixed)))


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
