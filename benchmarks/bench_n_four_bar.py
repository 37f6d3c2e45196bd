#!/usr/bin/env python
"""IFToMM benchmark A02, the N-four-bar (González et al., Multibody Syst. Dyn. 16:179-190, 2006):
every formulation and integrator of cmbs through its singular positions, against the exact motion.

    python benchmarks/bench_n_four_bar.py                    # N = 2, 20 s, every configuration
    python benchmarks/bench_n_four_bar.py --N 2 10 40        # the benchmark's three sizes
    python benchmarks/bench_n_four_bar.py --t-end 3 --json out.json

The model is ``cmbs.load("n-four-bar", N=N)``; the exact motion of B0 is
``cmbs.library.n_four_bar.exact_b0`` (the 1-DOF reduction on the parallelogram branch, DOP853
at 1e-12).  Configurations: each formulation (lagrange, baumgarte, penalty, projection,
udwadia-kalaba, matrix-r, at their default options) with rk4 at h = 1 ms and with rk45 and
dop853 at the default tolerances (rtol 1e-6, atol 1e-9), and generalized-α at h = 1 ms (which
brings its own index-3 Lagrange formulation); then projection and udwadia-kalaba again with rk4
and dop853 and drift projection after every step to max |Φ| < 1e-12 (``project=True,
projection_tolerance=1e-12``; "+proj" in the table), and matrix-r with dop853 at rtol 1e-8
(" 1e-8" after the integrator); outputs every 0.05 s, as the benchmark asks.
Per run: status, the time reached, max |B0 - exact| over the outputs, whether the run meets
IFToMM high precision (success to the end and B0 within 1e-3 m at every output), the energy
drift max |E - E0| / max T (``info["energy_drift"]``), the wall time of the run (its numba
compilation excluded by a short warm-up run first, which is not timed), the branch error (the
largest difference between two crank vectors B_i - A_i over the outputs: zero on the
parallelogram branch, of the order of the links on another) and two flags for a status success
with B0 more than 1e-3 m off: ``SUCCESS OFF BRANCH`` where the branch error exceeds 1e-3 m too —
a wrong answer that says nothing — else ``success, inaccurate``: on the branch, with an error
along it that the run's tolerances allowed.  Each run is a child process stopped after
``--timeout`` seconds.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import cmbs  # noqa: E402
from cmbs.library.n_four_bar import exact_b0  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from reporting import write_report  # noqa: E402

HIGH_PRECISION = 1e-3     # m, IFToMM A02 "high precision" on B0 at every output
OUTPUT_INTERVAL = 0.05    # s
STEP = 1e-3               # s, the fixed-step integrators
FORMULATIONS = ("lagrange", "baumgarte", "penalty", "projection", "udwadia-kalaba", "matrix-r")
EXPLICIT = ("rk4", "rk45", "dop853")
DRIFT_TOLERANCE = 1e-12   # max |Φ| after the drift projection of the "+proj" configurations
PROJECTED = ("projection", "udwadia-kalaba")
TIGHT_RTOL = 1e-8         # rtol of the tight configuration of matrix-r with dop853


def configurations() -> list[tuple[str | None, str, bool, float | None]]:
    """(formulation, integrator, drift projection, rtol or None for the default) tuples: each
    formulation with each explicit integrator, generalized-α with its own formulation (None), the
    :data:`PROJECTED` formulations with rk4 and dop853 and drift projection, and matrix-r with
    dop853 at :data:`TIGHT_RTOL`."""
    return [(formulation, integrator, False, None) for formulation in FORMULATIONS for integrator in EXPLICIT] + \
        [(None, "generalized-alpha", False, None)] + \
        [(formulation, integrator, True, None) for formulation in PROJECTED for integrator in ("rk4", "dop853")] + \
        [("matrix-r", "dop853", False, TIGHT_RTOL)]


def simulate(model: cmbs.Model, formulation: str | None, integrator: str, projected: bool, rtol: float | None,
             t_end: float) -> cmbs.Trajectory:
    """One run with outputs every :data:`OUTPUT_INTERVAL`: fixed-step integrators at :data:`STEP`
    keeping every 50th step, adaptive ones at ``rtol`` (None: the default tolerances); with
    ``projected``, coordinate and velocity projection after every step to :data:`DRIFT_TOLERANCE`."""
    drift = {"project": True, "projection_tolerance": DRIFT_TOLERANCE} if projected else {}
    if integrator in ("rk4", "generalized-alpha"):
        return cmbs.simulate(model, t_end=t_end, formulation=formulation, integrator=integrator, dt=STEP,
                             every=int(round(OUTPUT_INTERVAL / STEP)), **drift)
    tolerance = {} if rtol is None else {"rtol": rtol}
    return cmbs.simulate(model, t_end=t_end, formulation=formulation, integrator=integrator, dt=OUTPUT_INTERVAL,
                         **drift, **tolerance)


def b0_error(run: cmbs.Trajectory, N: int) -> float:
    """max over the run's outputs of |B0 - B0_exact| [m] (inf when an output is not finite)."""
    position, _ = exact_b0(run.t, N)
    distance = np.hypot(run["B0.x"] - position[:, 0], run["B0.z"] - position[:, 1])
    return float(distance.max()) if np.all(np.isfinite(distance)) else float("inf")


def branch_error(run: cmbs.Trajectory, N: int) -> float:
    """max over the run's outputs of |(B_i - A_i) - (B_0 - A_0)| [m], i = 1..N: the cranks of the
    parallelogram branch stay parallel and equal (inf when an output is not finite)."""
    spread = np.zeros(run.t.size)
    for i in range(1, N + 1):
        spread = np.maximum(spread, np.hypot(run[f"B{i}.x"] - i - run["B0.x"], run[f"B{i}.z"] - run["B0.z"]))
    return float(spread.max(initial=0.0)) if np.all(np.isfinite(spread)) else float("inf")


