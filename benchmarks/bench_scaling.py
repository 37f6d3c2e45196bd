#!/usr/bin/env python
"""Cost of one forward-dynamics evaluation against the number of links, beside Pinocchio and
MuJoCo (issue targets: <= 1.0x Pinocchio on the 14- and 50-link chains; growth no faster than
about N^1.2 from 14 to 200 links).

    python benchmarks/bench_scaling.py [--quick] [--json FILE] [--plot FILE.png]

Mechanisms: ``cmbs.load("chain", links=N, closed=...)`` for N = 3, 14, 50, 200, open (hanging
from P0) and tip-pinned (closed): uniform 0.3 m, 1 kg rods on a half circle
(the benchmark chain), gravity 9.81.  The other tools get the same chain through the tree builders of
bench_dynamics.py (joint angles; the pin as a 3-D point contact).

One evaluation: the model's terms and the solve for q̈ (and λ).  cmbs: ``CompiledDynamics
(model, "lagrange").into`` — one compiled call from Python, no allocation; Pinocchio:
``aba`` (open) or ``constraintDynamics`` (pinned), one C++ call from Python; MuJoCo:
``mj_forward`` (everything, no contacts).  Medians of timeit batches (bench_model.time_call).
Also, through ``cmbs.simulate`` (compiled loops) over 10 s (1 s for N = 200; --quick: 1 s and
0.1 s), Baumgarte (ξ = 1, ω = 10): RK4 at h = 1 ms and RK45 at rtol = atol = 1e-8, wall, max |Φ|
and the relative energy error at the end; and the peak resident memory of a fresh process that
runs the RK4 case (its second launch, with numba's cache warm).  The exponent is the
least-squares slope of log(µs) on log(N) from 14 to 200.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import math  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import cmbs  # noqa: E402
from cmbs.dynamics.field import CompiledDynamics  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_dynamics import GRAVITY, installed, mujoco_measure, pinocchio_measure, rod, tree_from  # noqa: E402
from reporting import write_report  # noqa: E402
from bench_model import time_call  # noqa: E402

SIZES = (3, 14, 50, 200)
TARGET_EXPONENT = 1.2


def chain_tree(model: cmbs.Model, links: int, closed: bool):
    return tree_from(model, [rod(f"link{k}", None if k == 1 else f"link{k - 1}", f"P{k - 1}", f"P{k}", 0.3, 1.0)
                             for k in range(1, links + 1)],
                     closures=[(f"link{links}", f"P{links}")] if closed else [])


def peak_memory(links: int, closed: bool, span: float) -> float:
    """Peak resident memory [MB] of a fresh process that imports cmbs, builds the chain and runs
    ``span`` s of RK4 at 1 ms: the child's VmHWM (Linux; getrusage's maxrss would keep the
    forking parent's high-water mark across exec)."""
    code = ("import cmbs; "
            f"m = cmbs.load('chain', links={links}, closed={closed}); "
            f"cmbs.simulate(m, t_end={span}, integrator='rk4', dt=1e-3, formulation='baumgarte'); "
            "print([line.split()[1] for line in open('/proc/self/status') if line.startswith('VmHWM')][0])")
    peaks = []
    for _ in range(2):                      # the second launch: numba's cache is warm (a compile takes GBs)
        output = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
        peaks.append(int(output.split()[-1]) / 1024.0)
    return peaks[-1]


