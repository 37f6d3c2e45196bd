"""Kinematic analysis: assembly, velocity and acceleration analysis, rank/DOF/redundancy.

Position analysis is Newton-Raphson on Φ(q, t) = 0 (thesis eq. 3.38-3.40): the step solves
``A_f Δq_f = -Φ`` for the free coordinates (all but the ones held ``fixed``) in the least-squares
minimum-norm sense, ``Δq_f = -A_f⁺ Φ``, which is the plain Newton step when A_f is square and
regular and still converges (quadratically, to the nearest point of the constraint manifold) for
under-determined or redundant systems.  Velocities solve ``A q̇ = -Φ_t``, accelerations
``A q̈ = γ``, with the fixed coordinates' values held.  Nonholonomic rows (``model.nonholonomic``)
take part in velocity and acceleration analysis only; assembly uses the holonomic rows.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from cmbs.errors import CmbsError, ConvergenceError, ModelError
from cmbs.lazy import on_first_use
from cmbs.model.model import Model, base_equations
from cmbs.trajectory import Trajectory

linalg = on_first_use("scipy.linalg")
optimize = on_first_use("scipy.optimize")
transform = on_first_use("scipy.spatial.transform")


@dataclass(frozen=True)
class ConstraintReport:
    """Rank analysis of A at one configuration.

    ``rank`` of the whole A (numerical, relative tolerance ``tolerance``), ``dof = n - rank`` of
    the holonomic rows (the dimension of the configuration manifold), ``velocity_dof = n - rank``
    (the admissible velocities: fewer than ``dof`` when there are nonholonomic constraints, equal
    otherwise), ``redundant`` constraint names (rows dependent on earlier ones: pivoted QR of
    Aᵀ), ``singular_values`` of A.
    """

    n: int
    m: int
    rank: int
    dof: int
    velocity_dof: int
    redundant: tuple[str, ...]
    singular_values: np.ndarray
    tolerance: float


def constraint_report(model: Model, q: np.ndarray, t: float = 0.0, *, tolerance: float = 1e-9) -> ConstraintReport:
    """Rank of A = Φ_q, DOF and the redundant constraints at (q, t).

    A singular value counts as zero below ``tolerance · σ_max``.  Redundant rows: the rows left
    out by QR with column pivoting of Aᵀ, i.e. those that depend linearly on the others
    (rows are normalised first so that units do not decide).  ``dof`` counts the holonomic
    rows only, ``velocity_dof`` all rows (see :class:`ConstraintReport`).
    """
    A = model.jacobian(q, t)
    n, m = model.n, model.m
    if m == 0:
        return ConstraintReport(n, 0, 0, n, n, (), np.zeros(0), tolerance)
    rank, sigma = numerical_rank(A, tolerance)
    holonomic_rank = numerical_rank(A[model.holonomic], tolerance)[0] if model.nonholonomic.any() else rank
    norms = np.linalg.norm(A, axis=1)
    scaled = A / np.where(norms > 0, norms, 1.0)[:, None]
    _, _, pivots = linalg.qr(scaled.T, pivoting=True, mode="economic")
    redundant = tuple(model.constraint_names[k] for k in sorted(pivots[rank:]))
    return ConstraintReport(n=n, m=m, rank=rank, dof=n - holonomic_rank, velocity_dof=n - rank, redundant=redundant,
                            singular_values=sigma, tolerance=tolerance)


def numerical_rank(matrix: np.ndarray, tolerance: float) -> tuple[int, np.ndarray]:
    """The rank of ``matrix`` (the singular values above ``tolerance · max(σ_max, 1)``) and its
    singular values."""
    if matrix.size == 0:
        return 0, np.zeros(0)
    sigma = np.linalg.svd(matrix, compute_uv=False)
    return int(np.sum(sigma > tolerance * max(sigma[0], 1.0))), sigma


def _free_mask(model: Model, fixed: Sequence[str | int]) -> np.ndarray:
    mask = np.ones(model.n, dtype=bool)
    mask[model.coordinate_indices(list(fixed))] = False
    return mask


#: Coordinate kinds measured in metres; the others (angles, joint and generic coordinates) are
#: scaled by 1 (radians, or the model's own units).
LENGTH_KINDS = frozenset({"x", "y", "z", "distance"})


def point_array(model: Model, q: np.ndarray) -> np.ndarray:
    """The positions of the model's named points at ``q`` as rows: (n_points, 2) in the plane
    (x, z), (n_points, 3) in space; (0, 2) for a model without points."""
    if not model.point_names:
        return np.zeros((0, 2))
    points = np.asarray(model.point_positions(q), dtype=float)
    return points if points.ndim == 2 else points.reshape(len(model.point_names), -1)


@dataclass(frozen=True)
class BodyPoses:
    """Poses of the rigid bodies of a spatial model or the links of a robot (:func:`body_poses`),
    ``...`` the leading shape of the coordinates given (none for one configuration, (k,) for k
    of them).

    ``names`` (bodies,), in the order they were added (a robot's moving links in the order of
    its links); ``origins`` (..., bodies, 3) the position of each body's origin point;
    ``rotations`` (..., bodies, 3, 3) the rotation R that turns the body as built into its pose:
    a body-fixed point p is at o + R (p₀ - o₀), p₀ and o₀ the point and the origin as built;
    ``quaternions`` (..., bodies, 4) the same rotations as unit quaternions, **scalar first**
    (w, x, y, z), of continuous sign along the first axis (the first with w >= 0).

    As built, a spatial natural-coordinate body is at the positions given to the builder (its
    inertia given in ground axes); a robot link is its frame at the world origin aligned with
    the world axes (o₀ = 0, p₀ = p its link coordinates), so R is the link frame's world
    rotation and the point is at o + R p (:func:`cmbs.model.robot.frame_placement`).
    """

    names: tuple[str, ...]
    origins: np.ndarray
    rotations: np.ndarray
    quaternions: np.ndarray


def body_poses(model: Model, q: np.ndarray) -> BodyPoses:
    """The poses of the rigid bodies of a spatial model (:class:`~cmbs.SpatialModelBuilder`
    ``add_body``) or of the moving links of a robot (:mod:`cmbs.model.robot`) at coordinates
    ``q``, (n,) or (k, n), and their quaternions.  Spatial bodies: each body's origin, and the
    rotation R = X X₀⁻¹ from its basis elements X = [b₁ b₂ b₃] (point differences and unit
    vectors) at q and as built, made exactly orthonormal by polar decomposition (the constraint
    error of a simulation leaves it slightly off; see ``SpatialEquations.body_poses``); rods and
    point masses are no bodies (a rod's spin about its axis is no coordinate).  Robots: each
    link frame's world origin and rotation (``RobotEquations.body_poses``), for every link but
    the root and the links fixed to it.  Configurations with non-finite coordinates give NaN.

    Raises
    ------
    ModelError
        ``model`` is neither a spatial natural-coordinate model nor a robot, or ``q`` has not n
        columns.
    """
    equations = base_equations(model)[0]
    if not hasattr(equations, "body_poses"):
        raise ModelError(f"model {model.name!r} is neither a spatial model (cmbs.SpatialModelBuilder) nor a robot: "
                         "body poses are those of its rigid bodies or links")
    q = np.asarray(q, dtype=float)
    if q.ndim not in (1, 2) or q.shape[-1] != model.n:
        raise ModelError(f"body poses of model {model.name!r} need coordinates of shape ({model.n},) or (k, "
                         f"{model.n}), got {q.shape}")
    origins, rotations = equations.body_poses(q)
    flat = rotations.reshape(-1, 3, 3)
    quaternions = np.full((flat.shape[0], 4), np.nan)
    finite = np.all(np.isfinite(flat), axis=(1, 2))
    if finite.any():
        quaternions[finite] = transform.Rotation.from_matrix(flat[finite]).as_quat()[:, [3, 0, 1, 2]]
    quaternions = quaternions.reshape(*rotations.shape[:-2], 4)
    quaternions *= np.where(quaternions[..., :1] < 0, -1.0, 1.0)
    if q.ndim == 2:
        for k in range(1, q.shape[0]):        # the sign of least change from the previous instant
            flip = np.einsum("bi,bi->b", quaternions[k], quaternions[k - 1]) < 0
            quaternions[k, flip] *= -1.0
    return BodyPoses(equations.body_names, origins, rotations, quaternions)


#: the result-file columns of a body's pose, after the body's name: its origin, then its
#: quaternion scalar first (:func:`with_body_poses`)
POSE_COLUMNS = ("origin.x", "origin.y", "origin.z", "qw", "qx", "qy", "qz")


def with_body_poses(model: Model, trajectory: Trajectory) -> Trajectory:
    """``trajectory`` with the poses of a spatial model's bodies or a robot's moving links
    (:func:`body_poses`) added as extras, seven per body: ``BODY.origin.x``, ``.origin.y``,
    ``.origin.z`` (m) and the quaternion ``BODY.qw``, ``.qx``, ``.qy``, ``.qz`` (scalar first);
    what a result file holds.  Returned unchanged for a model that is neither or has no bodies.

    Raises
    ------
    CmbsError
        A pose column would have the name of a coordinate or of another array of the trajectory.
    """
    if not getattr(base_equations(model)[0], "bodies", ()):
        return trajectory
    q = np.asarray(trajectory.q, dtype=float)[:, [trajectory.names.index(name) for name in model.coordinate_names]]
    poses = body_poses(model, q)
    extras = dict(trajectory.extras)
    for k, name in enumerate(poses.names):
        values = np.concatenate([poses.origins[:, k], poses.quaternions[:, k]], axis=1)
        for column, value in zip(POSE_COLUMNS, values.T):
            label = f"{name}.{column}"
            if label in extras or label in trajectory.names:
                raise CmbsError(f"the pose of body {name!r} would be written as {label!r}, which is already a "
                                "coordinate or result column; rename the body")
            extras[label] = value
    return Trajectory(trajectory.t, trajectory.q, trajectory.qd, trajectory.qdd, trajectory.names, extras,
                      trajectory.info)


def model_size(model: Model, q: np.ndarray) -> float:
    """The model's characteristic length L at ``q``: the diagonal of the box around its named
    points (fixed points included), else the largest length coordinate; 1 for a model with
    neither (user equations in their own units)."""
    points = point_array(model, q)
    size = float(np.linalg.norm(np.ptp(points, axis=0))) if len(points) > 1 else 0.0
    if not size > 0.0:
        lengths = [abs(value) for value, kind in zip(q, model.coordinate_kinds) if kind in LENGTH_KINDS]
        size = max(lengths, default=0.0)
    return size if np.isfinite(size) and size > 0.0 else 1.0


def coordinate_scales(model: Model, q: np.ndarray) -> np.ndarray:
    """The scale of each coordinate: L (:func:`model_size`) for lengths, 1 for the others."""
    size = model_size(model, q)
    return np.array([size if kind in LENGTH_KINDS else 1.0 for kind in model.coordinate_kinds])


def scaled_residuals(phi: np.ndarray, A: np.ndarray, size: float) -> np.ndarray:
    """|Φ_i| / (‖A_i‖ L): each constraint's error as the displacement that would remove it (a
    Newton step of row i alone), relative to the model's size L.  Unit-free, so that one
    tolerance means the same on a centimetre mechanism (rows in m² of 1e-4 m² scale) as on a
    ten-metre one."""
    norms = np.linalg.norm(A, axis=1)
    return np.abs(phi) / (np.where(norms > 0.0, norms, 1.0) * size)


def position_errors(model: Model, q: np.ndarray, t: float = 0.0) -> np.ndarray:
    """Each constraint row's :func:`scaled_residuals` at (q, t), against the model's size at its
    q0 (0 for nonholonomic rows, which have no position-level error): how far q lies from the
    constraints, as a fraction of the mechanism's size."""
    terms = model.evaluate(q, np.zeros(model.n), t)
    rows = model.holonomic
    errors = np.zeros(model.m)
    errors[rows] = scaled_residuals(terms.phi[rows], terms.A[rows], model_size(model, model.q0))
    return errors


