"""Without numba the same kernels run as plain Python on numpy arrays, with the same results."""

import os
import subprocess
import sys

import numpy as np

import cmbs
import cmbs.jit

SCRIPT = """
import sys
import numpy as np
import cmbs, cmbs.jit
assert not cmbs.jit.COMPILED
np.savez(sys.argv[1], **__import__("test_jit_fallback").results())
"""


def results() -> dict:
    """Runs through every kind of kernel: natural and joint models, the compiled RK4 loop
    (Lagrange, projection), the matrix-R loop, the Python path (rk45; penalty and Udwadia-Kalaba,
    whose solves are compiled kernels), the human's terms, and the batched sweep in lanes."""
    four_bar = cmbs.load("four-bar").without_drivers()
    speeds = [cmbs.velocities(four_bar, four_bar.q0, qd=np.eye(four_bar.n)[-1] * s, fixed=["alpha"])
              for s in (-1.0, 0.5, 2.0)]
    human = cmbs.load("human")
    terms = human.evaluate(human.q0, human.qd0 + 0.1, 0.3, np.linspace(-1.0, 1.0, human.n_u))
    return {
        "lagrange": cmbs.simulate(four_bar, t_end=0.05, integrator="rk4", dt=1e-3, formulation="lagrange").q,
        "projection": cmbs.simulate(four_bar, t_end=0.05, integrator="rk4", dt=1e-3, formulation="projection").q,
        "penalty": cmbs.simulate(four_bar, t_end=0.05, integrator="rk4", dt=1e-3, formulation="penalty").q,
        "udwadia_kalaba": cmbs.simulate(four_bar, t_end=0.05, integrator="rk4", dt=1e-3,
                                        formulation="udwadia-kalaba").q,
        "matrix_r": cmbs.simulate(cmbs.load("slider-crank"), t_end=0.05, integrator="rk4", dt=1e-3,
                                  formulation="matrix-r").q,
        "joint_rk45": cmbs.simulate(cmbs.load("slider-crank-joint", gravity=9.81), t_end=0.05).q,
        "human_Q": terms.Q, "human_A": terms.A, "human_gamma": terms.gamma, "human_M": terms.M,
        "sweep_lanes": cmbs.sweep(four_bar, [cmbs.Variant(qd0=qd) for qd in speeds], t_end=0.02, dt=1e-3).q,
    }


def test_kernels_without_numba_give_the_compiled_results(tmp_path):
    assert cmbs.jit.COMPILED
    path = tmp_path / "python.npz"
    environment = {**os.environ, "CMBS_DISABLE_NUMBA": "1",
                   "PYTHONPATH": os.pathsep.join([os.path.dirname(__file__), os.environ.get("PYTHONPATH", "")])}
    completed = subprocess.run([sys.executable, "-c", SCRIPT, str(path)], env=environment, capture_output=True,
                               text=True, timeout=600)
    assert completed.returncode == 0, completed.stderr
    compiled = results()
    with np.load(path) as interpreted:
        assert set(interpreted.files) == set(compiled)
        for name, value in compiled.items():
            np.testing.assert_allclose(interpreted[name], value, rtol=0, atol=1e-12 * max(1.0, np.abs(value).max()),
                                       err_msg=name)
