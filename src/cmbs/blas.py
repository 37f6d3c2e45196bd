"""One BLAS thread for the small matrices of the Python loops.

A Python-loop run factorises and solves matrices of a few to a few tens of rows thousands of
times.  A multi-threaded BLAS (OpenBLAS starts one thread per core) hands each of those calls to
its threads and waits for them, which costs far more than the work: Udwadia-Kalaba on the
four-bar took 23 ms per evaluation with OpenBLAS's default threads on 2 busy cores and 0.35 ms
with one thread (a 7×7 triangular solve took 12 ms).  :func:`small_matrix_loop` limits BLAS to
one thread for the duration of such a loop (threadpoolctl) and restores the setting after it;
nothing is changed at import.
"""

from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

#: coordinates up to which a model's matrices count as small: one BLAS thread is faster
SMALL = 200


@contextmanager
def small_matrix_loop(n: int) -> Iterator[None]:
    """Within the block, BLAS (numpy's and scipy's) runs on one thread when ``n`` (the model's
    coordinates) is at most :data:`SMALL`; unchanged otherwise."""
    if n > SMALL:
        yield
        return
    import scipy.linalg  # noqa: F401 -- loads scipy's own BLAS now: threadpoolctl limits the loaded ones
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        yield
