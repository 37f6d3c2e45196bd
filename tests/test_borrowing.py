"""The compiled paths free every array they allocate, and the fixed-step loops allocate none
per step.

The hot kernels work by design on arrays their caller allocated once per run, which the loops
borrow (:func:`cmbs.jit.borrow`).  A kernel that kept an array or a view it does not own would leak it;
numba's allocation statistics catch that: after each path has run once (compiling and warming
its caches), running it again and dropping the results must leave as many frees as allocations,
for the data and for their owners (meminfos).  A fixed-step loop that allocated a work array per
step or per stage would allocate more in a run twice as long: the four-bar's RK4 run allocates
the same in 50 and in 100 steps.  The statistics are switched on at interpreter start (NUMBA_NRT_STATS),
so the paths run in a subprocess.  The paths that must create arrays in compiled code (the SVD,
numba's lstsq, the adaptive loop, the sweep) are checked to have allocated, so the statistics were on.
"""

import json
import os
import subprocess
import sys
import textwrap

import pytest

from cmbs import jit

SCRIPT = textwrap.dedent("""
    import gc
    import json

    import numpy as np
    from numba.core.runtime import rtsys

    import cmbs
    from cmbs.control import ComputedTorque, Reference
    from cmbs.dynamics.field import CompiledDynamics

    four_bar = cmbs.load("four-bar").without_drivers()
    slider = cmbs.load("slider-crank")
    driven = cmbs.load("four-bar")
    motion = cmbs.kinematic_analysis(driven, np.linspace(0.0, 0.2, 201))
    law = ComputedTorque(four_bar, Reference(motion, ("alpha",)), kp=100.0, kd=20.0)
    joint = cmbs.load("slider-crank-joint", gravity=9.81)
    singular = slider.q0.copy()
    singular[slider.coordinate_index("theta1")] = np.pi / 2        # crank and rod upright: rank 4
    singular = cmbs.assemble(slider, singular, fixed=["theta1"])

    def paths():
        yield "rk4 lagrange", lambda: cmbs.simulate(four_bar, t_end=0.05, integrator="rk4", dt=1e-3)
        yield "rk4 lagrange, twice as long", lambda: cmbs.simulate(four_bar, t_end=0.1, integrator="rk4", dt=1e-3)
        yield "rk4 baumgarte, joint", lambda: cmbs.simulate(joint, t_end=0.05, integrator="rk4", dt=1e-3,
                                                            formulation="baumgarte")
        yield "rk4 projection through the singular position (SVD)", lambda: cmbs.simulate(
            slider, t_end=1.0, integrator="rk4", dt=1e-3, formulation="projection")
        yield "rk4 lagrange stopped at the singular position", lambda: cmbs.simulate(
            slider, t_end=1.0, integrator="rk4", dt=1e-3)
        yield "rk4 lagrange, least squares (lstsq)", lambda: cmbs.simulate(
            four_bar, t_end=0.05, integrator="rk4", dt=1e-3, formulation_options={"least_squares": True})
        yield "rk4 computed torque", lambda: cmbs.simulate(four_bar, t_end=0.05, integrator="rk4", dt=1e-3, u=law)
        yield "dop853", lambda: cmbs.simulate(four_bar, t_end=0.05, integrator="dop853")
        yield "matrix R", lambda: cmbs.simulate(four_bar, t_end=0.05, integrator="rk4", dt=1e-3,
                                                formulation="matrix-r")
        yield "rk4 drift projection", lambda: cmbs.simulate(four_bar, t_end=0.05, integrator="rk4", dt=1e-3,
                                                            project=True)
        yield "rk45 drift projection", lambda: cmbs.simulate(four_bar, t_end=0.05, formulation="projection",
                                                             project=True)
        yield "batched sweep", lambda: cmbs.sweep(four_bar, [cmbs.Variant(), cmbs.Variant()], t_end=0.05,
                                                  dt=1e-3)
        yield "batched adaptive sweep", lambda: cmbs.sweep(four_bar, [cmbs.Variant(), cmbs.Variant()], t_end=0.05,
                                                           dt=1e-3, integrator="rk45")
        compiled = CompiledDynamics(slider, "projection")      # its SVD at the singular position
        yield "CompiledDynamics", lambda: compiled.accelerations(singular, np.zeros(slider.n), 0.0)

    unbalanced, allocations = {}, {}
    for name, run in paths():
        result = run()
        if isinstance(result, cmbs.SweepResult):
            assert result.info["mode"] == "batched", name
        elif hasattr(result, "info"):
            assert result.info.get("compiled"), name
        del result
        gc.collect()
        before = rtsys.get_allocation_stats()
        result = run()
        del result
        gc.collect()
        after = rtsys.get_allocation_stats()
        allocated, freed = after.alloc - before.alloc, after.free - before.free
        owners, owners_freed = after.mi_alloc - before.mi_alloc, after.mi_free - before.mi_free
        if allocated != freed or owners != owners_freed:
            unbalanced[name] = [allocated, freed, owners, owners_freed]
        allocations[name] = [allocated, owners]
    print(json.dumps(allocations))
    print(json.dumps(unbalanced))
""")


@pytest.mark.skipif(not jit.COMPILED, reason="numba's statistics: numba is not installed")
def test_compiled_paths_free_every_array_they_allocate_and_fixed_step_loops_allocate_none_per_step():
    environment = {**os.environ, "NUMBA_NRT_STATS": "1", "OPENBLAS_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, env=environment,
                          timeout=1500)
    assert done.returncode == 0, done.stderr[-3000:]
    allocations, unbalanced = (json.loads(line) for line in done.stdout.strip().splitlines()[-2:])
    assert unbalanced == {}, done.stdout
    # the statistics are on: the paths that create arrays in compiled code did allocate (the SVD,
    # the adaptive loop's records, the sweep's per-variant workspace)
    for name in ("rk4 projection through the singular position (SVD)", "rk4 lagrange, least squares (lstsq)",
                 "dop853", "rk4 drift projection", "rk45 drift projection", "matrix R", "batched sweep",
                 "batched adaptive sweep", "CompiledDynamics"):
        assert allocations[name][0] > 0, (name, allocations)
    # the RK4 loop's work arrays are allocated once per run, none per step (the joint model's
    # runs allocate per record outside the loop: its energy kernel's work array)
    assert allocations["rk4 lagrange, twice as long"] == allocations["rk4 lagrange"], allocations
