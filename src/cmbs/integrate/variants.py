"""Many variants of one compiled run, each by the loop a single run takes, on Python threads.

The batched sweep (:mod:`cmbs.sweep`) runs N initial states and constant inputs of one model,
formulation and integrator.  Each variant here is one call of the single-run loop
(:func:`cmbs.integrate.compiled_rk4.rk4`, :func:`cmbs.integrate.compiled_adaptive.adaptive`)
with a copy of the formulation's work arrays of its own (its kernel's ``fresh``); the loops
release the GIL while they run (numba's ``nogil``), so the variants run in parallel on a pool of
:func:`cmbs.jit.threads` Python threads.  The numbers are those of single runs, bit for bit, and
a sweep compiles nothing a single run of the same model, formulation and integrator has not
already compiled (a loop of its own, parallel over the variants in numba's ``prange``, took 15 to
20 s to compile on its first use).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Callable, NamedTuple

import numpy as np

from cmbs.integrate.compiled_adaptive import adaptive
from cmbs.integrate.compiled_rk4 import rk4
from cmbs.integrate.tableaus import Tableau
from cmbs.jit import threads


def fresh(kernel: tuple) -> tuple:
    """A copy of a formulation's kernel tuple for a run beside others: of the same class (the
    class chooses the kernels: a band-LU kernel stays one), each writeable array copied (work
    arrays, matrix R's partition, the penalty's λ*), in nested tuples too; read-only data shared
    (a copy would be writeable, a type the loops would be compiled for again)."""
    items = [fresh(item) if isinstance(item, tuple) else
             item.copy() if isinstance(item, np.ndarray) and item.flags.writeable else item for item in kernel]
    return type(kernel)(*items) if hasattr(kernel, "_fields") else tuple(items)


def each_variant(run: Callable[[int], None], count: int) -> None:
    """``run(v)`` for every variant v < ``count``, on up to :func:`cmbs.jit.threads` threads (an
    exception raised by a run is raised here)."""
    workers = min(threads(), count)
    if workers <= 1:
        for v in range(count):
            run(v)
        return
    with ThreadPoolExecutor(max_workers=workers) as pool:
        for _ in pool.map(run, range(count)):
            pass


def rk4_variants(model: NamedTuple, formulation: NamedTuple, inputs: NamedTuple, Q0: np.ndarray, QD0: np.ndarray,
                 U0: np.ndarray, h: float, steps: int, every: int, buffer_size: int, m: int, Qs: np.ndarray,
                 QDs: np.ndarray, PHIs: np.ndarray, statuses: np.ndarray, recorded: np.ndarray) -> None:
    """:func:`~cmbs.integrate.compiled_rk4.rk4` from each row of Q0, QD0 with the inputs of U0's
    row: writes each variant's recorded q, q̇ and |Φ|max into Qs (N, records, n), QDs and PHIs
    (N, records), its status and the number of records it reached."""
    def run(v: int) -> None:
        out = rk4(model, fresh(formulation), inputs, Q0[v], QD0[v], h, steps, every, U0[v], buffer_size, m)
        count = out[9]
        Qs[v, :count] = out[1][:count]
        QDs[v, :count] = out[2][:count]
        PHIs[v, :count] = out[6][:count]
        statuses[v], recorded[v] = out[10], count

    each_variant(run, Q0.shape[0])


def adaptive_variants(model: NamedTuple, formulation: NamedTuple, Q0: np.ndarray, QD0: np.ndarray, U0: np.ndarray,
                      t_out: np.ndarray, kept: np.ndarray, rtol: float, atol: float, tableau: Tableau,
                      adjusts_state: bool, buffer_size: int, m: int, Qs: np.ndarray, QDs: np.ndarray,
                      PHIs: np.ndarray, statuses: np.ndarray, stops: np.ndarray, recorded: np.ndarray) -> None:
    """:func:`~cmbs.integrate.compiled_adaptive.adaptive` from each row of Q0, QD0 with the
    constant inputs of U0's row, outputs at ``t_out``: writes the outputs ``kept`` (increasing rows
    of ``t_out``) that each variant reached, its q, q̇ and |Φ|max into Qs (N, kept, n), QDs and
    PHIs (N, kept); its status, the time it refers to (where a failed run stopped) and the number
    of kept outputs it reached."""
    def run(v: int) -> None:
        result = adaptive(model, fresh(formulation), Q0[v], QD0[v], t_out, rtol, atol, U0[v], buffer_size, m, tableau,
                          adjusts_state)
        count = int(np.searchsorted(kept, result.recorded))
        rows = kept[:count]
        Qs[v, :count] = result.records[1][rows]
        QDs[v, :count] = result.records[2][rows]
        PHIs[v, :count] = result.records[5][rows]
        statuses[v], stops[v], recorded[v] = result.status, result.t_stop, count

    each_variant(run, Q0.shape[0])
