"""Constraint-force control and hybrid motion/force control (Aghili 2005 §VII-C, eq. 49-52;
THEORY §5).

Convention (THEORY §1): ``M q̈ + Aᵀλ = Q_ext + τ``, τ the actuation as generalized forces.  For
a consistent acceleration q̈ (A q̈ = γ) put ``b = M q̈ - Q_ext``.  Then

    τ = b + Aᵀλ_c    is the one generalized force giving the motion q̈ *and* the multipliers λ_c

(A of full row rank: substitute into the equations of motion, Aᵀ(λ - λ_c) = 0).  With the
projector P = I - A⁺A it splits into two orthogonal parts (Aghili §V, the decomposition of
Fig. 1):

    τ_∥ = P b                       potent: the PIDC torque, the only part that moves the system
    τ_⊥ = (I - P)(b + Aᵀλ_c)        impotent: changes the constraint force only

which is THEORY's ``τ_⊥ = (I - P)(M q̈ - Q) - f_d`` with the generalized constraint force
``f = -Aᵀλ``.  The desired constraint force is given as **multipliers λ_d(t)** in the model's
convention (for a closure row ``z_C - c = 0`` the guide pushes point C with the vertical force
``-λ``); the generalized force is then ``f_d = -Aᵀλ_d``.

Force loop (Aghili eq. 50, a PI law on the multipliers): ``λ_c = λ_d + K_f e + K_i ∫e dt`` with
``e = λ_d - λ`` the error of the *measured* multipliers.  With an exact model and an
instantaneous measurement λ = λ_c, hence the continuous error equation ``(1 + K_f) e + K_i ∫e = 0``.

How it is sampled (a digital force loop, period h): the integral is a state of the controller,
which :func:`cmbs.simulate` does not integrate, so it is updated at the controller's samples
t_k = k h only, never at Runge-Kutta stages.  At the first call with t ≥ t_k the controller

1. measures λ_k at the current (q, q̇, t) under the input it was applying just before t_k — the
   law re-evaluated with the previous command λ_c,k-1 (zero input at the first sample, before
   the controller ran).  The default sensor computes λ from the model's projection formulation
   (Aghili §V-B, ``λ = -(Aᵀ)⁺(I - P)(M q̈ - Q)``); pass ``measure`` to read a different plant;
2. updates ``e_k = Π(λ_d(t_k) - λ_k)``, ``I_k = I_k-1 + (k - k_prev) h e_k`` with
   Π = A A⁺ the part of λ the actuation can change (all of it when A has full row rank; near a
   singular configuration the lost direction is neither commanded nor integrated — Aghili's
   Remark 5 — which is the anti-windup);
3. holds ``λ_c,k = λ_d(t_k) + K_f e_k + K_i I_k`` until the next sample.

The torque itself is evaluated continuously from the held command (wrap the controller in
:class:`~cmbs.control.base.ZeroOrderHold` for a sampled torque too).  Commands are remembered by
sample, so a later call for an earlier time (a retried step, the recorder of :func:`cmbs.simulate`
re-evaluating the inputs at the output times) gets the command that was active then.  Use one
controller object per run (or :meth:`ConstraintForceControl.reset`); adaptive steps longer than
h skip samples — run the loop with a fixed step dividing h (rk4) to sample every period.

With an exact model the measured λ_k equals λ_c,k-1, so for constant λ_d the loop is the
difference equation ``x_k = (1 - K_f - K_i h) x_k-1 + K_f x_k-2`` (x = λ_c - λ_d), stable iff
``|K_f| < 1`` and ``0 < K_i h < 2 (1 - K_f)`` (Jury; K_i = 0 leaves the P law, also stable): the
one-sample measurement delay limits K_f below 1, unlike the continuous law.  The gains are
checked against these bounds (K_f ≥ 0, K_i ≥ 0).

The weight of :class:`~cmbs.control.pidc.PIDC` is not offered: the hybrid torque b + Aᵀλ_c is
fixed by the motion and the force command, and a weight would only relabel its split.
"""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from cmbs.control.base import Reference, gain_vector, input_map
from cmbs.dynamics.projection import Projection
from cmbs.errors import CmbsError
from cmbs.inverse.projected import projection_terms
from cmbs.kinematics import accelerations
from cmbs.model.model import Model

Sensor = Callable[[float, np.ndarray, np.ndarray, np.ndarray], np.ndarray]
ForceReference = float | Sequence[float] | Callable[[float], object]


