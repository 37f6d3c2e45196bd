#!/usr/bin/env python
"""Work-precision diagrams: error at the end of a run against its wall time, for every cmbs
formulation/integrator pair over a range of steps or tolerances, beside MuJoCo and Pinocchio.

    python benchmarks/work_precision.py [--quick] [--out-dir DIR] [--json FILE]

Mechanisms (the same in every tool; bench_dynamics.py builds the other tools' models):
``four-bar`` (the anchors' crank-rocker), ``slider-crank`` (equal links, natural coordinates,
gravity 9.81; its crank passes 90° at 0.83 s, where the constraint Jacobian loses rank) and
``chain14`` (14 links, tip pinned).  Span 1 s from the common start state.

Error: max |θ1(t) - θ1_ref(t)| over t = 0.25, 0.5, 0.75, 1 s, θ1 the first link's absolute
angle (the crank; link 1 of the chain), a quantity every tool has (several times: at one time
an error can vanish by chance).  Reference: for the slider-crank, its motion on the branch
θ2 = -2θ1 as one smooth ODE in θ1 (``cmbs.library.mechanisms.slider_crank_branch``, DOP853 at
1e-13), which no singular position disturbs; for the others, cmbs matrix R with RK4 at h = 25 µs.
Each is checked against Pinocchio with scipy's DOP853 at 1e-12 (the difference is printed; a
level below ten times it is not resolved).  Not a small-step run on the slider-crank: every
formulation evaluated at a stage within δ of the singular position amplifies rounding about
1/δ³ times, and small steps put stages there (matrix R at h = 25 µs ends 6e-10 rad off, at
10 µs 1e-5; docs/formulations.md).  Wall: the whole call (cmbs.simulate; the other
tools' loop), the median of up to 5 runs (fewer past 0.5 s) after a warm-up run of the same
configuration (cmbs, MuJoCo; it loads the compiled code that configuration takes).

Configurations: cmbs RK4 with h = 10, 6.25, 5, 3.125, 2, 1, 0.5, 0.2, 0.1 ms on the compiled loops (baumgarte,
projection, matrix-r); RK45 with rtol = 1e-4 ... 1e-10 (lagrange, matrix-r) and DOP853 (lagrange,
compiled); generalized-α with
h = 10, 2, 1 ms; MuJoCo RK4 and implicitfast with the same steps; Pinocchio RK45 and
DOP853 (scipy) with rtol = 1e-4 ... 1e-10 and RK4 (Python loop) with h = 10, 2, 1 ms.

For each accuracy level 1e-3 ... 1e-9: the fastest configuration of cmbs and of each tool that
reaches it, and whether cmbs's is faster than every tool's that reaches it (the issue's
target).  One figure per mechanism (error vs wall, log-log).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import math  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402

import cmbs  # noqa: E402
from cmbs.library.mechanisms import slider_crank_branch  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_dynamics import (GRAVITY, anchors_four_bar, chain_tree, four_bar_tree, installed,  # noqa: E402
                            mujoco_build, pinocchio_build, slider_crank_tree)
from reporting import write_report  # noqa: E402

SPAN = 1.0
QUARTERS = np.array([0.25, 0.5, 0.75, 1.0])   # error = max |Δθ1| over these times (one time can be lucky)
REFERENCE_STEP = 2.5e-5     # matrix R, RK4 (compiled), for the mechanisms without singular positions
LEVELS = [10.0 ** -k for k in range(3, 10)]
STEPS = [1e-2, 1 / 160, 5e-3, 1 / 320, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4]   # each a divisor of a quarter of SPAN
TOLERANCES = [1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10]


def small_step_reference(model: cmbs.Model, tree) -> tuple[np.ndarray, str]:
    """θ1 at the QUARTERS from cmbs matrix R with RK4 at REFERENCE_STEP, and its description."""
    run = cmbs.simulate(model, t_end=SPAN, formulation="matrix-r", integrator="rk4", dt=REFERENCE_STEP)
    return quarter_angles(model, tree, run), f"cmbs matrix-r RK4, h = {REFERENCE_STEP:g}"


def branch_reference(model: cmbs.Model, tree) -> tuple[np.ndarray, str]:
    """θ1 at the QUARTERS from the slider-crank's ODE on its branch θ2 = -2θ1, and its description."""
    theta, _ = slider_crank_branch(QUARTERS, **model.parameters)
    return theta, "branch ODE θ2 = -2θ1, DOP853 1e-13"


