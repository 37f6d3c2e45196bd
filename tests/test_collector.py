"""The library leaves the host's garbage collector, modules and thread settings as they were; the
``cmbs`` command, which owns its process, freezes the objects that live as long as it
(cmbs.collector).  Each check runs in a fresh interpreter, whose state it inspects or changes."""

import subprocess
import sys

import pytest

from cmbs import jit


def run(code: str, *arguments: str) -> str:
    return subprocess.run([sys.executable, "-c", code, *arguments], capture_output=True, text=True,
                          check=True).stdout


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


HOST = """
import atexit, gc, sys
enabled = sys.argv[1] == "enabled"
gc.set_threshold(1234, 7, 9)
if not enabled:
    gc.disable()
def collector():
    return [gc.isenabled(), list(gc.get_threshold()), gc.get_freeze_count()]
# atexit runs last-in first-out: this runs after every exit handler cmbs registers
atexit.register(lambda: print("at exit", collector()))
print("before", collector())
import importlib.util
import numpy as np
def lazy_modules_of_other_packages():   # LazyLoader's modules are _LazyModule until first used
    return sorted(name for name, module in sys.modules.items()
                  if not name.startswith("cmbs") and type(module) is importlib.util._LazyModule)
import cmbs
print("imported", collector())
print("lazy modules of other packages after import", lazy_modules_of_other_packages())
model = cmbs.load("four-bar").without_drivers()
run = cmbs.simulate(model, t_end=0.05, dt=1e-3, integrator="rk4")
spline = cmbs.SampledInput(np.linspace(0.0, 1.0, 5), np.zeros((5, 1)))(0.5)
print("compiled", run.info["compiled"], run.info["status"])
print("after runs", collector())
print("lazy modules of other packages after runs", lazy_modules_of_other_packages())
import scipy, scipy.linalg, scipy.interpolate
print("bindings", scipy.linalg is sys.modules["scipy.linalg"], scipy.interpolate is sys.modules["scipy.interpolate"],
      type(scipy.linalg) is type(sys), type(scipy.interpolate) is type(sys))
"""


def after(prefix: str, output: str) -> str:
    """The rest of the output line that starts with ``prefix``."""
    return next(line[len(prefix):].strip() for line in output.splitlines() if line.startswith(prefix))


@pytest.mark.parametrize("state", ["enabled", "disabled"])
def test_import_cmbs_and_its_runs_leave_the_collector_and_other_packages_modules_as_they_were(state):
    output = run(HOST, state)
    before = f"[{state == 'enabled'}, [1234, 7, 9], 0]"
    assert after("before", output) == before
    assert after("imported", output) == before
    assert after("compiled", output) == f"{jit.COMPILED} success"
    assert after("after runs", output) == before
    assert after("at exit", output) == before             # no exit handler of cmbs froze the objects
    assert after("lazy modules of other packages after import", output) == "[]"
    assert after("lazy modules of other packages after runs", output) == "[]"
    assert after("bindings", output) == "True True True True"


@pytest.mark.skipif(not jit.COMPILED, reason="numba's thread setting: numba is not installed")
def test_import_cmbs_and_a_compiled_run_leave_the_thread_settings_as_they_were():
    pytest.importorskip("threadpoolctl")
    output = run("""
import numba
from threadpoolctl import threadpool_info
def settings():
    return numba.get_num_threads(), sorted((pool["internal_api"], pool["num_threads"]) for pool in threadpool_info())
import numpy, scipy.linalg
before = settings()
import cmbs
run = cmbs.simulate(cmbs.load("four-bar").without_drivers(), t_end=0.05, dt=1e-3, integrator="rk4")
print(before == settings(), before, settings())
""")
    assert output.startswith("True"), output


@pytest.mark.skipif(not jit.COMPILED, reason="numba is not installed")
def test_the_command_freezes_its_long_lived_objects_and_main_called_by_a_program_does_not():
    """``main()`` is the process's entry point: it freezes the modules it imported, numba's
    registries at the first compiled call (some 10⁵ objects) and everything at exit; ``main(argv)``
    from a program leaves that program's collector alone."""
    probe = """
import atexit, gc, sys
atexit.register(lambda: print("at exit frozen", gc.get_freeze_count() > 0))
from cmbs.cli import main
command = ["simulate", "four-bar", "--undriven", "--t-end", "0.05", "--integrator", "rk4", "--dt", "0.001"]
if sys.argv[1] == "entry":
    sys.argv[1:] = command
    status = main()
else:
    status = main(command)
print("status", status, gc.get_freeze_count(), gc.isenabled())
"""
    entry, called = run(probe, "entry"), run(probe, "called")
    status, frozen, enabled = after("status", entry).split()
    assert (status, enabled) == ("0", "True") and int(frozen) > 100000, entry
    assert after("at exit frozen", entry) == "True"
    assert after("status", called) == "0 0 True"
    assert after("at exit frozen", called) == "False"
