"""Python's cyclic garbage collector in the process of the ``cmbs`` command.

A compiled run starts by creating some 10⁵ objects that are never freed: the modules of numpy,
numba and cmbs, and numba's typing and lowering registries, which numba builds when its CPU
target initialises (at the first compiled call, loading scipy.linalg for its BLAS).  The cyclic
collector examines young objects often while they are being created and walks all of them at
each full collection, and once more in the interpreter's final collection at exit.

The library leaves the collector alone: a program that imports cmbs keeps its collector as it set
it.  The ``cmbs`` command owns its process, and :func:`settle_the_command_process` (called by
:func:`cmbs.cli.main` as the process's entry point) moves the objects alive after its imports out
of the collector's reach (``gc.freeze``: a permanent generation that no collection walks), does
the same with what numba's target initialisation builds (:func:`long_lived`,
:func:`initialise_numba_target_on_first_use`), and freezes everything at exit, sparing the final
collection its walk.  The cost is the usual one of ``gc.freeze``: a reference cycle among the
frozen objects that becomes garbage is kept until exit, and at exit only finalizers of objects
left in cycles are skipped, which CPython does not promise to run at exit anyway.
"""

from __future__ import annotations

import atexit
import contextlib
import gc
from collections.abc import Iterator

_depth = 0
_was_enabled = True


@contextlib.contextmanager
def long_lived() -> Iterator[None]:
    """Run the block with the cyclic collector paused, then freeze every object alive and
    restore the collector's state.  Blocks may nest: the outermost one freezes and restores.
    The outermost one starts with a full collection (when the collector is enabled), so that
    the freeze keeps no garbage made before the block; it walks only the objects not frozen
    yet (those of the program since its start, or since the last block)."""
    global _depth, _was_enabled
    if _depth == 0:
        _was_enabled = gc.isenabled()
        if _was_enabled:
            gc.collect()            # what is garbage already is freed, not frozen
        gc.disable()
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
        if _depth == 0:
            gc.freeze()
            if _was_enabled:
                gc.enable()


def initialise_numba_target_on_first_use() -> None:
    """Initialise numba's CPU target in a :func:`long_lived` block at the next compiled call
    (numba's ``numba:compiler_lock`` event, raised when a kernel is compiled or loaded from the
    disk cache), before numba would do it on the same call with the collector running.  Only
    the initialisation is in the block: a compilation's own objects are freed as usual.

    Call it once the kernels' modules are imported: creating the first kernel creates the
    target's context, which takes the compiler lock too."""
    from numba.core import event, registry
    from numba.core.compiler_lock import global_compiler_lock

    class FirstCompiledCall(event.Listener):
        done = False

        def on_start(self, event: object) -> None:
            if not self.done:
                self.done = True
                with long_lived(), global_compiler_lock:
                    registry.cpu_target.target_context.refresh()

        def on_end(self, event: object) -> None:
            pass

    event.register("numba:compiler_lock", FirstCompiledCall())


def settle_the_command_process() -> None:
    """For the ``cmbs`` command only, which owns its process: freeze the objects alive now (the
    modules it imported; without a full collection first, which would walk them all once more
    to free the few cycles the imports left), freeze what numba's target initialisation builds
    at the first compiled call, and freeze everything at exit, before the interpreter's final
    collection.  Never called by the library."""
    from cmbs.jit import COMPILED

    gc.freeze()
    if COMPILED:
        initialise_numba_target_on_first_use()
    atexit.register(gc.freeze)
