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

One rule for every method: the motion is the one the model's drivers impose.  Each method takes
q and q̇ from the motion and the accelerations the drivers impose there (A q̈ = γ, which holds
the drivers' f''(t)); a motion given as a :class:`~cmbs.trajectory.Trajectory` must agree with
the drivers in q, q̇ and q̈ (to :data:`MOTION_TOLERANCE`, relative), else a :class:`CmbsError`
names the instant and the coordinate — drive the model by that motion with
:func:`cmbs.motion.prescribe` instead.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from cmbs.dynamics import formulation as make_formulation
from cmbs.errors import CmbsError, SingularSystemError, did_you_mean
from cmbs.kinematics import accelerations, kinematic_analysis
from cmbs.model.model import Model
from cmbs.trajectory import Trajectory

if TYPE_CHECKING:
    from cmbs.simulate import Inputs

METHODS = ("lagrange", "baumgarte", "penalty", "matrix-r")
#: A given motion's q, q̇ and q̈ must equal the drivers' to this, relative to the largest value
#: of each over the motion (positions: the constraint errors as displacements relative to the
#: model's size).
MOTION_TOLERANCE = 1e-6


@dataclass(frozen=True)
class InverseDynamics:
    """Result: the ``motion`` (q, q̇, q̈ with extras ``driver_forces`` (k, d) and ``lam``),
    the names of the driven coordinates and of the drivers, and the method used."""

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


def inverse_dynamics(model: Model, times: np.ndarray | Trajectory, *, method: str = "lagrange",
                     u: Inputs | np.ndarray | None = None, **options: object) -> InverseDynamics:
    """Forces on the driven coordinates that produce the motion imposed by the model's drivers.

    Parameters
    ----------
    times
        Output instants (the kinematic analysis runs on them), or a motion of this model that
        agrees with its drivers (see the module docstring).
    method
        ``lagrange``, ``baumgarte``, ``penalty`` (their multipliers of the driver rows) or
        ``matrix-r`` (Q_IDA = Rᵀ(M q̈ - Q)); ``options`` go to the formulation.
    u
        The model's actuator inputs during the motion, as for :func:`cmbs.simulate`: a constant
        (n_u,) array or a function u(t, q, q̇); zero by default.  The driver forces are what the
        drivers add to them.
    """
    from cmbs.simulate import input_law

    if method not in METHODS:
        raise CmbsError(f"unknown inverse-dynamics method {method!r}; choose one of {', '.join(METHODS)}")
    if not model.drivers.any():
        raise CmbsError(f"model {model.name!r} has no drivers: nothing prescribes the motion")
    inputs = input_law(model, u)
    if isinstance(times, Trajectory):
        motion = times
        check_motion(model, motion)
    else:
        motion = kinematic_analysis(model, np.asarray(times, dtype=float))
    columns = driven_columns(model)
    driver_rows = np.flatnonzero(model.drivers)
    k = motion.t.size
    forces = np.zeros((k, columns.size))
    lam = np.zeros((k, model.m))
    applied = np.zeros((k, model.n_u))
    terms = model.new_terms()
    if method == "matrix-r":
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
