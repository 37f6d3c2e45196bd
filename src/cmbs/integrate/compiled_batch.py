"""Many runs of one adaptive integration in one compiled call, parallel over the runs.

:func:`adaptive_batch` runs the rk45/rk23/dop853 loop of :mod:`cmbs.integrate.compiled_adaptive`
(its :func:`~cmbs.integrate.compiled_adaptive._steps`, the loop :func:`cmbs.simulate` runs) for N
variants of the initial state and the constant inputs, one variant per iteration of a numba
``prange`` (threads), each with its own arrays and its own copy of the formulation's work arrays
(:func:`cmbs.integrate.compiled_rk4.fresh`): each variant's numbers are those of its own
:func:`cmbs.simulate` run.  The fixed-step RK4 batch is
:func:`cmbs.integrate.compiled_rk4.rk4_batch`, beside its loop.
"""

from __future__ import annotations

import numpy as np

from cmbs.integrate.compiled_adaptive import _steps, run_arrays
from cmbs.integrate.compiled_rk4 import fresh
from cmbs.integrate.continuity import watch_array
from cmbs.jit import njit, prange


@njit(cache=True, parallel=True)
def adaptive_batch(model, formulation, Q0, QD0, U0, t_out, kept, rtol, atol, method, max_steps, buffer_size, m, Qs,
                   QDs, PHIs, statuses, stops, recorded):
    """The adaptive loop from each row of Q0, QD0 with the constant inputs of U0's row, outputs at
    ``t_out`` (as :func:`cmbs.integrate.compiled_adaptive.adaptive` with ``method`` of
    :func:`~cmbs.integrate.compiled_adaptive.loop_method` and ``max_steps``).  Writes the outputs
    ``kept`` (increasing rows of ``t_out``) that each variant reached: its q, q̇ and |Φ|max into
    Qs (N, kept, n), QDs and PHIs (N, kept); its status, the time it refers to (where a failed
    run stopped) and the number of kept outputs it reached."""
    for v in prange(Q0.shape[0]):
        y, y_new, k1, stages, counts, where, buffer, records = run_arrays(Q0[v], QD0[v], t_out, m, method[0], method[6],
                                                                          buffer_size)
        status, t_stop = _steps(model, fresh(formulation), y, y_new, k1, stages, counts, where, records, buffer,
                                t_out, rtol, atol, U0[v], method[0], method[1], method[2], method[3], method[4],
                                method[5], method[6], method[7], method[8], method[9], method[10], max_steps,
                                watch_array(Q0.shape[1], m))
        count = np.searchsorted(kept, counts[0])      # the kept outputs among the rows recorded
        for j in range(count):
            row = kept[j]
            for i in range(Q0.shape[1]):
                Qs[v, j, i] = records[1][row, i]
                QDs[v, j, i] = records[2][row, i]
            PHIs[v, j] = records[5][row]
        statuses[v] = status
        stops[v] = t_stop
        recorded[v] = count
