#!/usr/bin/env python
"""Peak resident memory of the same simulation in cmbs, MuJoCo, Pinocchio and Exudyn.

    python benchmarks/bench_memory.py [--quick] [--json FILE]

Mechanisms: those of bench_dynamics.py that the other tools get through its ``Tree``
description: the anchors' four-bar, the library four-bar, the slider-crank (natural
coordinates; crank 45° at 2 rad/s, through its singular positions), the 14-link tip-pinned chain
and the human model (hip free, falling under gravity).  Each (mechanism, tool) runs in a FRESH
child process (``python bench_memory.py --child ...``) that first imports the same modules as
every other child: bench_dynamics (hence cmbs, numpy, numba, scipy) and every installed tool
(mujoco, pinocchio, exudyn); it then builds the mechanism and simulates 10 s of its motion
(``--quick``: 1 s) at h = 1 ms, checks that the run reached the end with a finite state, and
prints its VmHWM (peak resident set, /proc/self/status; getrusage's maxrss would keep the forking
parent's high-water mark across exec):

* cmbs: the model bench_dynamics loads (``CASES[...].load()``), ``cmbs.simulate(model, t_end=...,
  dt=1e-3, integrator="rk4", formulation="baumgarte")`` (compiled RK4 loop, its recording of the
  trajectory included).  The slider-crank alone uses ``formulation="matrix-r"``: Baumgarte (like
  Lagrange) stops at its first singular position (t = 0.83 s, rank-deficient constraint
  Jacobian), and matrix R is the formulation of bench_dynamics's target run through them;
* MuJoCo: ``bench_dynamics.mujoco_build`` (hinges, connect equalities, no contacts) and
  ``mj_step`` with the integrator of that model, implicitfast, the one bench_dynamics names
  recommended (its RK4 gave the same peak within 0.1 MB on the 14-link chain, 2026-11-25: both
  work in the preallocated mjData arena);
* Pinocchio: ``bench_dynamics.pinocchio_build`` (revolute joints, 3-D point contacts;
  ``constraintDynamics``, or ``aba`` for the human) and the Python-loop RK4 of
  ``bench_dynamics.pinocchio_measure``, written out again below (it is local to that function);
* Exudyn: ``bench_dynamics.exudyn_measure`` with one run (redundant 2-D rigid bodies, its
  recommended generalized-alpha solver, no solution file).

The tools' children get the ``Tree`` from the parent (pickled once, built from the cmbs model
there), so that they do not load a cmbs model (and its compiled kernels) themselves.  A
baseline child does the same imports, loads the same pickle and builds nothing; "added" is the
child's VmHWM minus the baseline's: what the tool's model and run add to the peak.  A transient
peak of the imports (freed before the run) would hide that much of a run's memory, so "added" is
a lower bound of the memory the run holds.  Every child is launched twice and the second launch
is kept: numba's disk cache is then warm (a first compile of cmbs's loop takes GBs).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import importlib  # noqa: E402
import json  # noqa: E402
import pickle  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from typing import Callable  # noqa: E402

import numpy as np  # noqa: E402

import cmbs  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_dynamics as bd  # noqa: E402
from bench_model import environment  # noqa: E402
from reporting import write_report  # noqa: E402

MECHANISMS = ("four-bar", "four-bar-library", "slider-crank", "chain14-closed", "human")
FORMULATION = {"slider-crank": "matrix-r"}   # cmbs; "baumgarte" for the others (see the docstring)
SPAN, QUICK_SPAN = 10.0, 1.0


def steps(span: float) -> int:
    return int(round(span / bd.STEP))


def run_cmbs(label: str, tree: bd.Tree, span: float) -> str:
    """The cmbs model of bench_dynamics, RK4 at h = 1 ms; returns how it ran."""
    formulation = FORMULATION.get(label, "baumgarte")
    model = next(case for case in bd.CASES if case.label == label).load()
    run = cmbs.simulate(model, t_end=span, dt=bd.STEP, integrator="rk4", formulation=formulation)
    assert run.info["status"] == "success" and abs(run.t[-1] - span) < 1e-9, run.info.get("message")
    return f"RK4, {formulation}" + (", compiled" if run.info.get("compiled") else ", Python path")


def run_mujoco(label: str, tree: bd.Tree, span: float) -> str:
    import mujoco

    model, data, q0, v0, _ = bd.mujoco_build(tree)
    data.qpos[:], data.qvel[:] = q0, v0
    for _ in range(steps(span)):
        mujoco.mj_step(model, data)
    assert np.all(np.isfinite(data.qpos)), "non-finite state"
    return mujoco.mjtIntegrator(model.opt.integrator).name.removeprefix("mjINT_").lower()


def run_pinocchio(label: str, tree: bd.Tree, span: float) -> str:
    name, _, rhs, y, *_ = bd.pinocchio_build(tree)
    h = bd.STEP
    for _ in range(steps(span)):          # the RK4 loop of bench_dynamics.pinocchio_measure
        k1 = rhs(y)
        k2 = rhs(y + 0.5 * h * k1)
        k3 = rhs(y + 0.5 * h * k2)
        k4 = rhs(y + h * k3)
        y = y + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    assert np.all(np.isfinite(y)), "non-finite state"
    return f"RK4 Python loop, {name}"


def run_exudyn(label: str, tree: bd.Tree, span: float) -> str:
    (how, run), = bd.exudyn_measure(tree, span, 1)["runs"].items()
    assert "error" not in run, run.get("error")
    assert abs(run["t_end"] - span) < 1e-6, run["t_end"]
    return how.split(",")[0]


RUNS: dict[str, Callable[[str, bd.Tree, float], str]] = {
    "cmbs": run_cmbs, "MuJoCo": run_mujoco, "Pinocchio": run_pinocchio, "Exudyn": run_exudyn}


def child(tool: str, label: str, span: float, trees: str, modules: list[str]) -> None:
    """The child: import the installed tools, load the trees, run one (mechanism, tool) unless
    ``tool`` is "baseline", print VmHWM and VmRSS [kB] and how it ran as JSON."""
    for module in modules:
        importlib.import_module(module)
    with open(trees, "rb") as stream:
        tree = pickle.load(stream)[label]
    how = "" if tool == "baseline" else RUNS[tool](label, tree, span)
    with open("/proc/self/status") as status:
        figures = {line.split(":")[0]: int(line.split()[1]) for line in status if line.startswith(("VmHWM", "VmRSS"))}
    print(json.dumps({"how": how, **figures}))


def launch(tool: str, label: str, span: float, trees: str, modules: list[str]) -> dict:
    """Peak memory [MB] of the child, second of two launches; or the error of a failed one."""
    command = [sys.executable, os.path.abspath(__file__), "--child", tool, label, repr(span), trees, *modules]
    for _ in range(2):                     # the second launch: numba's cache is warm
        started = time.perf_counter()
        result = subprocess.run(command, capture_output=True, text=True)
        wall = time.perf_counter() - started
        if result.returncode != 0:
            return {"error": result.stderr.strip()[-800:] or f"exit status {result.returncode}"}
    figures = json.loads(result.stdout.strip().splitlines()[-1])
    return {"how": figures["how"], "peak_mb": figures["VmHWM"] / 1024.0, "rss_end_mb": figures["VmRSS"] / 1024.0,
            "wall_s": wall}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help=f"simulate {QUICK_SPAN:g} s instead of {SPAN:g} s")
    parser.add_argument("--json", help="write every figure to this file")
    parser.add_argument("--child", nargs="+", help=argparse.SUPPRESS)  # internal: tool label span trees modules...
    args = parser.parse_args()
    if args.child:
        tool, label, span, trees, *modules = args.child
        child(tool, label, float(span), trees, modules)
        return 0
    started = time.perf_counter()
    span = QUICK_SPAN if args.quick else SPAN
    modules = {name: module for name, (module, _) in bd.TOOLS.items() if bd.installed(module)}
    versions = {name: sys.modules[module].__version__ if name in modules else None
                for name, (module, _) in bd.TOOLS.items()}
    print(f"cmbs {cmbs.__version__}; " + ", ".join(f"{name} {version or 'not installed (skipped)'}"
                                                  for name, version in versions.items()))
    print(f"{span:g} s of motion at h = {bd.STEP * 1e3:g} ms; every child imports bench_dynamics (cmbs, numpy, "
          f"numba, scipy) and {', '.join(modules.values()) or 'no other tool'}; second of two launches")
    report: dict = {"environment": environment(), "span_s": span, "step_s": bd.STEP, "tools": versions,
                    "imports": ["bench_dynamics", *modules.values()], "rows": []}
    with tempfile.TemporaryDirectory() as directory:
        trees = os.path.join(directory, "trees.pickle")
        with open(trees, "wb") as stream:
            pickle.dump({case.label: case.tree(case.load()) for case in bd.CASES if case.label in MECHANISMS}, stream)
        baseline = report["baseline"] = launch("baseline", MECHANISMS[0], span, trees, list(modules.values()))
        if "error" in baseline:
            print(f"baseline child failed:\n{baseline['error']}", file=sys.stderr)
            return 1
        base = baseline["peak_mb"]
        print(f"baseline child (the imports, nothing built): VmHWM {base:.1f} MB\n")
        print(f"  {'mechanism':<17} {'tool':<10} {'run':<38} {'peak MB':>8} {'baseline':>8} {'added MB':>8} "
              f"{'cmbs/tool':>9}")
        for label in MECHANISMS:
            ours = None
            for tool in ["cmbs", *modules]:
                row = {"mechanism": label, "tool": tool, "baseline_mb": base,
                       **launch(tool, label, span, trees, list(modules.values()))}
                report["rows"].append(row)
                if "error" in row:
                    print(f"  {label:<17} {tool:<10} FAILED; stderr ends:\n" + "\n".join(
                        "      " + line for line in row["error"].splitlines()[-8:]))
                    continue
                row["added_mb"] = row["peak_mb"] - base
                if tool == "cmbs":
                    ours = row["added_mb"]
                elif ours is not None and row["added_mb"] > 0:
                    row["cmbs_over_tool"] = ours / row["added_mb"]
                ratio = f"{row['cmbs_over_tool']:.2f}" if "cmbs_over_tool" in row else "-"
                print(f"  {label:<17} {tool:<10} {row['how']:<38} {row['peak_mb']:>8.1f} {base:>8.1f} "
                      f"{row['added_mb']:>8.1f} {ratio:>9}")
    report["elapsed_s"] = time.perf_counter() - started
    print(f"\nadded = child's VmHWM - baseline's; cmbs/tool = cmbs's added / the tool's added (same mechanism); "
          f"elapsed {report['elapsed_s']:.0f} s")
    write_report(args.json, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