def half_turn_angles(model: Model, q: np.ndarray, t: float = 0.0, A: np.ndarray | None = None) -> list[tuple[str, float]]:
    """The angle coordinates of a natural-coordinate model that sit half a turn away from the
    direction they measure, as (name, value) pairs.

    The angle constraint cos φ (u×v) - sin φ (u·v) = |u||v| sin(θ - φ) also vanishes at
    φ = θ + π.  On the right branch ∂Φ/∂φ = -|u||v| cos(θ - φ) < 0; on the spurious one it is
    > 0 (see :mod:`cmbs.model.natural`).  Models of other kinds have no such root: [].  ``A``,
    the Jacobian at (q, t) when the caller has it.
    """
    from cmbs.model.model import base_equations
    from cmbs.model.natural import NaturalEquations

    if not isinstance(base_equations(model)[0], NaturalEquations):
        return []
    A = model.jacobian(q, t) if A is None else A
    wrong = []
    for row, constraint in enumerate(model.constraint_names):
        kind, _, name = constraint.partition(" ")
        if kind == "angle" and name in model.coordinate_names:
            column = model.coordinate_index(name)
            if A[row, column] > 0:
                wrong.append((name, float(q[column])))
    return wrong


class BranchError(ConvergenceError):
    """Assembly converged on a spurious root: an angle coordinate half a turn away from the
    direction it measures.  ``constraint`` names the angle's constraint row."""


