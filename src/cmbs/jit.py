"""numba when it is installed, else the same kernels as plain Python on numpy arrays.

Every compiled kernel of cmbs is written in the subset of Python and numpy that numba compiles,
and decorated with :func:`njit` from here.  Without numba (``import numba`` fails, e.g. on a
platform it has no wheels for, or with ``CMBS_DISABLE_NUMBA=1``) the decorator returns the
function unchanged: the same code runs interpreted, with the same results (tested to 1e-12
against the compiled kernels, tests/test_jit_fallback.py) and 100-1000× slower.  numba's own
``NUMBA_DISABLE_JIT=1`` has the same effect with numba installed.
"""

from __future__ import annotations

import os
from typing import Callable

try:
    if os.environ.get("CMBS_DISABLE_NUMBA", "") not in ("", "0"):
        raise ImportError("CMBS_DISABLE_NUMBA is set")
    import numba as _numba
except ImportError:
    _numba = None

#: True when the kernels are compiled by numba.
COMPILED = _numba is not None
#: numba's version, or "none": part of the name of generated equation modules.
VERSION = _numba.__version__ if _numba is not None else "none"


def njit(*args, **options) -> Callable:
    """``numba.njit`` with numba, else a decorator that leaves the function as it is."""
    if _numba is not None:
        return _numba.njit(*args, **options)
    if len(args) == 1 and callable(args[0]) and not options:
        return args[0]
    return lambda function: function


def njit_borrowing(*args, **options) -> Callable:
    """:func:`njit` for the kernels of the hot paths, which by design work on arrays their caller
    owns: they take packed arrays (a model's ``ints``/``reals``, a run's workspace), write into
    work arrays the caller allocated once per run, create no array themselves and return scalars
    or tuples of scalars.  Each array argument costs numba a reference-count increment and
    decrement per call, so a hot kernel takes few of them.  The compiled paths free every array
    they allocate, and the fixed-step RK4 loop allocates none per step (tests/test_borrowing.py)."""
    return njit(*args, **options)


def interpreted(kernel: Callable) -> Callable:
    """The Python function a kernel was compiled from (the kernel itself without numba): for a
    one-off call from Python of a plain-numpy kernel, which then loads no compiled code."""
    return getattr(kernel, "py_func", kernel)


#: ``numba.prange`` (parallel loop over independent iterations) with numba, else ``range``.
prange = _numba.prange if _numba is not None else range


def threads() -> int:
    """Threads a parallel kernel uses (numba's), 1 without numba."""
    return _numba.get_num_threads() if _numba is not None else 1


def announce_compilation(write: Callable[[str], object]) -> None:
    """Call ``write`` with one line the first time this process compiles a kernel (numba's
    ``numba:compile`` event, which a kernel loaded from the disk cache does not raise): the first
    run after an install compiles for one to two minutes and would otherwise look stuck."""
    if _numba is None:
        return
    from numba.core import event

    class Announcement(event.Listener):
        done = False

        def on_start(self, event: object) -> None:
            if not self.done:
                self.done = True
                write("cmbs: compiling the kernels this run needs (first use after an install: 1-2 minutes; "
                      "cached for later runs)")

        def on_end(self, event: object) -> None:
            pass

    event.register("numba:compile", Announcement())



class _CompileClock:
    """Seconds spent in numba's ``numba:compile`` events (:mod:`numba.core.event`) since it was
    registered, from each outermost start to its end, so that a kernel compiling its callees counts
    once."""

    def __init__(self) -> None:
        from numba.core import event

        self.listener = event.TimingListener()
        event.register("numba:compile", self.listener)

    def seconds(self) -> float:
        return self.listener.duration if self.listener.done else 0.0


_clock: _CompileClock | None = None


def compile_seconds() -> float:
    """Seconds this process has spent compiling kernels since its first call of this function (0
    without numba).  The difference of two calls is the compile time between them: 0 when every
    kernel used was already compiled in this process or loaded from the disk cache.  A run
    reports it as ``info["compile_time"]``, included in its ``wall_time``."""
    global _clock
    if _numba is None:
        return 0.0
    if _clock is None:
        _clock = _CompileClock()
    return _clock.seconds()