def measure(N: int, formulation: str | None, integrator: str, projected: bool, rtol: float | None,
            t_end: float) -> dict[str, object]:
    """Figures of one timed run (after an untimed 0.05 s warm-up run that compiles its kernels)."""
    model = cmbs.load("n-four-bar", N=N)
    simulate(model, formulation, integrator, projected, rtol, OUTPUT_INTERVAL)
    started = time.perf_counter()
    try:
        run = simulate(model, formulation, integrator, projected, rtol, t_end)
    except cmbs.CmbsError as error:
        return {"status": "error", "message": str(error), "wall": time.perf_counter() - started}
    wall = time.perf_counter() - started
    status = run.info["status"]
    error, off_branch = b0_error(run, N), branch_error(run, N)
    return {"status": status, "message": run.info.get("message", "") if status != "success" else "",
            "note": run.info.get("note", ""), "t_reached": float(run.t[-1]), "b0_error": error,
            "high_precision": bool(status == "success" and run.t[-1] >= t_end - 1e-9 and error <= HIGH_PRECISION),
            "branch_error": off_branch,
            "off_branch": bool(status == "success" and not off_branch <= HIGH_PRECISION),
            "inaccurate": bool(status == "success" and not error <= HIGH_PRECISION and off_branch <= HIGH_PRECISION),
            "energy_drift": run.info.get("energy_drift"), "wall": wall,
            "formulation_used": run.info.get("formulation", formulation)}


def _child(connection: multiprocessing.connection.Connection, *arguments: object) -> None:
    connection.send(measure(*arguments))
    connection.close()


def measure_with_timeout(N: int, formulation: str | None, integrator: str, projected: bool, rtol: float | None,
                         t_end: float, timeout: float) -> dict[str, object]:
    """:func:`measure` in a child process, stopped (status "timeout") after ``timeout`` seconds."""
    receiver, sender = multiprocessing.Pipe(duplex=False)
    child = multiprocessing.Process(target=_child, args=(sender, N, formulation, integrator, projected, rtol, t_end))
    child.start()
    sender.close()
    if receiver.poll(timeout):
        try:
            result = receiver.recv()
        except EOFError:
            result = {"status": "crashed", "message": "the child process ended without a result"}
    else:
        child.terminate()
        result = {"status": "timeout", "message": f"stopped after {timeout:g} s", "wall": timeout}
    child.join()
    return result


def row(formulation: str | None, integrator: str, projected: bool, rtol: float | None,
        result: dict[str, object]) -> str:
    """One line of the table ("+proj" after the integrator of a run with drift projection, the
    rtol after it when not the default)."""
    def number(key: str, form: str) -> str:
        value = result.get(key)
        return "-" if value is None else format(value, form)

    name = result.get("formulation_used") or formulation or "-"
    flag = "SUCCESS OFF BRANCH" if result.get("off_branch") else "success, inaccurate" if result.get("inaccurate") \
        else ""
    high = "yes" if result.get("high_precision") else "no"
    integrator = integrator + ("+proj" if projected else "") + ("" if rtol is None else f" {rtol:g}")
    return (f"  {name:<22} {integrator:<18} {result['status']:<8} {number('t_reached', '7.2f')} "
            f"{number('b0_error', '10.2e')} {number('branch_error', '9.1e')} {high:>5} {number('energy_drift', '9.1e')} "
            f"{number('wall', '8.3f')}"
            f"  {flag}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--N", type=int, nargs="+", default=[2], help="numbers of loops to run (benchmark: 2 10 40)")
    parser.add_argument("--t-end", type=float, default=20.0, help="simulated time [s] (benchmark: 20)")
    parser.add_argument("--timeout", type=float, default=600.0, help="wall seconds after which a run is stopped")
    parser.add_argument("--json", help="also write every figure to this JSON file")
    args = parser.parse_args()
    report: dict[str, list[dict[str, object]]] = {}
    for N in args.N:
        print(f"\nIFToMM A02 N-four-bar, N = {N}, {args.t_end:g} s, outputs every {OUTPUT_INTERVAL:g} s; "
              f"high precision: |B0 - exact| <= {HIGH_PRECISION:g} m at every output")
        print(f"  {'formulation':<22} {'integrator':<18} {'status':<8} {'t [s]':>7} {'max|B0 err|':>10} "
              f"{'branch':>9} {'HP':>5} {'E drift':>9} {'wall [s]':>8}")
        report[str(N)] = []
        for formulation, integrator, projected, rtol in configurations():
            result = measure_with_timeout(N, formulation, integrator, projected, rtol, args.t_end, args.timeout)
            print(row(formulation, integrator, projected, rtol, result), flush=True)
            for key in ("message", "note"):
                if result.get(key):
                    print(f"      {key}: {str(result[key]).splitlines()[0][:150]}")
            report[str(N)].append({"formulation": formulation, "integrator": integrator, "project": projected,
                                   **({"projection_tolerance": DRIFT_TOLERANCE} if projected else {}),
                                   **({} if rtol is None else {"rtol": rtol}), **result})
        runs = report[str(N)]
        print(f"  N = {N}: {sum(bool(r.get('high_precision')) for r in runs)} of {len(runs)} runs meet high "
              f"precision; {sum(bool(r.get('off_branch')) for r in runs)} say success off the branch, "
              f"{sum(bool(r.get('inaccurate')) for r in runs)} success on it but more than {HIGH_PRECISION:g} m off")
    write_report(args.json, report)


if __name__ == "__main__":
    main()