MECHANISMS = {
    "four-bar": (anchors_four_bar, four_bar_tree, small_step_reference),
    "slider-crank": (lambda: cmbs.load("slider-crank", gravity=GRAVITY), slider_crank_tree, branch_reference),
    "chain14": (lambda: cmbs.load("chain", links=14, closed=True), lambda model: chain_tree(model, 14),
                small_step_reference),
}


def wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def first_link_angle(model: cmbs.Model, tree, q: np.ndarray) -> float:
    """Absolute angle of the tree's first link from the cmbs model's point positions."""
    link = tree.links[0]
    points = dict(zip(model.point_names, np.asarray(model.point_positions(q))))
    d = points[link.end] - points[link.start]
    return math.atan2(d[1], d[0])


def quarter_angles(model: cmbs.Model, tree, run) -> np.ndarray:
    """θ1 at the QUARTERS from a cmbs run whose outputs include those times."""
    rows = [int(np.argmin(np.abs(run.t - time))) for time in QUARTERS]
    assert np.allclose(run.t[rows], QUARTERS, atol=1e-9), "outputs must include the quarter times"
    return np.array([first_link_angle(model, tree, run.q[row]) for row in rows])


def deviation(angles: np.ndarray, reference: np.ndarray) -> float | None:
    """max |Δθ1| over the quarter times (angles wrapped), None when not finite."""
    angles = np.asarray(angles, dtype=float)
    if not np.all(np.isfinite(angles)):
        return None
    return float(max(abs(wrap(a - r)) for a, r in zip(angles, reference)))


#: Each configuration's wall time is the median of up to REPEATS timed runs, fewer once BUDGET_S
#: seconds are spent (runs of a few ms vary by tens of per cent on shared cores; one run decides
#: nothing there).
REPEATS = 5
BUDGET_S = 0.5


def timed(call):
    """(the call's value, median wall seconds of up to REPEATS runs within BUDGET_S)."""
    walls = []
    while len(walls) < REPEATS and sum(walls) < BUDGET_S:
        started = time.perf_counter()
        value = call()
        walls.append(time.perf_counter() - started)
    return value, statistics.median(walls)


def cmbs_configurations(quick: bool) -> list[tuple[str, str, dict, str]]:
    steps = STEPS[::2] if quick else STEPS
    tolerances = TOLERANCES[::2] if quick else TOLERANCES
    configurations = []
    for formulation in ("baumgarte", "projection", "matrix-r"):
        configurations += [(f"cmbs {formulation} RK4", formulation, {"integrator": "rk4", "dt": h}, f"h={h:g}")
                           for h in steps]
    for formulation in ("lagrange", "matrix-r"):
        configurations += [(f"cmbs {formulation} RK45", formulation,
                            {"integrator": "rk45", "rtol": tol, "atol": tol, "dt": 0.25}, f"rtol={tol:g}")
                           for tol in tolerances]
    configurations += [("cmbs lagrange DOP853", "lagrange",
                        {"integrator": "dop853", "rtol": tol, "atol": tol, "dt": 0.25}, f"rtol={tol:g}")
                       for tol in tolerances]
    configurations += [("cmbs generalized-alpha", None, {"integrator": "generalized-alpha", "dt": h}, f"h={h:g}")
                       for h in (1e-2, 2e-3, 1e-3)]
    return configurations


def run_cmbs(model, tree, quick: bool, reference: float) -> list[dict]:
    rows = []
    for family, formulation, options, setting in cmbs_configurations(quick):
        cmbs.simulate(model, t_end=SPAN, formulation=formulation, **options)  # warm: compiled code loaded
        run, wall = timed(lambda: cmbs.simulate(model, t_end=SPAN, formulation=formulation, **options))
        ok = run.info["status"] == "success" and abs(run.t[-1] - SPAN) < 1e-9
        error = deviation(quarter_angles(model, tree, run), reference) if ok else None
        rows.append({"tool": "cmbs", "family": family, "setting": setting, "wall_s": wall, "error": error,
                     "status": run.info["status"], "path": "compiled" if run.info.get("compiled") else "python"})
    return rows


