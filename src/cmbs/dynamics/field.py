"""Forward dynamics at one state, compiled: a model's terms, then a formulation's solve.

A formulation that runs in the compiled loops gives its dataclass a ``compiled(solver, model)``
method returning a :class:`typing.NamedTuple` of its parameters and work arrays whose class
carries ``solve(kernel, terms, t, q̇, q̈, λ) -> status`` (:class:`cmbs.dynamics.lagrange.LagrangeKernel`,
:class:`cmbs.dynamics.projection.ProjectionKernel`); a model gives its kernel tuple
(:mod:`cmbs.model.compiled`).  :func:`field` evaluates the one and solves with the other, each
chosen by its tuple's class when the caller is compiled (:func:`cmbs.jit.type_dispatch`): the
integration loops (:mod:`cmbs.integrate.compiled_rk4`, :mod:`cmbs.integrate.compiled_adaptive`)
are written once for every model kind and formulation, and a run compiles only what it uses.

The class also carries two hooks the loops call for every formulation: ``stage_state(kernel,
model, q, q̇, t, buffer) -> status`` on each stage state before its field, in place, and
``after_step(kernel, model, q, q̇, t, buffer) -> status`` on each accepted state, in place.
:func:`unchanged` is both for a formulation that takes the states as they are; matrix R
(:class:`cmbs.dynamics.matrix_r_kernels.MatrixRKernel`) recovers its dependent coordinates and
velocities there, and its after-step hook chooses a new partition in place when the partition
has become ill-conditioned.  A hook's failure status ends the run (the solver's
``loop_failure(status, t)`` gives its message,
:meth:`cmbs.dynamics.matrix_r.MatrixRSolver.loop_failure`).
A state the after-step hook left is one the stage hook leaves as it is (at the same time, with
the same kernel: matrix R's recovery of a recovered state changes nothing), so a loop need not
call the stage hook on it again.  An optional third hook, ``output_state`` (same arguments),
runs on each output state an adaptive loop interpolates before it is recorded: drift projection
(:class:`cmbs.dynamics.drift.DriftProjection`, which wraps a formulation's kernel) projects
the accepted and the output states there.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np

from cmbs.dynamics.base import NON_FINITE, OK, SINGULAR, Formulation
from cmbs.errors import CmbsError, SingularSystemError
from cmbs.jit import COMPILED, borrow, njit, type_dispatch
from cmbs.model.compiled import evaluate, model_kernel, terms_finite, terms_views
from cmbs.model.model import Model

#: ``solve(kernel, terms, t, qd, qdd, lam) -> status``: the solve of the formulation ``kernel`` describes.
solve = type_dispatch("solve")
#: ``stage_state(kernel, model, q, qd, t, buffer) -> status``: the formulation's stage state, in place.
stage_state = type_dispatch("stage_state")
#: ``after_step(kernel, model, q, qd, t, buffer) -> status``: the formulation's accepted state, in place.
after_step = type_dispatch("after_step")


@njit(cache=True, inline="always")
def unchanged(kernel, model, q, qd, t, buffer):
    """The stage and after-step hook of a formulation that takes every state as it is: OK."""
    return OK


#: ``output_state(kernel, model, q, qd, t, buffer) -> status``: an output state of an adaptive
#: loop (interpolated between accepted states) as the formulation records it, in place; the
#: state as it is (:func:`unchanged`) for a class without the hook.
output_state = type_dispatch("output_state", unchanged)


def formulation_kernel(chosen: Formulation, solver: object, model: Model) -> NamedTuple | None:
    """The compiled solve's tuple of formulation ``chosen`` bound to ``model`` as ``solver``, or
    None when the formulation (or one of its options) has none."""
    compiled = getattr(chosen, "compiled", None)
    return compiled(solver, model) if compiled is not None else None


@njit(cache=True)
def field(model, formulation, q, qd, t, u, buffer, terms, qdd, lam):
    """q̈ and λ at (q, q̇, t, u) into ``qdd``, ``lam``; returns OK, SINGULAR or NON_FINITE.

    ``model`` and ``formulation`` are the kernel tuples; ``buffer`` receives the terms and
    ``terms`` are its views (:func:`~cmbs.model.compiled.terms_views`), made once per run.  A
    state whose terms are not finite returns NON_FINITE before any factorisation."""
    evaluate(model, q, qd, t, u, buffer)
    n = q.shape[0]
    if not terms_finite(model, n, lam.shape[0], buffer):
        return NON_FINITE
    status = solve(formulation, terms, t, qd, qdd, lam)
    if status != OK:
        return status
    for k in range(n):
        if not math.isfinite(qdd[k]):
            return NON_FINITE
    return OK


@njit(cache=True)
def _bound_field_at(bound, q, qd, t, u, qdd, lam):
    """:func:`field` with the model, formulation and terms buffer of a :class:`Bound` (the call
    of :meth:`CompiledDynamics.into`), the terms' views made here: one compiled function between
    Python and the field, which numba links and optimises once."""
    model, formulation, buffer, q, qd, u, qdd, lam = borrow((bound.model, bound.formulation, bound.buffer, q, qd, u,
                                                             qdd, lam))
    terms = terms_views(model, q.shape[0], lam.shape[0], buffer)
    return field(model, formulation, q, qd, t, u, buffer, terms, qdd, lam)


if COMPILED:
    from numba.core import types
    from numba.experimental import structref

    @structref.register
    class _BoundType(types.StructRef):
        def preprocess_fields(self, fields):
            return tuple((name, types.unliteral(kind)) for name, kind in fields)

    class Bound(structref.StructRefProxy):
        """A model's kernel tuple, a formulation's and a terms buffer in one object, which a call
        from Python hands to compiled code as one pointer: numba types and unboxes a tuple of
        arrays element by element on every call (about 0.8 µs for a four-bar's two tuples)."""

    structref.define_proxy(Bound, _BoundType, ["model", "formulation", "buffer"])
else:
    class Bound:
        """The model's kernel tuple, the formulation's and a terms buffer (interpreted kernels)."""

        def __init__(self, model: NamedTuple, formulation: NamedTuple, buffer: np.ndarray):
            self.model, self.formulation, self.buffer = model, formulation, buffer


class CompiledDynamics:
    """Forward dynamics of one model under one formulation at single states, in one compiled call
    (model terms and solve: :func:`field`, the function the compiled loops run at each stage).

    For callers that evaluate q̈ at states of their own (an integrator of their own, a shooting
    method, a benchmark).  Same results as ``formulation.bind(model).accelerations`` after
    ``model.evaluate`` (tested to 1e-10); where the solve fails (Lagrange and Baumgarte at a
    rank-deficient A, naming the constraints; a mass matrix that is not positive definite) it
    raises the Python solver's :class:`~cmbs.errors.SingularSystemError`.

    Parameters
    ----------
    model
        A natural- or joint-coordinate model without Python-callable time functions.
    formulation
        A name or a :class:`~cmbs.dynamics.Formulation` with a compiled solve (``lagrange`` and
        ``baumgarte``, ``least_squares`` included, ``penalty``, ``projection`` with any inertia,
        ``udwadia-kalaba`` without a non-ideal term, ``matrix-r`` on a holonomic model: its solve
        at the state as given, without recovery, as ``MatrixRSolver.accelerations``).
    """

    def __init__(self, model: Model, formulation: str | Formulation = "lagrange"):
        from cmbs.dynamics import formulation as make_formulation

        chosen = make_formulation(formulation) if isinstance(formulation, str) else formulation
        self.model, self.formulation = model, chosen
        self.solver = chosen.bind(model)
        kernel = model_kernel(model)
        solve_kernel = formulation_kernel(chosen, self.solver, model) if kernel is not None else None
        if solve_kernel is None:
            raise CmbsError(f"the compiled field cannot run model {model.name!r} with formulation {chosen.name!r}: "
                            "it takes natural- or joint-coordinate models without Python time functions, with "
                            "a formulation that has a compiled solve (lagrange, baumgarte, penalty, projection, "
                            "udwadia-kalaba without a nonideal term, matrix-r on a holonomic model)")
        # bound once: a call then passes (and numba unboxes) only the state and the outputs
        self._field = functools.partial(_bound_field_at, Bound(kernel, solve_kernel, model.new_terms().buffer))
        self._no_input = np.zeros(model.n_u)

    def into(self, q: np.ndarray, qd: np.ndarray, t: float, u: np.ndarray | None, qdd: np.ndarray,
             lam: np.ndarray) -> int:
        """q̈ (n,) and λ (m,) at (q, q̇, t, u) into ``qdd`` and ``lam``; returns the status code
        (OK, SINGULAR or NON_FINITE).  Float64 contiguous arrays of the model's sizes; no
        checks and no allocation (the fast path)."""
        return self._field(q, qd, t, self._no_input if u is None else u, qdd, lam)

    def accelerations(self, q: np.ndarray, qd: np.ndarray, t: float = 0.0,
                      u: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(q̈, λ) at (q, q̇, t, u) as new arrays.

        Raises
        ------
        CmbsError
            Arrays of the wrong size; :class:`~cmbs.errors.SingularSystemError` at a singular
            configuration (Lagrange, Baumgarte: the constraints are named); non-finite terms or
            accelerations.
        """
        model = self.model
        q, qd = np.ascontiguousarray(q, dtype=float), np.ascontiguousarray(qd, dtype=float)
        u = self._no_input if u is None else np.ascontiguousarray(u, dtype=float)
        for name, value, size in (("q", q, model.n), ("qd", qd, model.n), ("u", u, model.n_u)):
            if value.shape != (size,):
                raise CmbsError(f"model {model.name!r}: {name} must have shape ({size},), got {value.shape}")
        qdd, lam = np.empty(model.n), np.empty(model.m)
        status = self.into(q, qd, float(t), u, qdd, lam)
        if status == SINGULAR:
            terms = model.evaluate(q, qd, t, u)
            self.solver.accelerations(terms, q, qd, t)   # raises, naming the dependent constraints
            raise SingularSystemError(f"model {model.name!r} at t={t:.6g}: singular system")
        if status != OK:
            raise CmbsError(f"model {model.name!r} at t={t:.6g}: non-finite terms or accelerations")
        return qdd, lam