def assemble(model: Model, q: np.ndarray | None = None, t: float = 0.0, *, fixed: Sequence[str | int] = (),
             tolerance: float = 1e-12, max_iterations: int = 50) -> np.ndarray:
    """Solve Φ(q, t) = 0 by Newton-Raphson from ``q`` (default ``model.q0``), on the holonomic
    rows (nonholonomic rows constrain velocities only).

    The one assembly routine of cmbs: every position analysis (model files and library models,
    prescribed motions, kinematic analysis, inverse kinematics of robots, gait reconstruction,
    sweeps) goes through it, and it refuses a solution with an angle half a turn away from its
    direction (:func:`half_turn_angles`) or a robot's link frame turned more than 90° from the
    target orientation of its pose driver (``RobotEquations.turned_targets``).

    A model with ``coordinate_limits`` (a robot's joint limits, when it asks for them) is
    assembled within them: where Newton's solution leaves them, or Newton does not converge,
    the bounded least-squares problem min ‖Φ(q)‖ over the free coordinates within their limits
    is solved by a trust-region reflective method (``scipy.optimize.least_squares``, method
    ``trf``: Branch, Coleman & Li, SIAM J. Sci. Comput. 21(1), 1999) from Newton's solution
    reflected into the limits, then from the guess, each finished by Newton with the coordinates
    at a limit held there.  It is a local method: it finds the configuration within the limits that its
    start leads to, if any.

    Parameters
    ----------
    fixed
        Coordinates (names or indices) held at their given values: the independent coordinates
        of a position analysis.
    tolerance
        Convergence when every :func:`scaled_residuals` |Φ_i| / (‖A_i‖ L) < tolerance: the
        constraint errors as displacements relative to the model's size L (:func:`model_size`).

    Raises
    ------
    ConvergenceError
        Naming the iteration count, the largest residual and its constraint (``constraint``);
        with limits, the coordinate Newton's solution puts beyond its limit.
    BranchError
        When Newton converged with an angle half a turn away from its direction, or a pose
        driver's frame at a spurious root of its orientation rows.
    """
    q = np.array(model.q0 if q is None else q, dtype=float)
    rows = np.flatnonzero(model.holonomic)
    if rows.size == 0:
        return q
    free = _free_mask(model, fixed)
    size = model_size(model, q)
    solution, error, A = _newton(model, q, t, rows, free, size, tolerance, max_iterations)
    if model.coordinate_limits is not None:
        beyond = None if solution is None else _beyond_limits(model, solution, free)
        if solution is None or beyond is not None:      # the bounded solve refuses spurious roots itself
            starts = [q] if solution is None else [solution, q]
            solution, error = _within_limits(model, starts, t, rows, free, size, tolerance, max_iterations, beyond,
                                             error)
            if solution is None:
                raise error
            return solution
    if solution is None:
        raise error
    _refuse_half_turns(model, solution, t, A)
    return solution


