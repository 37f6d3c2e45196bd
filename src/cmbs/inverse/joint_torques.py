"""Joint torques of a driven robot: the drivers prescribe the motion, the joints produce it
(docs/robots.md, "Inverse dynamics of a driven robot").

A robot's actuators are its joints: input u_k is the torque (revolute) or force (prismatic) of
joint k, ``Q = u - C(q, q̇) q̇ - g(q)`` (:mod:`cmbs.model.robot`).  Its drivers — pose drivers of
link frames (:mod:`cmbs.model.robot_targets`) and joint drivers — prescribe q(t), q̇(t), q̈(t)
(:func:`cmbs.kinematic_analysis`); they are not physical constraints.  The joint torques τ that
produce that motion on the robot without its drivers (closures and mimic couplings kept, rows
A_c) satisfy ``M q̈ + A_cᵀλ = Q(u + τ) = Q(u) + τ``, so (Aghili 2005, §VII;
:mod:`cmbs.inverse.projected`)::

    τ = b - A_cᵀμ,   b = M q̈ - Q(u),   any μ.

The rule: every joint carries torque and τ is the minimum-norm one, ``τ = P b``,
``P = I - A_c⁺A_c`` (:func:`~cmbs.inverse.projected.pidc_torque`) — for an open tree P = I and
``τ = M q̈ + C q̇ + g - u``, the recursive Newton-Euler inverse dynamics (Featherstone 2008,
§5.3); or, when ``actuated`` names the joints that carry it, τ is zero on the others
(:func:`~cmbs.inverse.projected.passive_joint_torque`, Aghili §VII-D; a
:class:`~cmbs.inverse.projected.ControllabilityError` when they cannot be left free).  The
closures' multipliers then solve ``A_cᵀλ = Q(u + τ) - M q̈`` (least squares: redundant rows
share their force by the minimum norm); the drivers' rows carry no force (λ = 0).
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from cmbs.errors import CmbsError
from cmbs.inverse.projected import passive_joint_torque, pidc_torque
from cmbs.kinematics import accelerations
from cmbs.model.model import Model
from cmbs.trajectory import Trajectory


def checked_actuated(model: Model, actuated: Sequence[str] | None) -> np.ndarray:
    """The columns of the joints that carry torque: all coordinates when ``actuated`` is None,
    else those named (a :class:`CmbsError` for an unknown, repeated or missing name)."""
    if actuated is None:
        return np.arange(model.n)
    names = [actuated] if isinstance(actuated, str) else list(actuated)
    if not names:
        raise CmbsError(f"model {model.name!r}: actuated names no joint; give at least one of "
                        f"{', '.join(model.coordinate_names)}")
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise CmbsError(f"model {model.name!r}: actuated names {', '.join(map(repr, repeated))} more than once")
    return model.coordinate_indices(names)


def joint_torques(model: Model, motion: Trajectory, inputs: Callable[[float, np.ndarray, np.ndarray], np.ndarray],
                  actuated: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The torques of the ``actuated`` joints (columns, :func:`checked_actuated`) that produce
    ``motion`` (of the driven ``model``; q and q̇ from it, q̈ the drivers' accelerations there) on
    top of the inputs ``inputs(t, q, q̇)`` (module docstring).

    Returns
    -------
    forces (k, len(actuated)), lam (k, m) — the closures' multipliers, zero on the drivers' rows —
    and the inputs applied (k, n_u).
    """
    free = model.without_drivers()
    closures = np.flatnonzero(~model.drivers)
    every_joint = actuated.size == model.n and np.array_equal(actuated, np.arange(model.n))
    names = [model.coordinate_names[c] for c in actuated]
    k = motion.t.size
    forces, lam, applied = np.zeros((k, actuated.size)), np.zeros((k, model.m)), np.zeros((k, model.n_u))
    terms = free.new_terms()
    for i, t in enumerate(motion.t):
        q, qd = motion.q[i], motion.qd[i]
        qdd = accelerations(model, q, qd, t)          # the drivers' own (A q̈ = γ), as every method
        applied[i] = inputs(t, q, qd)
        tau = pidc_torque(free, q, qd, qdd, t, u=applied[i]) if every_joint else \
            passive_joint_torque(free, q, qd, qdd, t, actuated=names, u=applied[i])
        forces[i] = tau[actuated]
        free.evaluate(q, qd, t, applied[i] + tau, out=terms)
        lam[i, closures] = np.linalg.lstsq(terms.A.T, terms.Q - terms.M @ qdd, rcond=None)[0]
    return forces, lam, applied
