"""Which runs the compiled loops take, and the kernel tuples they take them with.

A run is compiled when its model, formulation and inputs each have a compiled kernel
(:func:`cmbs.model.compiled.model_kernel`, :func:`cmbs.dynamics.field.formulation_kernel`,
:func:`inputs_kernel`) and its integrator has a compiled loop for them: rk4 (t_end a multiple of
dt) with any inputs kernel, rk45/rk23/dop853 with constant inputs; with drift projection the
formulation's kernel is wrapped in :class:`~cmbs.dynamics.drift.DriftProjection` (not for a
batch).  The index-3 integrators (backward Euler, generalized-α:
:mod:`cmbs.integrate.compiled_index3`) bring their own formulation: they need the model's and
the inputs' kernels only (a held law with t_end a multiple of dt); so does the trapezoidal rule
in matrix R's independent coordinates (:mod:`cmbs.integrate.compiled_reduced`), with constant
inputs.  :func:`cmbs.simulate` and :func:`cmbs.sweep` ask here; a batch of runs
(:mod:`cmbs.integrate.variants`) takes every formulation kernel, each run with its own copy
(matrix R: its own partition too).
"""

from __future__ import annotations

from typing import NamedTuple

from cmbs.dynamics.base import Formulation
from cmbs.dynamics.drift import drift_projection
from cmbs.dynamics.field import formulation_kernel
from cmbs.integrate.compiled_rk4 import ConstantInputs
from cmbs.integrate.grid import whole_steps
from cmbs.model.compiled import model_kernel
from cmbs.model.model import Model

#: The integrators with a compiled adaptive loop (:mod:`cmbs.integrate.compiled_adaptive`).
ADAPTIVE = ("rk45", "rk23", "dop853")
#: The integrators of the index-3 DAE, compiled with :mod:`cmbs.integrate.compiled_index3`.
INDEX3 = ("backward-euler", "generalized-alpha")


def inputs_kernel(u: object, model: Model, dt: float) -> NamedTuple | None:
    """The inputs of a run of ``model`` with step ``dt`` as the compiled loop takes them:
    :class:`~cmbs.integrate.compiled_rk4.ConstantInputs` for an array or None; a
    :class:`~cmbs.control.compiled_torque.ComputedTorqueKernel` for a
    :class:`~cmbs.control.ComputedTorque` law, alone or in a :class:`~cmbs.control.ZeroOrderHold`
    of period ``dt`` exactly, whose model has a compiled kernel and the plant's coordinate and
    input counts; None for anything else (a fault wrapper, another law, another period)."""
    if not callable(u):
        return ConstantInputs()
    from cmbs.control.base import ZeroOrderHold   # here: a run with constant inputs does not import
    from cmbs.control.computed_torque import ComputedTorque   # the control package
    from cmbs.control.compiled_torque import computed_torque_kernel

    held = type(u) is ZeroOrderHold and u.period == dt
    law = u.law if held else u
    if type(law) is not ComputedTorque or law.model.n != model.n or law.model.n_u != model.n_u:
        return None
    return computed_torque_kernel(law, held)


def compiled_run(model: Model, chosen: Formulation, solver: object, integrator: str, u: object, project: bool,
                 t_end: float, dt: float, batched: bool = False, projection_tolerance: float = 1e-10
                 ) -> tuple[NamedTuple, NamedTuple | None, NamedTuple] | None:
    """(model, formulation, inputs) kernel tuples when a compiled loop can run the simulation of
    ``model`` under ``chosen`` (bound as ``solver``) with ``integrator``, else None (why:
    :func:`compiled_plan`)."""
    plan = compiled_plan(model, chosen, solver, integrator, u, project, t_end, dt, batched, projection_tolerance)
    return None if isinstance(plan, str) else plan


def compiled_plan(model: Model, chosen: Formulation, solver: object, integrator: str, u: object, project: bool,
                  t_end: float, dt: float, batched: bool = False, projection_tolerance: float = 1e-10
                  ) -> tuple[NamedTuple, NamedTuple | None, NamedTuple] | str:
    """The kernel tuples of :func:`compiled_run`, or the reason in a few words why no compiled loop
    can run the simulation (the note of a run on the Python loop).  The formulation's tuple is
    None for an index-3 integrator (:data:`INDEX3`) and the trapezoidal rule, which bring their
    own.  ``batched``: for many runs of a sweep (:mod:`cmbs.integrate.variants`,
    :mod:`cmbs.integrate.compiled_lanes`), without drift projection.  ``project``: drift
    projection to ``projection_tolerance`` after each step (explicit integrators only)."""
    if project and batched:
        return "drift projection is not batched"
    if integrator not in ("rk4", "trapezoidal") and integrator not in ADAPTIVE and integrator not in INDEX3:
        return f"integrator {integrator!r} has no compiled loop (rk4, {', '.join(ADAPTIVE)}, trapezoidal and " \
               f"{' and '.join(INDEX3)} have)"
    if project and integrator != "rk4" and integrator not in ADAPTIVE:
        return f"drift projection is compiled with rk4 and {', '.join(ADAPTIVE)}, not {integrator}"
    model_part = model_kernel(model)
    if model_part is None:
        return f"model {model.name!r} has Python-callable terms or time functions"
    inputs = inputs_kernel(u, model, dt)
    if inputs is None:
        return ("the inputs are a Python callable (a ComputedTorque law alone or held with period dt is "
                "compiled)")
    exact = whole_steps(t_end, dt) is not None
    if integrator not in INDEX3 and integrator != "rk4" and not isinstance(inputs, ConstantInputs):
        return f"inputs that change during the run are compiled with rk4 and {' and '.join(INDEX3)}, not {integrator}"
    if integrator == "trapezoidal":
        return model_part, None, inputs
    if integrator in INDEX3:        # a held law samples at each step's end: the steps must be the periods
        if getattr(inputs, "held", False) and not exact:
            return "t_end is not a multiple of dt, the period of the held law"
        return model_part, None, inputs
    if integrator == "rk4" and not exact:
        return "t_end is not a multiple of dt"
    formulation = formulation_kernel(chosen, solver, model)
    if formulation is None:
        return f"formulation {chosen.name!r} with these options has no compiled solve"
    return model_part, drift_projection(formulation, model, projection_tolerance) if project else formulation, inputs
