"""The protocol every forward-dynamics formulation follows.

A formulation is a frozen set of parameters (Baumgarte's ξ, ω; the penalty α; an SVD
threshold).  :meth:`Formulation.bind` gives the per-run :class:`Solver` that owns whatever must
persist between evaluations (matrix-R's choice of independent coordinates, the augmented
Lagrangian's multipliers) and turns the terms of the equations of motion at one state into
accelerations, multipliers and constraint forces, in the library's convention (THEORY §1)::

    M q̈ + Aᵀ λ = Q,        generalized constraint force  f_c = -Aᵀ λ.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Protocol

import numpy as np

from cmbs.model.model import Model, Terms

#: Status codes of the compiled solves (:func:`cmbs.dynamics.field.field`): the accelerations were
#: found; the system is singular (the formulation cannot go on at this state); a term or an
#: acceleration is not finite (the motion diverged).
OK, SINGULAR, NON_FINITE = 0, 1, 2


@dataclass(frozen=True)
class Accelerations:
    """What a formulation returns at one state: ``qdd`` (n,), ``lam`` (m,) and the generalized
    constraint force ``constraint_force = -Aᵀλ`` (n,)."""

    qdd: np.ndarray
    lam: np.ndarray
    constraint_force: np.ndarray


class Solver(Protocol):
    """A formulation bound to one model for one run; ``adjusts_state`` tells whether
    :meth:`after_step` changes the state (the integrator then re-evaluates the derivative)."""

    adjusts_state: bool

    def accelerations(self, terms: Terms, q: np.ndarray, qd: np.ndarray, t: float) -> Accelerations:
        """Accelerations at the state whose terms (M, Q, Φ, A, γ, Φ_t) are ``terms``."""

    def after_step(self, q: np.ndarray, qd: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Adjust the state after an accepted integration step (identity for most formulations)."""

    def stage_state(self, q: np.ndarray, qd: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The state at which an integrator stage evaluates the accelerations (identity for most
        formulations; matrix R recovers the dependent coordinates from the independent ones)."""


class Formulation(Protocol):
    """Parameters of a formulation; ``name`` is its registry name (``"lagrange"``, ...)."""

    name: ClassVar[str]

    def bind(self, model: Model) -> Solver:
        """A solver for ``model``."""


class StatelessSolver:
    """Base for solvers that need no state between evaluations and leave steps untouched."""

    adjusts_state = False

    def __init__(self, model: Model):
        self.model = model

    def after_step(self, q: np.ndarray, qd: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        return q, qd

    def stage_state(self, q: np.ndarray, qd: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        return q, qd


def check_parameters(formulation: object, **rules: str) -> None:
    """Validate a formulation's options: each rule is ``"positive"``, ``"non-negative"``,
    ``"count"`` (integer ≥ 0), ``"above-one"``, ``"optional-positive"`` (None allowed) or
    ``"flag"`` (True or False).

    Raises :class:`~cmbs.errors.CmbsError` naming the formulation, the option and the value.
    """
    from cmbs.errors import CmbsError

    name = getattr(formulation, "name", type(formulation).__name__)
    for option, rule in rules.items():
        value = getattr(formulation, option)
        if rule == "optional-positive" and value is None:
            continue
        if rule == "flag":
            ok, expected = isinstance(value, (bool, np.bool_)), "true or false"
        elif rule == "count":
            ok = isinstance(value, int) and not isinstance(value, bool) and value >= 0
            expected = "an integer >= 0"
        else:
            number = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
            finite = number and bool(np.isfinite(value))
            ok = finite and {"positive": value > 0, "optional-positive": value > 0, "non-negative": value >= 0,
                             "above-one": value > 1}[rule] if finite else False
            expected = {"positive": "a number > 0", "optional-positive": "a number > 0", "non-negative":
                        "a number >= 0", "above-one": "a number > 1"}[rule]
        if not ok:
            raise CmbsError(f"formulation {name!r}: option {option} must be {expected}, got {value!r}")
