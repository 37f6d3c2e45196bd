"""Inverse dynamic analysis of fully driven models (thesis §4; THEORY §5).

The drivers fix every degree of freedom, so kinematic analysis gives q, q̇, q̈ at each instant.
The force each driver must exert is what its constraint multiplier carries: with
``M q̈ + Aᵀλ = Q`` and a driver row ``q_c - f(t) = 0`` (row e_cᵀ of A), replacing the driver by a
generalized force τ_c on coordinate c gives the same motion when

    τ_c = -λ_c                                                     (Lagrange multipliers)

The velocity transformation gives it directly (thesis eq. 4.2): with the driven coordinates as
the independent coordinates z of the undriven model, q̇ = R ż, q̈ = R z̈ + Ṙ ż,

    Q_IDA = Rᵀ M R z̈ - Rᵀ (Q - M Ṙ ż) = Rᵀ (M q̈ - Q)

The two must agree (a test).  ``method`` chooses how the multipliers are obtained: from the
formulation of that name evaluated on the kinematic motion (``lagrange``, ``baumgarte``,
``penalty`` — the thesis's Figure 4.3 compares them), or ``matrix-r`` (Q_IDA above).

A robot's joints carry its actuation (:mod:`cmbs.inverse.joint_torques`): method ``projected``
gives the joint torques that produce the drivers' motion on the robot without its drivers — the
minimum-norm τ = P (M q̈ - Q) of Aghili's projected inverse dynamics, or zero on the joints not
``actuated`` — with the drivers' rows' multipliers zero.  It is the method of a robot driven by
a pose driver (a link frame's pose is no joint's force), and the only one there.

One rule for every method: the motion is the one the model's drivers impose.  Each method takes
q and q̇ from the motion and the accelerations the drivers impose there (A q̈ = γ, which holds
the drivers' f''(t)); a motion given as a :class:`~cmbs.trajectory.Trajectory` must agree with
the drivers in q, q̇ and q̈ (to :data:`MOTION_TOLERANCE`, relative), else a :class:`CmbsError`
names the instant and the coordinate — drive the model by that motion with
:func:`cmbs.motion.prescribe` instead.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import numpy as np

from cmbs.dynamics import formulation as make_formulation
from cmbs.errors import CmbsError, SingularSystemError, did_you_mean
from cmbs.kinematics import accelerations, kinematic_analysis
from cmbs.inverse.joint_torques import checked_actuated, joint_torques
from cmbs.model.model import Model, base_equations
from cmbs.model.robot import RobotEquations
from cmbs.trajectory import Trajectory

if TYPE_CHECKING:
    from cmbs.simulate import Inputs

METHODS = ("lagrange", "baumgarte", "penalty", "matrix-r", "projected")
#: A given motion's q, q̇ and q̈ must equal the drivers' to this, relative to the largest value
#: of each over the motion (positions: the constraint errors as displacements relative to the
#: model's size).
MOTION_TOLERANCE = 1e-6


@dataclass(frozen=True)
class InverseDynamics:
    """Result: the ``motion`` (q, q̇, q̈ with extras ``driver_forces`` (k, d) and ``lam``),
    the names of the driven coordinates (method ``projected``: the joints that carry torque) and
    of the drivers, and the method used."""

    motion: Trajectory
    driven_coordinates: tuple[str, ...]
    driver_names: tuple[str, ...]
    method: str

    @property
    def forces(self) -> np.ndarray:
        """(k, d) generalized forces on the driven coordinates that reproduce the motion."""
        return self.motion.extras["driver_forces"]

    def force(self, coordinate: str) -> np.ndarray:
        """The force history on one driven coordinate (CmbsError naming the driven coordinates for
        any other name)."""
        if coordinate not in self.driven_coordinates:
            raise CmbsError(f"no driver force on {coordinate!r}{did_you_mean(coordinate, self.driven_coordinates)}; "
                            f"the driven coordinates are {', '.join(self.driven_coordinates)}")
        return self.forces[:, self.driven_coordinates.index(coordinate)]


def driven_columns(model: Model) -> np.ndarray:
    """Index of the coordinate each driver row drives (its A row is a unit row vector)."""
    A = model.jacobian(model.q0, 0.0)[model.drivers]
    columns = []
    for name, row in zip(model.driver_names, A):
        nonzero = np.flatnonzero(np.abs(row) > 0)
        if nonzero.size != 1 or row[nonzero[0]] != 1.0:
            raise CmbsError(f"model {model.name!r}: driver {name!r} does not drive a single coordinate")
        columns.append(int(nonzero[0]))
    return np.array(columns, dtype=np.int64)


def inverse_dynamics(model: Model, times: np.ndarray | Trajectory, *, method: str | None = None,
                     u: Inputs | np.ndarray | None = None, actuated: Sequence[str] | None = None,
                     **options: object) -> InverseDynamics:
    """Forces on the driven coordinates (method ``projected``: on the robot's joints) that produce
    the motion imposed by the model's drivers.

    Parameters
    ----------
    times
        Output instants (the kinematic analysis runs on them), or a motion of this model that
        agrees with its drivers (see the module docstring).
    method
        ``lagrange``, ``baumgarte``, ``penalty`` (their multipliers of the driver rows),
        ``matrix-r`` (Q_IDA = Rᵀ(M q̈ - Q)); ``options`` go to the formulation; or, for a robot,
        ``projected`` (the joints' torques, :mod:`cmbs.inverse.joint_torques`).  Default
        ``projected`` for a robot with a pose driver, else ``lagrange``.
    u
        The model's actuator inputs during the motion, as for :func:`cmbs.simulate`: a constant
        (n_u,) array or a function u(t, q, q̇); zero by default.  The driver forces are what the
        drivers add to them.
    actuated
        Method ``projected``: the joints that carry torque (default all: the minimum-norm torques).
    """
    from cmbs.simulate import input_law

    equations = base_equations(model)[0]
    robot = isinstance(equations, RobotEquations)
    pose_driven = robot and equations.pose_driven
    method = method if method is not None else "projected" if pose_driven else "lagrange"
    if method not in METHODS:
        raise CmbsError(f"unknown inverse-dynamics method {method!r}{did_you_mean(method, METHODS)}; choose one of "
                        f"{', '.join(METHODS)}")
    if not model.drivers.any():
        raise CmbsError(f"model {model.name!r} has no drivers: nothing prescribes the motion")
    if method == "projected":
        if not robot:
            raise CmbsError(f"model {model.name!r}: method 'projected' gives a robot's joint torques; this model is "
                            "not a robot (a URDF tree): use lagrange, baumgarte, penalty or matrix-r")
        if options:
            raise CmbsError(f"method 'projected' takes no formulation options, got {', '.join(sorted(options))}")
        columns = checked_actuated(model, actuated)
    elif pose_driven:
        raise CmbsError(f"model {model.name!r}: a pose driver prescribes a link's pose, not a joint's force: its "
                        f"joint torques come from method 'projected' (the default for it), not {method!r}")
    elif actuated is not None:
        raise CmbsError(f"actuated is for method 'projected' (a robot's joint torques); method {method!r} gives "
                        "the forces of the driven coordinates")
    else:
        columns = driven_columns(model)
    inputs = input_law(model, u)
    if isinstance(times, Trajectory):
        motion = times
        check_motion(model, motion)
    else:
        motion = kinematic_analysis(model, np.asarray(times, dtype=float))
    driver_rows = np.flatnonzero(model.drivers)
    k = motion.t.size
    forces = np.zeros((k, columns.size))
    lam = np.zeros((k, model.m))
    applied = np.zeros((k, model.n_u))
    terms = model.new_terms()
    if method == "projected":
        forces, lam, applied = joint_torques(model, motion, inputs, columns)
    elif method == "matrix-r":
        free = model.without_drivers()
        solver = make_formulation("matrix-r", independent=tuple(model.coordinate_names[c] for c in columns),
                                  **options).bind(free)
        free_terms = free.new_terms()
        for i, t in enumerate(motion.t):
            applied[i] = inputs(t, motion.q[i], motion.qd[i])
            qdd = accelerations(model, motion.q[i], motion.qd[i], t)
            free.evaluate(motion.q[i], motion.qd[i], t, applied[i], out=free_terms)
            R = solver.velocity_matrix(free_terms)
            forces[i] = R.T @ (free_terms.M @ qdd - free_terms.Q)
            model.evaluate(motion.q[i], motion.qd[i], t, applied[i], out=terms)
            lam[i] = np.linalg.lstsq(terms.A.T, terms.Q - terms.M @ qdd, rcond=None)[0]
    else:
        solver = make_formulation(method, **options).bind(model)
        for i, t in enumerate(motion.t):
            applied[i] = inputs(t, motion.q[i], motion.qd[i])
            model.evaluate(motion.q[i], motion.qd[i], t, applied[i], out=terms)
            try:
                lam[i] = solver.accelerations(terms, motion.q[i], motion.qd[i], t).lam
            except np.linalg.LinAlgError as error:
                raise SingularSystemError(f"model {model.name!r} at t={t:.6g}: the {method} system is singular "
                                          f"({error}); try method 'matrix-r' or 'lagrange'") from None
            forces[i] = -lam[i, driver_rows]
    extras = {**motion.extras, "driver_forces": forces, "lam": lam}
    if model.n_u:
        extras["u"] = applied
    result = Trajectory(motion.t, motion.q, motion.qd, motion.qdd, motion.names, extras,
                        {**motion.info, "analysis": "inverse dynamics", "method": method,
                         "driven_coordinates": [model.coordinate_names[c] for c in columns]})
    return InverseDynamics(result, tuple(model.coordinate_names[c] for c in columns), model.driver_names, method)


def check_motion(model: Model, motion: Trajectory) -> None:
    """Raise a :class:`CmbsError` unless ``motion`` is one the model's drivers impose: Φ = 0,
    A q̇ = -Φ_t and q̈ equal to the acceleration analysis's (A q̈ = γ) at every instant, to
    :data:`MOTION_TOLERANCE`."""
    from cmbs.kinematics import position_errors, velocities

    if tuple(motion.names) != model.coordinate_names:
        raise CmbsError(f"the motion's coordinates ({', '.join(motion.names)}) are not model {model.name!r}'s "
                        f"({', '.join(model.coordinate_names)})")
    speed_scale = max(float(np.abs(motion.qd).max(initial=0.0)), 1e-300)
    accel_scale = max(float(np.abs(motion.qdd).max(initial=0.0)), 1e-300)
    for i, t in enumerate(motion.t):
        q, qd = motion.q[i], motion.qd[i]
        position = float(position_errors(model, q, t).max(initial=0.0))
        if not position <= MOTION_TOLERANCE:
            _disagreement(model, t, f"positions violate its constraints by {position:.3g} of its size")
        for label, given, own, scale in (("velocities", qd, velocities(model, q, t, qd=qd), speed_scale),
                                         ("accelerations", motion.qdd[i], accelerations(model, q, qd, t), accel_scale)):
            error = np.abs(given - own) / scale
            if not np.max(error) <= MOTION_TOLERANCE:
                worst = int(np.nanargmax(error)) if np.any(np.isfinite(error)) else 0
                _disagreement(model, t, f"{label} differ from the drivers' by {error[worst]:.3g} (relative) in "
                                        f"{model.coordinate_names[worst]}")


def _disagreement(model: Model, t: float, what: str) -> None:
    raise CmbsError(f"model {model.name!r}: at t={t:.6g} the motion's {what}: inverse dynamics computes the "
                    "forces of the drivers' own motion; to analyse this motion, drive the model by it "
                    "(cmbs.motion.prescribe, or --motion)")