def exponent(sizes: list[int], micros: list[float]) -> float:
    """Slope of log(µs) against log(N) over the sizes from 14 on."""
    points = [(math.log(n), math.log(us)) for n, us in zip(sizes, micros) if n >= 14 and us]
    x, y = np.array(points).T
    return float(np.polyfit(x, y, 1)[0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="shorter timing batches")
    parser.add_argument("--json", help="write every figure to this file")
    parser.add_argument("--plot", help="figure of µs per evaluation against N (log axes)")
    args = parser.parse_args()
    batches, target = (3, 0.05) if args.quick else (7, 0.2)
    tools = {"Pinocchio": installed("pinocchio"), "MuJoCo": installed("mujoco")}
    print(f"cmbs {cmbs.__version__}; tools: " + ", ".join(f"{k} {'yes' if v else 'not installed'}"
                                                         for k, v in tools.items()))
    report: dict = {"sizes": list(SIZES), "chains": {}}
    for closed in (False, True):
        label = "pinned" if closed else "open"
        rows = report["chains"][label] = []
        print(f"\n== {label} chains (gravity {GRAVITY}); µs per evaluation, median [min-max]")
        print(f"  {'N':>4} {'n':>4} {'m':>4}  {'cmbs compiled':>16}  {'Pinocchio':>16}  {'MuJoCo':>16}  "
              f"{'cmbs/Pin':>8}  {'cmbs/MuJoCo':>11}  {'RK4 loop µs/eval':>16}")
        for links in SIZES:
            if closed and links < 3:
                continue
            model = cmbs.load("chain", links=links, closed=closed)
            compiled = CompiledDynamics(model, "lagrange")
            q, qd = model.q0.copy(), model.qd0.copy()
            qdd, lam = np.empty(model.n), np.empty(model.m)
            compiled.into(q, qd, 0.0, None, qdd, lam)
            ours = time_call(lambda: compiled.into(q, qd, 0.0, None, qdd, lam), batches, target)
            span = (0.1 if links >= 200 else 1.0) if args.quick else (1.0 if links >= 200 else 10.0)
            runs = {}
            for label, options in (("RK4 h=1ms", dict(integrator="rk4", dt=1e-3, formulation="baumgarte")),
                                   ("RK45 rtol=1e-8", dict(integrator="rk45", rtol=1e-8, atol=1e-8, dt=1e-2,
                                                           formulation="baumgarte"))):
                cmbs.simulate(model, t_end=0.01, **{**options, "dt": min(options["dt"], 0.01)})
                started = time.perf_counter()
                run = cmbs.simulate(model, t_end=span, **options)
                energy = run["energy"]
                runs[label] = {"wall_s": time.perf_counter() - started, "status": run.info["status"],
                               "evaluations": run.info["evaluations"], "compiled": bool(run.info.get("compiled")),
                               "max_constraint_error": float(run["constraint_error"].max()),
                               "relative_energy_error_end": float(abs(energy[-1] - energy[0])
                                                                  / max(abs(energy[0]), 1.0))}
            rk4 = runs["RK4 h=1ms"]
            loop_us = 1e6 * rk4["wall_s"] / rk4["evaluations"]
            row = {"links": links, "n": model.n, "m": model.m, "cmbs_us": ours["median"], "cmbs": ours,
                   "rk4_loop_us_per_eval": loop_us, "span_s": span, "runs": runs,
                   "peak_rss_mb": peak_memory(links, closed, span)}
            tree = chain_tree(model, links, closed)
            for name, measure in (("Pinocchio", pinocchio_measure), ("MuJoCo", mujoco_measure)):
                if not tools[name]:
                    continue
                try:
                    measured = measure(tree, 0.001, 1, batches, target)
                except Exception as error:  # noqa: BLE001 - reported, not fatal
                    row[name] = {"error": f"{type(error).__name__}: {error}"[:120]}
                    continue
                key = next(iter(measured["per_eval"]))       # aba / constraintDynamics / mj_forward
                row[name] = {"call": key, **measured["per_eval"][key]}
            rows.append(row)

            def cell(entry):
                return f"{entry['median']:.3g} [{entry['min']:.3g}-{entry['max']:.3g}]" if entry and "median" in entry \
                    else "-"

            pin, mj = row.get("Pinocchio"), row.get("MuJoCo")
            print(f"  {links:>4} {model.n:>4} {model.m:>4}  {cell(ours):>16}  {cell(pin):>16}  {cell(mj):>16}  "
                  + (f"{ours['median'] / pin['median']:>8.2f}" if pin and "median" in pin else f"{'-':>8}") + "  "
                  + (f"{ours['median'] / mj['median']:>11.2f}" if mj and "median" in mj else f"{'-':>11}")
                  + f"  {loop_us:>16.3g}")
            for label, entry in runs.items():
                print(f"        {span:g} s {label:<15} {entry['wall_s']:8.3f} s wall ({entry['status']}, "
                      f"{'compiled' if entry['compiled'] else 'python'}), max|Φ| {entry['max_constraint_error']:.1e}, "
                      f"|ΔE|/E0 at the end {entry['relative_energy_error_end']:.1e}")
            print(f"        peak memory of a process importing cmbs and running {span:g} s of RK4: "
                  f"{row['peak_rss_mb']:.0f} MB")
        sizes = [row["links"] for row in rows]
        slope = exponent(sizes, [row["cmbs_us"] for row in rows])
        report[f"exponent_{label}"] = slope
        others = "; ".join(f"{name} N^{exponent(sizes, [row[name]['median'] for row in rows]):.2f}"
                           for name in tools if tools[name] and all("median" in row.get(name, {}) for row in rows))
        print(f"  growth from 14 to 200 links: cmbs N^{slope:.2f} (target <= N^{TARGET_EXPONENT}: "
              f"{'PASS' if slope <= TARGET_EXPONENT else 'MISS'})" + (f"; {others}" if others else ""))
    write_report(args.json, report)
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        figure, axes = plt.subplots(1, 2, figsize=(10, 4.2), layout="constrained", sharey=True)
        for axis, label in zip(axes, ("open", "pinned")):
            rows = report["chains"][label]
            sizes = [row["links"] for row in rows]
            axis.loglog(sizes, [row["cmbs_us"] for row in rows], "o-", label="cmbs (compiled)")
            for name, style in (("Pinocchio", "s--"), ("MuJoCo", "^--")):
                if all("median" in row.get(name, {}) for row in rows):
                    axis.loglog(sizes, [row[name]["median"] for row in rows], style, label=name)
            axis.set_title(f"{label} chains", fontsize="medium")
            axis.set_xlabel("links N")
            axis.grid(alpha=0.3, which="both")
            axis.legend(fontsize="small")
        axes[0].set_ylabel("µs per forward-dynamics evaluation")
        figure.savefig(args.plot, dpi=120)
        print(f"figure -> {args.plot}")


if __name__ == "__main__":
    main()
