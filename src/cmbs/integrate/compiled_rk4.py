"""The compiled fixed-step RK4 loop: every step, stage and record in one numba function.

The loop is written once: it takes the model, the formulation and the inputs as kernel tuples
(:mod:`cmbs.model.compiled`, :mod:`cmbs.dynamics.field`, :class:`ConstantInputs` or
:class:`cmbs.control.compiled_torque.ComputedTorqueKernel`) and calls :func:`cmbs.dynamics.field.field`
at each stage, after the formulation's stage hook, and its after-step hook on each new state
(matrix R recovers its dependent coordinates there, and chooses a new partition when its
condition calls for one); numba compiles one specialisation per combination of their classes,
containing only the code that combination needs, and caches it.  The loop releases the GIL
(``nogil``): a sweep runs its variants on Python threads (:mod:`cmbs.integrate.variants`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cmbs.dynamics.base import OK
from cmbs.dynamics.field import after_step, field, stage_state
from cmbs.integrate.continuity import LEFT_BRANCH, jump_message, kept_records, left_branch, watch_array
from cmbs.jit import borrow, interpreted, njit, type_dispatch
from cmbs.model.compiled import terms_views

#: ``apply(inputs, step, stage, q, qd, t, u)``: the inputs at a stage into ``u``.
apply_inputs = type_dispatch("apply")


class ConstantInputs(NamedTuple):
    """Inputs that keep their initial value: nothing to do at the stages."""


@njit(cache=True)
def _keep(inputs, step, stage, q, qd, t, u):
    """Constant inputs: ``u`` stays as it is."""


ConstantInputs.apply = staticmethod(_keep)


def rk4(model: NamedTuple, formulation: NamedTuple, inputs: NamedTuple, q0: np.ndarray, qd0: np.ndarray, h: float,
        steps: int, every: int, u0: np.ndarray, buffer_size: int, m: int) -> tuple:
    """Fixed-step RK4 for ``steps`` steps of size ``h`` from t = 0; records (t, q, q̇, q̈, λ, u,
    |Φ|max, |Φ̇|max, f_c = -Aᵀλ) every ``every`` steps (only those are stored).  Returns the
    records, the number recorded and a status code with the time, the steps completed, the state
    and inputs it refers to (for a failed run: where the formulation could not go on).

    The inputs start at ``u0``; the ``inputs`` kernel may change them at each stage.  The
    recorded u at t_n is the input applied from t_n on, with q̈, λ evaluated with it.
    """
    state, records, work = _rk4_arrays(q0, qd0, u0, m, steps // every + 1, buffer_size)
    q, qd, u, sq, sv = state
    watch = interpreted(watch_array)(q0.shape[0], m)
    recorded, status, t_stop, step = _rk4_steps(model, formulation, inputs, h, steps, every, q, qd, u, sq, sv, work,
                                                records, 0, 0, watch)
    if status != OK:
        message = jump_message(watch) if status == LEFT_BRANCH else ""
        return *records, recorded, status, t_stop, step, sq, sv, u, message
    return *records, recorded, OK, steps * h, steps, q, qd, u, ""


def _rk4_arrays(q0, qd0, u0, m, records, buffer_size):
    """The arrays of an RK4 run from (q0, q̇0) with inputs u0: its state (q, q̇, u; the stage
    state), its records (t, q, q̇, q̈, λ, u, |Φ|max, |Φ̇|max, f_c) and its workspace (terms
    buffer, the stages' slopes of q and q̇, λ at the step and at a stage)."""
    n, n_u = q0.shape[0], u0.shape[0]
    state = (q0.copy(), qd0.copy(), u0.copy(), np.empty(n), np.empty(n))
    records = (np.zeros(records), np.zeros((records, n)), np.zeros((records, n)), np.zeros((records, n)),
               np.zeros((records, m)), np.zeros((records, n_u)), np.zeros(records), np.zeros(records),
               np.zeros((records, n)))
    work = (np.zeros(buffer_size), np.empty((4, n)), np.empty((4, n)), np.empty(m), np.empty(m))
    return state, records, work


@njit(cache=True, nogil=True)
def _rk4_steps(model, formulation, inputs, h, steps, every, q, qd, u, sq, sv, work, records, start_step, recorded,
               watch):
    """The loop of :func:`rk4` on the arrays :func:`_rk4_arrays` allocated (state q, q̇, u
    updated in place; stage state sq, sv), from step ``start_step`` with ``recorded`` records
    written; the branch watch (:mod:`cmbs.integrate.continuity`) sees each step's state, and
    where it finds the run left its branch the loop stops there (status LEFT_BRANCH) keeping the
    records up to the jump's start.  Returns (records written, status, time and step of a failed
    stage); where the after-step hook fails at the new state of step k, its status, time and step
    k + 1 (a loop that goes on from there records that state first)."""
    model, formulation, inputs, q, qd, u, sq, sv, work, records, watch = borrow(
        (model, formulation, inputs, q, qd, u, sq, sv, work, records, watch))
    n = q.shape[0]
    buffer, kq, kv, lam, stage_lam = work
    T, Qs, QDs, QDDs, LAMs, Us, PHI, PHID, FORCE = records
    terms = terms_views(model, n, lam.shape[0], buffer)
    for step in range(start_step, steps + 1):
        t = step * h
        st = t
        for stage in range(4):
            if stage == 0:
                for i in range(n):
                    sq[i] = q[i]
                    sv[i] = qd[i]
            else:
                a = h if stage == 3 else 0.5 * h
                for i in range(n):
                    sq[i] = q[i] + a * kq[stage - 1, i]
                    sv[i] = qd[i] + a * kv[stage - 1, i]
                st = t + a
            if stage > 0 or step == start_step:     # else the state the after-step hook left
                status = stage_state(formulation, model, sq, sv, st, buffer)
                if status != OK:
                    return recorded, status, st, step
            for i in range(n):                  # the stage's q̇, as the hook left it, is its slope of q
                kq[stage, i] = sv[i]
            apply_inputs(inputs, step, stage, sq, sv, st, u)
            status = field(model, formulation, sq, sv, st, u, buffer, terms, kv[stage],
                           lam if stage == 0 else stage_lam)
            if status != OK:
                return recorded, status, st, step
            if stage == 0:
                if left_branch(watch, t, qd, kv[0], terms[2]):
                    return kept_records(T, recorded, watch), LEFT_BRANCH, t, step
                if step % every == 0:
                    T[recorded] = t
                    for i in range(n):
                        Qs[recorded, i] = q[i]
                        QDs[recorded, i] = qd[i]
                        QDDs[recorded, i] = kv[0, i]
                    for i in range(lam.shape[0]):
                        LAMs[recorded, i] = lam[i]
                    for i in range(u.shape[0]):
                        Us[recorded, i] = u[i]
                    record_constraints(terms, qd, lam, PHI, PHID, FORCE, recorded)
                    recorded += 1
                if step == steps:
                    break
        if step == steps:
            break
        for i in range(n):                  # in place: the loop allocates nothing per step
            q[i] += (h / 6.0) * (kq[0, i] + 2.0 * kq[1, i] + 2.0 * kq[2, i] + kq[3, i])
            qd[i] += (h / 6.0) * (kv[0, i] + 2.0 * kv[1, i] + 2.0 * kv[2, i] + kv[3, i])
        status = after_step(formulation, model, q, qd, (step + 1) * h, buffer)
        if status != OK:
            return recorded, status, (step + 1) * h, step + 1
    return recorded, OK, steps * h, steps


@njit(cache=True)
def record_constraints(terms, qd, lam, PHI, PHID, FORCE, k):
    """Row ``k`` of a loop's records from the ``terms`` views (at the state with velocities
    ``qd``) and the multipliers ``lam``: max |Φ|, max |A q̇ + Φ_t| and f_c = -Aᵀλ."""
    _, phi, A, _, phi_t, _ = terms
    m, n = A.shape
    largest, rate_largest = 0.0, 0.0
    for a in range(m):
        largest = max(largest, abs(phi[a]))
        rate = phi_t[a]
        for j in range(n):
            rate += A[a, j] * qd[j]
        rate_largest = max(rate_largest, abs(rate))
    PHI[k], PHID[k] = largest, rate_largest
    for j in range(n):
        total = 0.0
        for a in range(m):
            total -= A[a, j] * lam[a]
        FORCE[k, j] = total