@dataclass(frozen=True)
class Split:
    """The projected quantities at one state: ``b = M q̈ - Q_ext`` (n,), A (m, n), its
    pseudo-inverse A⁺ (n, m) and P = I - A⁺A."""

    b: np.ndarray
    A: np.ndarray
    pinv: np.ndarray
    P: np.ndarray

    def parts(self, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(τ_∥, τ_⊥) = (P b, (I - P)(b + Aᵀλ)) (Aghili eq. 43 and 49)."""
        motion = self.P @ self.b
        return motion, self.b - motion + (self.A.T @ lam - self.P @ (self.A.T @ lam))

    def controllable(self, lam: np.ndarray) -> np.ndarray:
        """Π λ = A A⁺ λ: the part of λ that Aᵀ sees (Aghili Remark 5)."""
        return self.A @ (self.pinv @ lam)


def split(model: Model, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, t: float = 0.0, *,
          threshold: float = 1e-9) -> Split:
    """:class:`Split` at (q, q̇, t) for the consistent acceleration ``qdd`` (CmbsError if
    A q̈ ≠ γ); pseudo-inverse as :func:`~cmbs.inverse.projected.pidc_torque`."""
    b, P, pinv = projection_terms(model, q, qd, qdd, t, threshold, None)
    return Split(b, model.jacobian(q, t), pinv, P)


def hybrid_torque(model: Model, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, lam: np.ndarray, t: float = 0.0,
                  *, threshold: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """Motion part P b and force part (I - P)(b + Aᵀλ) of the generalized force that gives the
    consistent acceleration ``qdd`` with multipliers ``lam`` (Aghili 2005 eq. 52)."""
    lam = np.asarray(lam, dtype=float)
    if lam.shape != (model.m,):
        raise CmbsError(f"model {model.name!r}: multipliers must have shape ({model.m},), got {lam.shape}")
    return split(model, q, qd, qdd, t, threshold=threshold).parts(lam)


class ForceSensor:
    """The multipliers λ a plant would show at (q, q̇, t) under inputs u, from its projection
    formulation (Aghili §V-B; minimum-norm λ if A loses rank)."""

    def __init__(self, model: Model, threshold: float = 1e-9):
        self.model = model
        self.solver = Projection(threshold=threshold).bind(model)
        self.terms = model.new_terms()

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray, u: np.ndarray) -> np.ndarray:
        self.model.evaluate(q, qd, t, u, out=self.terms)
        return self.solver.accelerations(self.terms, q, qd, t).lam.copy()

    def acceleration(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """q̈ with zero inputs (the free motion)."""
        self.model.evaluate(q, qd, t, None, out=self.terms)
        return self.solver.accelerations(self.terms, q, qd, t).qdd.copy()


def _force_reference(value: ForceReference, m: int, name: str) -> Callable[[float], np.ndarray]:
    if callable(value):
        def reference(t: float) -> np.ndarray:
            result = np.asarray(value(t), dtype=float).reshape(-1)
            if result.shape != (m,):
                raise CmbsError(f"force_reference(t) must return {m} multiplier(s) for model {name!r}, "
                                f"got shape {result.shape} at t={t:g}")
            return result
        return reference
    try:
        constant = np.broadcast_to(np.asarray(value, dtype=float), (m,)).copy()
    except ValueError:
        raise CmbsError(f"force_reference must be a number, {m} multiplier(s) or a function of t for model "
                        f"{name!r}, got {value!r}") from None
    return lambda t: constant


class ConstraintForceControl:
    """Constraint-force control alone (Aghili §VII-C): u(t, q, q̇) whose force part drives the
    multipliers to ``force_reference`` (λ_d, constant or a function of t) and whose motion
    part is zero — the system moves as if uncontrolled.  ``kf``, ``ki`` scalars or (m,);
    ``period`` the force loop's sample period h [s]; ``measure(t, q, q̇, u) -> λ`` the sensor
    (default :class:`ForceSensor` of ``model``).  Every coordinate must be actuated."""

    def __init__(self, model: Model, force_reference: ForceReference, *, kf: float | Sequence[float],
                 ki: float | Sequence[float], period: float = 1e-3, measure: Sensor | None = None,
                 threshold: float = 1e-9):
        if model.m == 0:
            raise CmbsError(f"model {model.name!r} has no constraints: there is no constraint force to control")
        if not (isinstance(period, (int, float)) and np.isfinite(period) and period > 0):
            raise CmbsError(f"force loop sample period must be a number > 0, got {period!r}")
        self.model = model
        self.reference = _force_reference(force_reference, model.m, model.name)
        self.kf = gain_vector(kf, model.m, "kf")
        self.ki = gain_vector(ki, model.m, "ki")
        if np.any(self.kf < 0) or np.any(self.kf >= 1):
            raise CmbsError(f"kf must be in [0, 1) (the sampled loop measures one sample late and is unstable "
                            f"for kf >= 1), got {kf!r}")
        if np.any(self.ki < 0) or np.any(self.ki * period >= 2 * (1 - self.kf)):
            raise CmbsError(f"ki must be >= 0 with ki·period < 2(1 - kf) for a stable sampled loop, got ki={ki!r} "
                            f"with period {period:g} s")
        self.period = float(period)
        self.threshold = threshold
        self.sensor = ForceSensor(model, threshold)
        self.measure = measure if measure is not None else self.sensor
        self.inverse_gains = input_map(model, model.coordinate_names)
        self.reset()

    def reset(self) -> None:
        """Forget the samples and the integral (before reusing the controller in a new run)."""
        self.samples: list[int] = []
        self.commands: list[np.ndarray] = []
        self.integral = np.zeros(self.model.m)

    def command(self, t: float, q: np.ndarray, qd: np.ndarray, at: Split) -> np.ndarray:
        """λ_c active at t: a new sample (measure, update the PI) at the first call with t ≥ t_k,
        else the command held since the latest sample not after t."""
        k = int(np.floor(t / self.period + 1e-9))
        if self.samples and k <= self.samples[-1]:
            return self.commands[max(bisect_right(self.samples, k) - 1, 0)]
        if self.samples:
            applied = self.inverse_gains @ np.add(*at.parts(self.commands[-1]))
            elapsed = k - self.samples[-1]
        else:
            applied, elapsed = np.zeros(self.model.n_u), 1
        desired = self.reference(t)
        error = at.controllable(desired - np.asarray(self.measure(t, q, qd, applied), dtype=float))
        self.integral = self.integral + elapsed * self.period * error
        lam = desired + self.kf * error + self.ki * self.integral
        self.samples.append(k)
        self.commands.append(lam)
        return lam

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        at = split(self.model, q, qd, self.sensor.acceleration(t, q, qd), t, threshold=self.threshold)
        return self.inverse_gains @ np.add(*at.parts(self.command(t, q, qd, at)))


def commanded_acceleration(model: Model, reference: Reference, columns: np.ndarray, kp: np.ndarray,
                           kd: np.ndarray, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """PIDC's consistent q̈_c: ``z̈_c = z̈_ref + K_d ė + K_p e`` on the reference coordinates,
    completed by A q̈_c = γ (Aghili eq. 44; as :class:`~cmbs.control.pidc.PIDC`)."""
    z_ref, zd_ref, zdd_ref = reference(t)
    desired = np.zeros(model.n)
    desired[columns] = zdd_ref + kd * (zd_ref - qd[columns]) + kp * (z_ref - q[columns])
    return accelerations(model, q, qd, t, qdd=desired, fixed=columns)


class Hybrid:
    """Hybrid motion/force control (Aghili 2005 eq. 52): the PIDC motion part P b for the
    PD-corrected acceleration of ``reference`` (gains ``kp`` [s⁻²], ``kd`` [s⁻¹]) plus the
    constraint-force part (I - P)(b + Aᵀλ_c) of a :class:`ConstraintForceControl` loop on
    ``force_reference`` (λ_d) with ``kf``, ``ki``.  With an exact model the motion error obeys
    ë + K_d ė + K_p e = 0 whatever the force part does."""

    def __init__(self, model: Model, reference: Reference, *, kp: float | Sequence[float],
                 kd: float | Sequence[float], force_reference: ForceReference, kf: float | Sequence[float],
                 ki: float | Sequence[float], period: float = 1e-3, measure: Sensor | None = None,
                 threshold: float = 1e-9):
        self.model = model
        self.reference = reference
        self.columns = model.coordinate_indices(list(reference.coordinates))
        self.kp = gain_vector(kp, self.columns.size, "kp")
        self.kd = gain_vector(kd, self.columns.size, "kd")
        self.force = ConstraintForceControl(model, force_reference, kf=kf, ki=ki, period=period, measure=measure,
                                            threshold=threshold)

    def parts(self, t: float, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(τ_∥, τ_⊥): the PIDC and the constraint-force generalized forces at (t, q, q̇)."""
        qdd = commanded_acceleration(self.model, self.reference, self.columns, self.kp, self.kd, t, q, qd)
        at = split(self.model, q, qd, qdd, t, threshold=self.force.threshold)
        return at.parts(self.force.command(t, q, qd, at))

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return self.force.inverse_gains @ np.add(*self.parts(t, q, qd))
