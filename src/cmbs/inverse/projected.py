"""Aghili's projected inverse dynamics (Aghili 2005, §VII; THEORY §5).

With ``M q̈ + Aᵀλ = Q_ext + τ`` (τ the actuation, generalized forces), every τ that produces a
given consistent acceleration q̈ (A q̈ = γ) is ``τ = b - Aᵀμ`` with ``b = M q̈ - Q_ext`` and any μ:
the component in range(Aᵀ) only changes the constraint force.  The minimum-norm one is the
projected inverse dynamics (PIDC)::

    τ = P b,   P = I - A⁺A                                    (|τ| minimal, A τ = 0)

and, with a weight W (mixed units), minimising |W⁻¹τ|::

    A_W = A W⁻¹,   P_W = I - A_W⁺ A_W,   τ = W P_W W⁻¹ b.

Passive joints (Aghili §VII-D): with the actuated selection S (diagonal 0/1), an admissible τ has
``(I - S) τ = 0``.  Adding an impotent component ``(I - P) η`` (it changes only the constraint
force), ``η = -[(I - S)(I - P)]⁺ (I - S) τ_PIDC`` cancels the passive components when
``(I - S) τ_PIDC ∈ range((I - S)(I - P))``: the controllability condition, reported when it fails.

The motion and the constraint force are decoupled when ``P M (I - P) = 0``.

The pseudo-inverses discard singular values below ``threshold`` of A with its rows normalised at
the model's initial configuration (as :class:`~cmbs.dynamics.Projection`), so a constraint row
that vanishes at a singular configuration is seen as lost.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from cmbs.dynamics.projection import pseudo_inverse, reference_row_scale
from cmbs.errors import CmbsError
from cmbs.model.model import Model


class ControllabilityError(CmbsError):
    """The passive joints cannot be left unactuated at this state (Aghili's condition fails)."""

    exit_status = 1


def projection_terms(model: Model, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, t: float, threshold: float,
                     weight: np.ndarray | None, u: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``b = M q̈ - Q_ext``, the projector ``P = I - A_W⁺A_W`` and ``A_W⁺`` (A_W = A W⁻¹, or A) at
    the state, after checking that ``qdd`` satisfies A q̈ = γ; Q_ext is the model's Q with the
    inputs ``u`` (zero when None)."""
    terms = model.evaluate(np.asarray(q, float), np.asarray(qd, float), t, u)
    qdd = np.asarray(qdd, dtype=float)
    residual = terms.A @ qdd - terms.gamma
    scale = max(1.0, np.abs(terms.A @ qdd).max(initial=0.0), np.abs(terms.gamma).max(initial=0.0))
    if np.abs(residual).max(initial=0.0) > 1e-8 * scale:
        raise CmbsError(f"model {model.name!r} at t={t:g}: the desired acceleration violates the constraints "
                        f"(max |A q̈ - γ| = {np.abs(residual).max():.3g}); make it consistent first "
                        "(cmbs.accelerations with the independent accelerations fixed)")
    b = terms.M @ qdd - terms.Q
    A = terms.A if weight is None else terms.A @ np.linalg.inv(weight)
    pinv, P = pseudo_inverse(A, threshold, reference_row_scale(model))
    return b, P, pinv


def pidc_torque(model: Model, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, t: float = 0.0, *,
                weight: np.ndarray | None = None, threshold: float = 1e-9, u: np.ndarray | None = None) -> np.ndarray:
    """Minimum-norm (or minimum |W⁻¹τ|) generalized force producing the consistent acceleration
    ``qdd`` at (q, q̇, t); Q_ext is the model's Q with the inputs ``u`` (zero by default)."""
    b, P, _ = projection_terms(model, q, qd, qdd, t, threshold, weight, u)
    if weight is None:
        return P @ b
    weight = np.asarray(weight, dtype=float)
    return weight @ (P @ np.linalg.solve(weight, b))


def passive_joint_torque(model: Model, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, t: float = 0.0, *,
                         actuated: Sequence[str], threshold: float = 1e-9, tolerance: float = 1e-8,
                         u: np.ndarray | None = None) -> np.ndarray:
    """Generalized force producing ``qdd`` with zero force on every coordinate not in
    ``actuated`` (Aghili §VII-D); Q_ext is the model's Q with the inputs ``u`` (zero by default).

    Raises
    ------
    ControllabilityError
        When ``(I - S) τ_PIDC`` is not in range((I - S)(I - P)): the passive joints cannot be
        left free at this state (e.g. the equal-link slider-crank with joint B passive at its
        singular position), naming the coordinates and the residual.
    """
    b, P, _ = projection_terms(model, q, qd, qdd, t, threshold, None, u)
    tau = P @ b
    passive = np.ones(model.n)
    passive[model.coordinate_indices(list(actuated))] = 0.0
    I_S = np.diag(passive)
    I_P = np.eye(model.n) - P
    operator = I_S @ I_P
    target = I_S @ tau
    eta = -np.linalg.pinv(operator, rcond=threshold) @ target
    result = tau + I_P @ eta
    residual = np.abs(I_S @ result).max(initial=0.0)
    if residual > tolerance * max(1.0, np.abs(tau).max(initial=0.0)):
        names = [model.coordinate_names[k] for k in np.flatnonzero(passive)]
        raise ControllabilityError(
            f"model {model.name!r} at t={t:g}: passive coordinate(s) {', '.join(names)} cannot be left "
            f"unactuated: the force they would need ({residual:.3g}) is not in the range of the constraint "
            "forces there ((I-S)τ_PIDC ∉ range((I-S)(I-P)), e.g. at a singular configuration)")
    return result


def is_decoupled(model: Model, q: np.ndarray, t: float = 0.0, *, tolerance: float = 1e-9,
                 threshold: float = 1e-9) -> bool:
    """True when motion and constraint force are decoupled at q: ``P M (I - P) = 0``
    (relative to |M|)."""
    terms = model.evaluate(np.asarray(q, float), np.zeros(model.n), t)
    _, P = pseudo_inverse(terms.A, threshold, reference_row_scale(model))
    coupling = P @ terms.M @ (np.eye(model.n) - P)
    return bool(np.abs(coupling).max(initial=0.0) <= tolerance * max(np.abs(terms.M).max(), 1e-300))