def _newton(model: Model, q: np.ndarray, t: float, rows: np.ndarray, free: np.ndarray, size: float,
            tolerance: float, max_iterations: int) -> tuple[np.ndarray | None, ConvergenceError | None, np.ndarray]:
    """Newton-Raphson on the holonomic ``rows`` over the ``free`` coordinates from ``q`` (least-
    squares steps): (the solution, None, A there), or (None, the error naming the largest
    residual, A at the last iterate)."""
    q = q.copy()
    terms = model.new_terms()
    zeros = np.zeros(model.n)
    for iteration in range(max_iterations + 1):
        model.evaluate(q, zeros, t, out=terms)
        phi = terms.phi[rows]
        residual = np.max(scaled_residuals(phi, terms.A[rows], size))
        if not np.isfinite(residual):
            break
        if residual < tolerance:
            return q, None, terms.A
        if iteration == max_iterations:
            break
        step, *_ = np.linalg.lstsq(terms.A[np.ix_(rows, free)], -phi, rcond=None)
        q[free] += step
    phi = terms.phi[rows]
    worst = int(np.nanargmax(np.abs(phi))) if np.any(np.isfinite(phi)) else 0
    constraint = model.constraint_names[rows[worst]]
    where = f"largest residual {abs(phi[worst]):.3g} in constraint {constraint!r}"
    problem = model.time_function_problem([t]) if not np.all(np.isfinite(phi)) else ""
    if problem:
        error = ConvergenceError(f"model {model.name!r}: assembly at t={t:g} met a non-finite residual ({where}): "
                                 f"{problem}")
    else:
        error = ConvergenceError(
            f"model {model.name!r}: assembly at t={t:g} did not converge in {max_iterations} Newton iterations "
            f"({where}); check the initial positions, the segment lengths and the drivers' values")
    error.constraint = constraint
    return None, error, terms.A