def run_mujoco(tree, quick: bool, reference: float) -> list[dict]:
    import mujoco

    model, data, q0, v0, address = mujoco_build(tree)
    root = address(tree.links[0].name)
    rows = []
    for label, integrator in (("MuJoCo RK4", mujoco.mjtIntegrator.mjINT_RK4),
                              ("MuJoCo implicitfast", mujoco.mjtIntegrator.mjINT_IMPLICITFAST)):
        model.opt.integrator = integrator
        for h in (STEPS[::2] if quick else STEPS):
            model.opt.timestep = h
            steps = int(round(SPAN / h))

            def simulate():
                mujoco.mj_resetData(model, data)
                data.qpos[:], data.qvel[:] = q0, v0
                angles = []
                for quarter in range(4):
                    for _ in range(steps // 4):
                        mujoco.mj_step(model, data)
                    angles.append(float(data.qpos[root]))
                return angles
            simulate()
            angles, wall = timed(simulate)
            rows.append({"tool": "MuJoCo", "family": label, "setting": f"h={h:g}", "wall_s": wall,
                         "error": deviation(angles, reference)})
    return rows


def pinocchio_solution(built: tuple, method: str, tolerance: float) -> np.ndarray:
    """θ1 at the quarters by scipy's ``method`` on the Pinocchio model ``built`` by
    :func:`pinocchio_build` (its right-hand side, start state and index of θ1)."""
    from scipy.integrate import solve_ivp

    rhs, y0, root = built
    solution = solve_ivp(lambda t, y: rhs(y), (0.0, SPAN), y0, method=method, rtol=tolerance, atol=tolerance,
                         t_eval=QUARTERS)
    return solution.y[root]


def pinocchio_model(tree) -> tuple:
    """(right-hand side, start state, index of θ1) of :func:`pinocchio_build` for ``tree``."""
    _, _, rhs, y0, index, *_ = pinocchio_build(tree)
    return rhs, y0, index(tree.links[0].name)


def run_pinocchio(tree, quick: bool, reference: float) -> list[dict]:
    built = pinocchio_model(tree)
    rhs, y0, root = built
    rows = []
    for method in ("RK45", "DOP853"):
        for tolerance in (TOLERANCES[::2] if quick else TOLERANCES):
            angles, wall = timed(lambda: pinocchio_solution(built, method, tolerance))
            rows.append({"tool": "Pinocchio", "family": f"Pinocchio {method} (scipy)", "setting": f"rtol={tolerance:g}",
                         "wall_s": wall, "error": deviation(angles, reference)})
    for h in (1e-2, 2e-3, 1e-3):
        def rk4():
            y, angles = y0.copy(), []
            for _ in range(4):
                for _ in range(int(round(SPAN / h)) // 4):
                    k1 = rhs(y)
                    k2 = rhs(y + 0.5 * h * k1)
                    k3 = rhs(y + 0.5 * h * k2)
                    k4 = rhs(y + h * k3)
                    y = y + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
                angles.append(float(y[root]))
            return angles
        angles, wall = timed(rk4)
        rows.append({"tool": "Pinocchio", "family": "Pinocchio RK4 (Python loop)", "setting": f"h={h:g}",
                     "wall_s": wall, "error": deviation(angles, reference)})
    return rows


def fastest(rows: list[dict], tool: str, level: float) -> dict | None:
    reached = [row for row in rows if row["tool"] == tool and row["error"] is not None and row["error"] <= level]
    return min(reached, key=lambda row: row["wall_s"]) if reached else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="every other step and tolerance")
    parser.add_argument("--out-dir", default="out", help="folder of the figures (work-precision-MECHANISM.png)")
    parser.add_argument("--json", help="write every run to this file")
    parser.add_argument("--mechanism", action="append", choices=list(MECHANISMS), help="only these (repeatable)")
    args = parser.parse_args()
    os.makedirs(args.out_dir, exist_ok=True)
    tools = [name for name, module in (("MuJoCo", "mujoco"), ("Pinocchio", "pinocchio")) if installed(module)]
    print(f"cmbs {cmbs.__version__}; other tools: {', '.join(tools) or 'none installed'}; span {SPAN} s")
    report = {}
    for label in args.mechanism or list(MECHANISMS):
        build, tree_of, reference_of = MECHANISMS[label]
        model = build()
        tree = tree_of(model)
        reference, described = reference_of(model, tree)
        check = None
        if "Pinocchio" in tools:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                other = pinocchio_solution(pinocchio_model(tree), "DOP853", 1e-12)
            check = deviation(other, reference)
        print(f"\n== {label}: reference θ1(1 s) = {reference[-1]:.12f} rad ({described})"
              + (f"; Pinocchio DOP853 1e-12 differs by {check:.1e} rad" if check is not None else ""))
        rows = run_cmbs(model, tree, args.quick, reference)
        if "MuJoCo" in tools:
            rows += run_mujoco(tree, args.quick, reference)
        if "Pinocchio" in tools:
            rows += run_pinocchio(tree, args.quick, reference)
        print(f"  {'configuration':<34} {'setting':<12} {'wall s':>9} {'error rad':>10}")
        for row in rows:
            error = f"{row['error']:.2e}" if row["error"] is not None else "failed"
            print(f"  {row['family']:<34} {row['setting']:<12} {row['wall_s']:>9.4f} {error:>10}")
        print("  fastest configuration reaching each error level (wall s); target: cmbs faster than every tool "
              "that reaches the level")
        verdicts = []
        for level in LEVELS:
            ours = fastest(rows, "cmbs", level)
            theirs = {tool: fastest(rows, tool, level) for tool in tools}
            beaten = [tool for tool, row in theirs.items() if row and (ours is None or row["wall_s"] < ours["wall_s"])]
            resolved = check is None or level > 10 * check
            verdict = ("PASS" if not beaten else "MISS") if ours else ("MISS" if any(theirs.values()) else "-")
            if not resolved:
                verdict += " (below the references' agreement)"
            verdicts.append({"level": level, "verdict": verdict, "cmbs": ours, **theirs})
            cells = [f"cmbs {ours['wall_s']:.4f} ({ours['family'][5:]}, {ours['setting']})" if ours else "cmbs -"]
            cells += [f"{tool} {row['wall_s']:.4f} ({row['family'].split(' ', 1)[1]}, {row['setting']})" if row
                      else f"{tool} -" for tool, row in theirs.items()]
            print(f"    {level:.0e}: " + "; ".join(cells) + f"  {verdict}")
        report[label] = {"reference": reference.tolist(), "reference_check": check, "runs": rows, "levels": verdicts}
        plot(label, rows, os.path.join(args.out_dir, f"work-precision-{label}.png"), check)
    write_report(args.json, report)


def plot(label: str, rows: list[dict], path: str, floor: float | None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(8, 5.5), layout="constrained")
    families = list(dict.fromkeys(row["family"] for row in rows))
    markers = "os^vD<>ph*"
    for k, family in enumerate(families):
        points = sorted((row["wall_s"], row["error"]) for row in rows if row["family"] == family
                        and row["error"] is not None and row["error"] > 0)
        if points:
            x, y = zip(*points)
            axis.loglog(x, y, marker=markers[k % len(markers)], linestyle="-" if family.startswith("cmbs") else "--",
                        label=family)
    if floor:
        axis.axhline(floor, color="0.5", linewidth=0.8, linestyle=":", label="references' agreement")
    axis.set_xlabel("wall time [s] for 1 s of motion")
    axis.set_ylabel("max |θ1 - reference| at 0.25, 0.5, 0.75, 1 s [rad]")
    axis.set_title(f"work-precision: {label}", fontsize="medium")
    axis.grid(alpha=0.3, which="both")
    axis.legend(fontsize="x-small", ncol=2)
    figure.savefig(path, dpi=120)
    plt.close(figure)
    print(f"  figure -> {path}")


if __name__ == "__main__":
    main()
