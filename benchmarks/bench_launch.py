#!/usr/bin/env python
"""Whole-process wall time: a fresh interpreter imports the tool, builds the thesis four-bar and
simulates 10 s of its free motion at h = 1 ms, then exits (issue target: <= 0.6 s on the second
launch, compiled code cached; the first launch's compile time stated); and the ``cmbs`` command
doing the same run, which, owning its process, keeps the garbage collector from walking the
objects that live as long as the process (``cmbs.collector``).

    python benchmarks/bench_launch.py              # a cold launch, then 5 warm ones of each
    python benchmarks/bench_launch.py --repeat 3 --no-cold

Timed from the parent around ``subprocess.run`` (interpreter start and exit included), beside:
an empty interpreter; the floor any numba program pays (import numpy and numba, initialise
numba's CPU target, which imports scipy.linalg for its BLAS, and exit with the objects frozen out
of the final garbage collection, as the ``cmbs`` command arranges); the same with the garbage
collector paused while numpy and numba are imported and initialised; and MuJoCo
(if installed) on the same four-bar (``bench_dynamics.mujoco_xml``), 10 000 steps of its default
implicitfast integrator.  The programs take turns, one launch of each per round, so that all
see the same machine load.  The launches write and use Python's bytecode cache, as an installed
package does.  The cold launch uses a fresh ``NUMBA_CACHE_DIR``, so it compiles every
kernel the run needs; the warm launches share that directory.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
TARGET_S = 0.6

CMBS_RUN = ("import cmbs; model = cmbs.load('four-bar').without_drivers(); "
            "run = cmbs.simulate(model, t_end=10.0, dt=1e-3, integrator='rk4'); "
            "assert run.info['compiled'] and run.info['status'] == 'success', run.info")
# the console script's call: main() without arguments owns its process (cmbs.collector)
CMBS_COMMAND = ("import sys; from cmbs.cli import main; sys.argv[1:] = ['simulate', 'four-bar', '--undriven', "
                "'--t-end', '10', '--dt', '0.001', '--integrator', 'rk4']; sys.exit(main())")
NUMBA_FLOOR = ("import atexit, gc, numpy, numba; from numba.core.registry import cpu_target; "
               "cpu_target.target_context.refresh(); atexit.register(gc.freeze)")
NUMBA_FLOOR_PAUSED = ("import atexit, gc; gc.disable(); import numpy, numba; "
                      "from numba.core.registry import cpu_target; cpu_target.target_context.refresh(); "
                      "gc.freeze(); gc.enable(); atexit.register(gc.freeze)")
MUJOCO_RUN = ("import sys, mujoco, numpy; xml, q0, v0 = open(sys.argv[1]).read().split('\\n'); "
              "model = mujoco.MjModel.from_xml_string(xml); data = mujoco.MjData(model); "
              "data.qpos[:] = [float(x) for x in q0.split()]; data.qvel[:] = [float(x) for x in v0.split()]\n"
              "for _ in range(10000): mujoco.mj_step(model, data)")


def launch(code: str, environment: dict, *arguments: str) -> float:
    """Wall seconds of a fresh ``python -c code``."""
    started = time.perf_counter()
    subprocess.run([sys.executable, "-c", code, *arguments], env=environment, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - started


def interleaved(programs: dict[str, tuple], environment: dict, repeat: int) -> dict[str, list[float]]:
    """Wall seconds of ``repeat`` launches of each program (name: (code, *arguments)), taking turns."""
    times: dict[str, list[float]] = {name: [] for name in programs}
    for _ in range(repeat):
        for name, (code, *arguments) in programs.items():
            times[name].append(launch(code, environment, *arguments))
    return times


def describe(times: list[float]) -> str:
    return f"{statistics.median(times):.3f} s [{min(times):.3f}-{max(times):.3f}]"


def mujoco_file(directory: str) -> str | None:
    """The four-bar's MJCF and start state in a file for the MuJoCo child, or None."""
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return None
    sys.path.insert(0, HERE)
    import cmbs
    from bench_dynamics import library_four_bar_tree, mujoco_build, mujoco_xml

    tree = library_four_bar_tree(cmbs.load("four-bar"))
    _, _, q0, v0, _ = mujoco_build(tree)
    path = os.path.join(directory, "four-bar.mjcf")
    with open(path, "w") as file:
        state = [" ".join(repr(float(x)) for x in values) for values in (q0, v0)]
        file.write("\n".join([mujoco_xml(tree), *state]))
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=5, help="warm launches of each (default 5)")
    parser.add_argument("--no-cold", action="store_true", help="skip the cold launch; use the usual numba cache")
    args = parser.parse_args()
    environment = dict(os.environ)
    # Python's bytecode cache, as an installed package has it (pip compiles it at install; a
    # checkout writes it at its first import).  With PYTHONDONTWRITEBYTECODE set, every launch
    # would compile cmbs's source again (about 0.05 s).
    if environment.pop("PYTHONDONTWRITEBYTECODE", None):
        print("PYTHONDONTWRITEBYTECODE is unset for the launches: they use Python's bytecode cache")
    with tempfile.TemporaryDirectory() as directory:
        if not args.no_cold:
            environment["NUMBA_CACHE_DIR"] = os.path.join(directory, "numba")
            print(f"cmbs first launch, cold numba cache (compiles): {launch(CMBS_RUN, environment):.1f} s")
        model_file = mujoco_file(directory)
        programs = {"empty": ("pass",), "floor": (NUMBA_FLOOR,), "paused": (NUMBA_FLOOR_PAUSED,),
                    "cmbs": (CMBS_RUN,), "command": (CMBS_COMMAND,)}
        if model_file:
            programs["mujoco"] = (MUJOCO_RUN, model_file)
        times = interleaved(programs, environment, args.repeat)
    cmbs_median = statistics.median(times["cmbs"])
    mujoco_times = times.get("mujoco")
    print(f"empty interpreter:                          {describe(times['empty'])}")
    print(f"numpy + numba imported and initialised:     {describe(times['floor'])} (the floor of any numba program)")
    print(f"  the same, garbage collector paused:       {describe(times['paused'])}")
    print(f"cmbs, import + four-bar + 10 s RK4 (warm):  {describe(times['cmbs'])}; target {TARGET_S} s, ratio "
          f"{cmbs_median / TARGET_S:.2f} -> {'PASS' if cmbs_median <= TARGET_S else 'MISS'}")
    print(f"the cmbs command, the same run (warm):      {describe(times['command'])} (its collector settled, "
          f"cmbs.collector)")
    if mujoco_times:
        print(f"MuJoCo, import + four-bar + 10 000 steps:   {describe(mujoco_times)}; cmbs / MuJoCo = "
              f"{cmbs_median / statistics.median(mujoco_times):.2f}")
    else:
        print("MuJoCo: not installed (pip install '.[bench]')")


if __name__ == "__main__":
    main()