def _beyond_limits(model: Model, q: np.ndarray, free: np.ndarray) -> tuple[int, float, float, float] | None:
    """The first free coordinate of ``q`` outside the model's ``coordinate_limits`` (beyond 1e-12
    of its range or of 1), as (index, value, lower, upper); None when all are within."""
    lower, upper = model.coordinate_limits
    slack = 1e-12 * np.maximum(1.0, np.where(np.isfinite(upper - lower), upper - lower, 1.0))
    outside = free & ((q < lower - slack) | (q > upper + slack))
    if not outside.any():
        return None
    k = int(np.flatnonzero(outside)[0])
    return k, float(q[k]), float(lower[k]), float(upper[k])


def _within_limits(model: Model, starts: list[np.ndarray], t: float, rows: np.ndarray, free: np.ndarray, size: float,
                   tolerance: float, max_iterations: int, beyond: tuple[int, float, float, float] | None,
                   error: ConvergenceError | None) -> tuple[np.ndarray | None, ConvergenceError | None]:
    """The assembly within the coordinate limits (:func:`assemble`) from each of ``starts`` in turn
    (Newton's solution, then the guess): trust-region reflective least squares from the start
    reflected into the limits (a coordinate beyond a limit by δ starts δ inside it), then Newton
    with the coordinates at a limit held; a solution at a spurious root (:func:`_refuse_half_turns`)
    counts as none.  ``beyond`` is what Newton's own solution left (None
    when Newton failed, ``error`` its failure)."""
    from scipy.optimize import least_squares

    lower, upper = (limit[free] for limit in model.coordinate_limits)
    span = np.where(np.isfinite(upper - lower), upper - lower, 1.0)
    terms = model.new_terms()
    zeros = np.zeros(model.n)
    best = None
    for q in starts:
        def evaluated(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            trial = q.copy()
            trial[free] = x
            model.evaluate(trial, zeros, t, out=terms)
            return terms.phi[rows], terms.A[np.ix_(rows, free)]

        start = q[free]
        start = np.clip(np.where(start < lower, 2 * lower - start, np.where(start > upper, 2 * upper - start, start)),
                        lower, upper)
        fit = least_squares(lambda x: evaluated(x)[0], start, jac=lambda x: evaluated(x)[1], bounds=(lower, upper),
                            method="trf", x_scale="jac", ftol=np.finfo(float).eps, xtol=np.finfo(float).eps,
                            gtol=np.finfo(float).eps, max_nfev=50 * max(1, int(free.sum())))
        fitted = q.copy()
        fitted[free] = fit.x
        at_limit = np.zeros(model.n, dtype=bool)
        at_limit[free] = (fit.x - lower <= 1e-9 * span) | (upper - fit.x <= 1e-9 * span)
        solution, _, A = _newton(model, fitted, t, rows, free & ~at_limit, size, tolerance, max_iterations)
        if solution is not None and _beyond_limits(model, solution, free) is None:
            try:
                _refuse_half_turns(model, solution, t, A)
                return solution, None
            except BranchError:             # a spurious root: the next start may avoid it
                pass
        phi = evaluated(fit.x)[0]
        if best is None or np.max(np.abs(phi)) < np.max(np.abs(best[0])):
            best = phi, at_limit
    phi, at_limit = best
    worst = int(np.argmax(np.abs(phi)))
    name = model.coordinate_names
    if beyond is not None:
        k, value, low, high = beyond
        reason = f"Newton's solution puts {name[k]!r} at {value:.6g}, beyond its limits [{low:.6g}, {high:.6g}]"
    else:
        reason = f"Newton from the guess did not converge ({error})"
    failure = ConvergenceError(
        f"model {model.name!r}: no configuration within the coordinate limits at t={t:g}: {reason}; within the "
        f"limits the smallest residual found is {abs(phi[worst]):.3g} in constraint "
        f"{model.constraint_names[rows[worst]]!r}"
        + (f" with {', '.join(repr(name[k]) for k in np.flatnonzero(at_limit))} at a limit" if at_limit.any() else ""))
    failure.constraint = model.constraint_names[rows[worst]]
    return None, failure


def _refuse_half_turns(model: Model, q: np.ndarray, t: float, A: np.ndarray) -> None:
    equations = base_equations(model)[0]
    turned = [(row, angle) for row, angle in equations.turned_targets(q, t) if row in model.constraint_names] \
        if hasattr(equations, "turned_targets") else []
    if turned:
        row, angle = turned[0]
        error = BranchError(
            f"model {model.name!r}: assembly turned the frame of pose driver {row.rpartition('.')[0]!r} by "
            f"{np.degrees(angle):.4g} degrees from its target orientation at t = {t:g} (a spurious root of the "
            "orientation rows): start from joint values that put the frame nearer its target")
        error.constraint = row
        raise error
    wrong = half_turn_angles(model, q, t, A)
    if wrong:
        name, value = wrong[0]
        error = BranchError(
            f"model {model.name!r}: assembly put angle {name} half a turn away from the direction it measures "
            f"({name} = {value:.6g} rad at t = {t:g}; the angle constraint's spurious root): start from points "
            "drawn near that angle, or give the angle a value within 90 degrees of the angle of the points")
        error.constraint = f"angle {name}"
        raise error


def follow_branch(model: Model, q: np.ndarray, t_from: float, t_to: float, *, fixed: Sequence[str | int] = (),
                  fixed_to: np.ndarray | None = None, tolerance: float = 1e-12, max_iterations: int = 50,
                  max_correction: float = 0.05, rates: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Carry the assembled configuration ``q`` at ``t_from`` to ``t_to`` along its own assembly
    branch (natural-parameter continuation, Allgower & Georg, *Introduction to Numerical
    Continuation Methods*, 2003, ch. 2), while the ``fixed`` coordinates move linearly from their
    values in ``q`` to ``fixed_to``.

    On the path s ∈ [0, 1], t(s) = t_from + s Δt and q_c(s) = q_c + s Δc for the fixed
    coordinates c.  Each sub-step s → s + h predicts with the path's tangent q' (A_f q'_f =
    -Φ_t Δt - A_c Δc) and, when time moves, its curvature (A q̈ = γ at q̇ = q'/Δt), then corrects
    with :func:`assemble`.  A sub-step is accepted when the correction, in units of
    :func:`coordinate_scales`, is at most ``max_correction`` (5 % of the model's size, or
    0.05 rad) and no angle sits half a turn away; else it is halved.  Other branches lie much
    farther away except at a singular configuration, so the result is the configuration the
    mechanism reaches by moving continuously — never one of another assembly mode.  ``rates``,
    q̇ and q̈ at ``t_from`` when the caller has them (time moving, nothing held), spare the first
    predictor's velocity and acceleration analyses.

    Raises
    ------
    ConvergenceError
        When the sub-step shrinks below 1e-9 of the path without an accepted step (a singular
        configuration where branches meet, or a driver demanding an impossible position).
    """
    q = np.array(q, dtype=float)
    columns = model.coordinate_indices(list(fixed))
    start_values = q[columns].copy()
    change = np.zeros(columns.size) if fixed_to is None else np.asarray(fixed_to, dtype=float) - start_values
    duration = t_to - t_from
    if not model.holonomic.any():
        q[columns] = start_values + change
        return q
    if duration == 0.0 and not np.any(change):
        return assemble(model, q, t_to, fixed=fixed, tolerance=tolerance, max_iterations=max_iterations)
    problem = model.time_function_problem([t_to]) if duration != 0.0 else ""
    if problem:
        raise ConvergenceError(f"model {model.name!r}: no configuration at t={t_to:g}: {problem}")
    scales = coordinate_scales(model, q)
    s, h = 0.0, 1.0
    while s < 1.0:
        h = min(h, 1.0 - s)
        if s == 0.0 and rates is not None and columns.size == 0:
            guess = q + h * duration * rates[0] + 0.5 * (h * duration) ** 2 * rates[1]
        else:
            guess = _predict(model, q, t_from + s * duration, h, duration, columns, change)
        guess[columns] = start_values + (s + h) * change
        t = t_from + (s + h) * duration if s + h < 1.0 else t_to
        try:
            candidate = assemble(model, guess, t, fixed=fixed, tolerance=tolerance, max_iterations=max_iterations)
            accepted = np.max(np.abs(candidate - guess) / scales) <= max_correction
        except ConvergenceError:
            accepted = False
        if accepted:
            q, s, h = candidate, s + h, 2.0 * h
        elif h > 1e-9:
            h *= 0.5
        else:
            raise ConvergenceError(
                f"model {model.name!r}: cannot follow the assembly branch beyond t={t_from + s * duration:.6g} "
                f"(on the way to t={t_to:g}): " + (_at_limits(model, q, columns) or
                "the position analysis would jump to another assembly mode or does not converge — a singular "
                "configuration, or a motion the mechanism cannot reach"))
    return q


def _at_limits(model: Model, q: np.ndarray, held: np.ndarray) -> str:
    """The coordinates of ``q`` (not ``held``) at one of the model's ``coordinate_limits`` (within
    1e-6 of the range, or of 1), as a sentence; empty when there are none."""
    if model.coordinate_limits is None:
        return ""
    lower, upper = model.coordinate_limits
    span = np.where(np.isfinite(upper - lower), upper - lower, 1.0)
    named = [f"{name} beyond its limit {lower[k] if q[k] - lower[k] <= 1e-6 * span[k] else upper[k]:.6g}"
             for k, name in enumerate(model.coordinate_names)
             if k not in held and min(q[k] - lower[k], upper[k] - q[k]) <= 1e-6 * span[k]]
    return f"the motion takes {' and '.join(named)}" if named else ""


def _predict(model: Model, q: np.ndarray, t: float, h: float, duration: float, columns: np.ndarray,
             change: np.ndarray) -> np.ndarray:
    """q(s + h) ≈ q + h q' + ½ h² q'' on the path of :func:`follow_branch` (q'' only when time
    moves and no coordinate is held: the fixed coordinates' path is linear in s)."""
    terms = model.evaluate(q, np.zeros(model.n), t)
    rows = model.holonomic
    free = np.ones(model.n, dtype=bool)
    free[columns] = False
    tangent = np.zeros(model.n)
    tangent[columns] = change
    rhs = -terms.phi_t[rows] * duration - terms.A[rows] @ tangent
    tangent[free] = np.linalg.lstsq(terms.A[np.ix_(rows, free)], rhs, rcond=None)[0]
    guess = q + h * tangent
    if duration != 0.0 and columns.size == 0:
        qdd = accelerations(model, q, tangent / duration, t)
        guess += 0.5 * (h * duration) ** 2 * qdd
    return guess


def velocities(model: Model, q: np.ndarray, t: float = 0.0, *, qd: np.ndarray | None = None,
               fixed: Sequence[str | int] = ()) -> np.ndarray:
    """Solve A q̇ = -Φ_t with the ``fixed`` coordinates' velocities held at their values in ``qd``.

    The free velocities get the minimum-norm correction of ``qd`` (default ``model.qd0``).
    """
    qd = np.array(model.qd0 if qd is None else qd, dtype=float)
    terms = model.evaluate(np.asarray(q, float), qd, t)
    return _correct(terms.A, -terms.phi_t - terms.A @ qd, qd, _free_mask(model, fixed))


def accelerations(model: Model, q: np.ndarray, qd: np.ndarray, t: float = 0.0, *, qdd: np.ndarray | None = None,
                  fixed: Sequence[str | int] = ()) -> np.ndarray:
    """Solve A q̈ = γ with the ``fixed`` coordinates' accelerations held at their values in ``qdd``."""
    qdd = np.zeros(model.n) if qdd is None else np.array(qdd, dtype=float)
    terms = model.evaluate(np.asarray(q, float), np.asarray(qd, float), t)
    return _correct(terms.A, terms.gamma - terms.A @ qdd, qdd, _free_mask(model, fixed))


def _correct(A: np.ndarray, rhs: np.ndarray, base: np.ndarray, free: np.ndarray) -> np.ndarray:
    if A.shape[0] == 0:
        return base
    step, *_ = np.linalg.lstsq(A[:, free], rhs, rcond=None)
    result = base.copy()
    result[free] += step
    return result


def kinematic_analysis(model: Model, times: np.ndarray, *, q0: np.ndarray | None = None,
                       tolerance: float = 1e-12, max_iterations: int = 50) -> Trajectory:
    """Positions, velocities and accelerations of a fully driven model over ``times``.

    This is the kinematics of the thesis's inverse dynamic analysis (§4): drivers fix every
    degree of freedom, so at each t, Φ = 0, A q̇ = -Φ_t and A q̈ = γ have unique solutions.
    The configuration is carried from one output instant to the next along its assembly branch
    by :func:`follow_branch` (sub-steps between outputs as the motion needs), so that a coarse
    output grid gives the same configurations as a fine one.

    Raises
    ------
    ModelError
        When the model is not fully driven (DOF > 0 at the start).
    ConvergenceError
        When the branch cannot be followed (see :func:`follow_branch`).
    """
    times = np.asarray(times, dtype=float)
    q = assemble(model, q0, float(times[0]), tolerance=tolerance, max_iterations=max_iterations)
    report = constraint_report(model, q, float(times[0]))
    if report.dof > 0:
        raise ModelError(f"model {model.name!r} has {report.dof} degree(s) of freedom at t={times[0]:g}: "
                         f"kinematic analysis needs drivers on every DOF (add {report.dof} driver(s))")
    k, n = len(times), model.n
    Q, QD, QDD = np.zeros((k, n)), np.zeros((k, n)), np.zeros((k, n))
    for step, t in enumerate(times):
        if step > 0:
            q = follow_branch(model, q, float(times[step - 1]), float(t), tolerance=tolerance,
                              max_iterations=max_iterations, rates=(QD[step - 1], QDD[step - 1]))
        qd = velocities(model, q, float(t), qd=np.zeros(n))
        Q[step], QD[step], QDD[step] = q, qd, accelerations(model, q, qd, float(t))
    return Trajectory(times, Q, QD, QDD, model.coordinate_names,
                      info={"model": model.name, "analysis": "kinematics", "tolerance": tolerance})


@dataclass(frozen=True)
class SingularConfiguration:
    """A configuration along a motion where rank A drops: time, rank there, and σ_min/σ_max."""

    t: float
    rank: int
    nominal_rank: int
    relative_sigma: float


def singular_configurations(model: Model, trajectory: Trajectory, *, threshold: float = 1e-6,
                            tolerance: float = 1e-9, fixed: Sequence[str | int] = ()) -> list[SingularConfiguration]:
    """Find where A loses rank along a motion (e.g. the equal-link slider-crank at 90°).

    The nominal rank r is the largest rank seen over the samples; at each local minimum of
    ρ(t) = σ_r(A)/σ_1(A) over the samples, ρ is minimised between the neighbouring samples on a
    cubic Hermite interpolation of q (from q and q̇), and a singular configuration is reported
    where the minimum falls below ``threshold``.  With ``fixed`` coordinates (the inputs of a
    position analysis, held), A is restricted to the columns of the others: its rank drops where
    the inputs no longer decide the configuration (the mechanism moves, or gains a branch, with
    them held; :func:`cmbs.workspace.workspace`).
    """
    times, qs, qds = trajectory.t, trajectory.q, trajectory.qd
    free = _free_mask(model, fixed)

    def jacobian(q: np.ndarray, t: float) -> np.ndarray:
        return model.jacobian(q, t)[:, free]

    nominal = max(numerical_rank(jacobian(q, t), tolerance)[0] for t, q in zip(times, qs))
    if nominal == 0:
        return []

    def rho_at(q: np.ndarray, t: float) -> float:
        sigma = np.linalg.svd(jacobian(q, t), compute_uv=False)
        return float(sigma[nominal - 1] / max(sigma[0], 1e-300))

    def q_at(t: float, k: int) -> np.ndarray:
        h = times[k + 1] - times[k]
        s = (t - times[k]) / h
        h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
        return h00 * qs[k] + h10 * h * qds[k] + h01 * qs[k + 1] + h11 * h * qds[k + 1]

    rho = np.array([rho_at(q, t) for t, q in zip(times, qs)])
    found: list[SingularConfiguration] = []
    for k in range(len(times)):
        left = rho[k - 1] if k > 0 else np.inf
        right = rho[k + 1] if k + 1 < len(times) else np.inf
        if not (rho[k] <= left and rho[k] < right):
            continue
        lo, hi = times[max(k - 1, 0)], times[min(k + 1, len(times) - 1)]
        def segment(t: float) -> int:
            return max(int(np.searchsorted(times, t, side="right")) - 1, 0)

        def objective(t: float) -> float:
            j = min(segment(t), len(times) - 2)
            return rho_at(q_at(t, j), t)

        best = optimize.minimize_scalar(objective, bounds=(lo, hi), method="bounded", options={"xatol": 1e-12}) \
            if hi > lo else None
        t_min, value = (best.x, best.fun) if best is not None and best.fun < rho[k] else (times[k], rho[k])
        if value < threshold:
            j = min(segment(t_min), len(times) - 2)
            rank = numerical_rank(jacobian(q_at(t_min, j), t_min), max(tolerance, threshold))[0]
            found.append(SingularConfiguration(float(t_min), rank, nominal, float(value)))
    return found
