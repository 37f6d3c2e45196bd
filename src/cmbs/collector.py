"""Python's cyclic garbage collector and the objects that live as long as the process.

A compiled run starts by creating some 10⁵ objects that are never freed: the modules of numpy,
numba and cmbs, and numba's typing and lowering registries, which numba builds when its CPU
target initialises (at the first compiled call, loading scipy.linalg for its BLAS).  The cyclic
collector examines young objects often while they are being created and walks all of them at
each full collection: in a whole launch (import, the four-bar, 10 s of RK4) about 60 ms went to
collections that found nothing to free, a tenth of the process.

:func:`long_lived` pauses the collector while a block creates such objects and then moves
everything alive out of its reach (``gc.freeze``: a permanent generation that no collection
walks); ``import cmbs`` runs in one, and so does numba's target initialisation
(:func:`initialise_numba_target_on_first_use`).  The cost is the usual one
of ``gc.freeze``: a reference cycle among the frozen objects that becomes garbage is kept until
exit.  :func:`freeze_at_exit` spares the interpreter's final collection the same walk (about
0.2 s); memory is returned to the system at exit as always, and only finalizers of objects left
in cycles are skipped there, which CPython does not promise to run at exit anyway.
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


def freeze_at_exit() -> None:
    """Freeze every object when the interpreter exits, before its final collection."""
    atexit.register(gc.freeze)


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
