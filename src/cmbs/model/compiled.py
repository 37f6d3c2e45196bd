"""A model as the compiled loops take it: its kernel tuple and the terms that kernel writes.

Each model kind with a compiled evaluator gives its equations a ``compiled_kernel()`` method
returning a :class:`typing.NamedTuple` of its data whose class carries the kernel as
``evaluate(kernel, q, q̇, t, u, buffer)`` (:class:`cmbs.model.natural.NaturalKernel`,
:class:`cmbs.model.joints.JointKernel`).  :func:`evaluate` calls the kernel of the tuple's class,
chosen when the caller is compiled (:func:`cmbs.jit.type_dispatch`): a loop compiles only the
evaluator of the model it runs.  The kernel writes M (unless constant), Q, Φ, A, γ and Φ_t
into a buffer laid out as :class:`~cmbs.model.model.Terms`; :func:`terms_views` gives the loops
their views, made once per run.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from cmbs.jit import njit, type_dispatch
from cmbs.model.model import Model

#: ``evaluate(kernel, q, qd, t, u, buffer)``: the terms of the model ``kernel`` describes.
evaluate = type_dispatch("evaluate")


def model_kernel(model: Model) -> NamedTuple | None:
    """The compiled kernel tuple of ``model``, or None when its terms cannot be evaluated by
    compiled code alone (user-equation models, Python-callable time functions)."""
    kernel = getattr(model.equations, "compiled_kernel", None)
    return kernel() if kernel is not None else None


@njit(cache=True, inline="always")
def terms_views(kernel, n, m, buffer):
    """Views (Q, Φ, A, γ, Φ_t, M) of the terms the kernel writes into ``buffer``; M is the
    kernel's constant ``mass`` when it has one (n x n), else the buffer's."""
    Q = buffer[:n]
    phi = buffer[n:n + m]
    A = buffer[n + m:n + m + m * n].reshape((m, n))
    gamma = buffer[n + m + m * n:n + 2 * m + m * n]
    phi_t = buffer[n + 2 * m + m * n:n + 3 * m + m * n]
    mass = kernel.mass
    M = mass if mass.shape[0] == n else buffer[n + 3 * m + m * n:n + 3 * m + m * n + n * n].reshape((n, n))
    return Q, phi, A, gamma, phi_t, M


@njit(cache=True, inline="always")
def terms_finite(kernel, n, m, buffer):
    """True when every term the kernel wrote (Q, Φ, A, γ, Φ_t, and M when not constant) is
    finite: a state that has blown up must not reach a factorisation."""
    size = n + 3 * m + m * n if kernel.mass.shape[0] == n else n + 3 * m + m * n + n * n
    for k in range(size):
        if not math.isfinite(buffer[k]):
            return False
    return True
