"""The cyclic collector is paused while long-lived objects are made and they are then frozen
(cmbs.collector); each check runs in a fresh interpreter, whose collector state it changes."""

import subprocess
import sys

import pytest


def run(code: str) -> str:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout


def test_long_lived_pauses_the_collector_and_freezes_what_the_block_made():
    output = run("""
import gc, weakref
from cmbs.collector import long_lived
gc.enable()
gc.set_threshold(10**6)                          # no automatic collection: only the block's frees it
class Node:
    pass
garbage = Node()
garbage.itself = garbage                         # a reference cycle: only the collector frees it
garbage = weakref.ref(garbage)
with long_lived():
    freed_first = garbage() is None              # the freeze does not keep it
    paused = not gc.isenabled()
    made = [[] for _ in range(1000)]
    with long_lived():
        pass
    still_paused = not gc.isenabled()            # an inner block leaves the pause to the outer one
tracked = {id(item) for item in gc.get_objects()}
print(freed_first, paused, still_paused, gc.isenabled(), any(id(item) in tracked for item in made))
gc.disable()
with long_lived():
    pass
print("disabled before, after:", gc.isenabled())
""")
    assert "True True True True False" in output     # garbage freed, paused, restored, the lists frozen
    assert "disabled before, after: False" in output


def test_import_cmbs_runs_its_imports_without_collections_and_freezes_them():
    """Without the pause, importing numpy and numba alone runs about a hundred collections."""
    output = run("""
import gc, sys
during = []
gc.callbacks.append(lambda phase, info: during.append("numpy" in sys.modules) if phase == "start" else None)
import cmbs
tracked = {id(item) for item in gc.get_objects()}
print("collections after numpy", sum(during), "tracked", id(cmbs.simulate) in tracked,
      id(sys.modules["numba"].njit) in tracked, "enabled", gc.isenabled())
""")
    assert "collections after numpy 0 tracked False False enabled True" in output


def test_numba_target_is_initialised_in_a_long_lived_block_at_the_first_compiled_call():
    pytest.importorskip("numba")
    output = run("""
import gc, cmbs.jit
from numba.core.registry import cpu_target
before = gc.get_freeze_count()
model = cmbs.load("four-bar")                    # the first compiled call (cached or compiled)
print("compiled", cmbs.jit.COMPILED, "frozen by it", gc.get_freeze_count() - before, "enabled", gc.isenabled())
""")
    words = output.split()
    if words[1] == "False":
        pytest.skip("numba is disabled")
    assert int(words[5]) > 10000                     # numba's typing and lowering registries
    assert words[7] == "True"
