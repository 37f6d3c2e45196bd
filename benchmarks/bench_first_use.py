"""First use: the CPU time of a command on an empty numba cache, most of it compiling kernels.

Each command runs in a new process with ``NUMBA_CACHE_DIR`` set to an empty folder of its own
(the commands of one case share it, in order: a sweep after the single run it repeats shows what
the sweep compiles beyond it).  Given ``--before TREE`` (a checkout of another commit), each
case runs on that tree's ``src`` and on this one in turn, and the ratio after / before is printed.

    python benchmarks/bench_first_use.py [--quick] [--before /path/to/other/checkout]

CPU time of the child processes (user + system, ``resource.RUSAGE_CHILDREN``): on a shared
machine it varies less than the wall time.  About 8 minutes (``--quick``: the first three cases).
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
PYTHON_EXAMPLE = """
import numpy as np
import cmbs
model = cmbs.load("four-bar")
motion = cmbs.kinematic_analysis(model, np.linspace(0, 4, 401))
run = cmbs.simulate(model.without_drivers(), t_end=10, formulation="projection", integrator="rk45", rtol=1e-9,
                    project=True)
print(run.info["status"])
"""

#: The targets (issue "One engine"): seconds of a first run on an empty cache.
SIMULATE_TARGET, EXAMPLE_TARGET = 20.0, 40.0

#: (label, commands): each command a ``cmbs`` argument list, or ["python", source].
CASES = [
    ("the README's first command (four-bar, projection, RK45, drift projection)",
     [["simulate", "four-bar", "--undriven", "--t-end", "10", "--formulation", "projection", "--rtol", "1e-9",
       "--project"]]),
    ("four-bar --t-end 1 (Lagrange, RK45)", [["simulate", "four-bar", "--t-end", "1"]]),
    ("slider-crank at its dead centre (Lagrange cannot start)",
     [["simulate", "slider-crank", "--t-end", "0.1", "--param", "crank_angle=90"]]),
    ("double-pendulum, Baumgarte, RK45", [["simulate", "double-pendulum", "--formulation", "baumgarte", "--t-end", "10"]]),
    ("four-bar, Udwadia-Kalaba, DOP853",
     [["simulate", "four-bar", "--undriven", "--formulation", "udwadia-kalaba", "--integrator", "dop853", "--t-end",
       "5"]]),
    ("four-bar, generalized-alpha", [["simulate", "four-bar", "--undriven", "--integrator", "generalized-alpha", "--dt",
                                      "1e-3", "--t-end", "1"]]),
    ("slider-crank-joint RK4, then a sweep of 4 start speeds (the sweep's share)",
     [["simulate", "slider-crank-joint", "--integrator", "rk4", "--t-end", "1", "--dt", "1e-3"],
      ["sweep", "slider-crank-joint", "--speed", "theta1=1,2,3,4", "--integrator", "rk4", "--t-end", "1", "--dt",
       "1e-3"]]),
    ("the README's first Python example", [["python", PYTHON_EXAMPLE]]),
]


def cpu_seconds(arguments: list[str], environment: dict[str, str]) -> float:
    """CPU time of one child process running ``arguments`` (it must succeed or fail as a run: exit 0 or 1)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    command = [sys.executable, "-c", arguments[1]] if arguments[0] == "python" else \
        [sys.executable, "-c", "import sys; from cmbs.cli import main; sys.exit(main(sys.argv[1:]))", *arguments]
    done = subprocess.run(command, env=environment, capture_output=True, text=True)
    if done.returncode not in (0, 1):
        raise SystemExit(f"{' '.join(arguments[:3])} ... exited {done.returncode}:\n{done.stderr[-2000:]}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def run_case(commands: list[list[str]], source: Path) -> list[float]:
    """CPU seconds of each command of a case, on an empty cache shared by the case's commands."""
    with tempfile.TemporaryDirectory() as cache:
        environment = {**os.environ, "NUMBA_CACHE_DIR": cache, "PYTHONPATH": str(source),
                       "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
        return [cpu_seconds(command, environment) for command in commands]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the first three cases only")
    parser.add_argument("--before", type=Path, help="another checkout to compare with (its src is used)")
    options = parser.parse_args()
    trees = [("after", HERE.parent / "src")]
    if options.before:
        trees.insert(0, ("before", options.before.resolve() / "src"))
    print("| case | " + " | ".join(label for label, _ in trees) + (" | after / before |" if options.before else " |"))
    print("|---" * (len(trees) + 1 + bool(options.before)) + "|")
    simulations, example = [], None
    for label, commands in CASES[:3] if options.quick else CASES:
        seconds = [run_case(commands, source) for _, source in trees]
        cells = [" + ".join(f"{value:.1f} s" for value in each) for each in seconds]
        ratio = f" {sum(seconds[1]) / sum(seconds[0]):.2f} |" if options.before else ""
        print(f"| {label} | " + " | ".join(cells) + " |" + ratio, flush=True)
        if commands[0][0] == "simulate":
            simulations.append(seconds[-1][0])
        else:
            example = seconds[-1][0]
    print(f"\ntarget: a first `cmbs simulate` <= {SIMULATE_TARGET:g} s: {verdict(max(simulations), SIMULATE_TARGET)} "
          f"(the largest of {len(simulations)}, {max(simulations):.1f} s)")
    if example is not None:
        print(f"target: the README's Python example <= {EXAMPLE_TARGET:g} s: {verdict(example, EXAMPLE_TARGET)} "
              f"({example:.1f} s)")


def verdict(seconds: float, target: float) -> str:
    """PASS or MISS with the ratio to the target."""
    return f"{'PASS' if seconds <= target else 'MISS'} ({seconds / target:.2f})"


if __name__ == "__main__":
    main()
