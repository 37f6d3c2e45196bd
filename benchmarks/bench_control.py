"""Closed-loop computed-torque tracking of the thesis four-bar: 10 s with RK4 at 1 ms.

Target: <= 1 s wall.  The law is ComputedTorque (k_p = 100, k_d = 20) on α, from α0 + 0.1 rad at
rest, on the undriven four-bar, formulation lagrange.  Three runs: the law evaluated at every RK4
stage and at 1 kHz (sampled and held over each step, a digital controller), each on the path
cmbs.simulate chooses (compiled when it can), and the continuous law forced onto the Python path.
The runs must agree with each other (printed) and track the reference (final error printed).

    python benchmarks/bench_control.py            # 10 s of motion per run
    python benchmarks/bench_control.py --quick    # 2 s of motion per run
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import cmbs
from cmbs.control import ComputedTorque, Reference, ZeroOrderHold

TARGET = 1.0   # s of wall time for 10 s of motion


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="2 s of motion instead of 10")
    parser.add_argument("--repeat", type=int, default=3, help="timed runs per case (the median is reported)")
    args = parser.parse_args()
    t_end, h = (2.0 if args.quick else 10.0), 1e-3

    driven = cmbs.load("four-bar")
    motion = cmbs.kinematic_analysis(driven, np.linspace(0.0, t_end, int(round(t_end / h)) + 1))
    plant = driven.without_drivers()
    q0 = motion.q[0].copy()
    q0[plant.coordinate_index("alpha")] += 0.1
    q0 = cmbs.assemble(plant, q0, fixed=["alpha"])

    def continuous() -> ComputedTorque:
        return ComputedTorque(plant, Reference(motion, ["alpha"]), kp=100.0, kd=20.0)

    cases = {"CTC at every stage": (continuous, None),
             "CTC at 1 kHz (held)": (lambda: ZeroOrderHold(continuous(), h), None),
             "CTC at every stage, Python path": (continuous, False)}
    print(f"four-bar, computed-torque tracking, {t_end:g} s, RK4 h = {h:g} s, lagrange; target {TARGET:g} s per 10 s")
    runs = {}
    for label, (make_law, compiled) in cases.items():
        cmbs.simulate(plant, t_end=10 * h, integrator="rk4", dt=h, u=make_law(), q0=q0, qd0=np.zeros(plant.n),
                      compiled=compiled)                                  # warm-up: compile, caches
        walls = []
        for _ in range(max(1, args.repeat if compiled is None else 1)):
            started = time.perf_counter()
            run = cmbs.simulate(plant, t_end=t_end, integrator="rk4", dt=h, u=make_law(), q0=q0,
                                qd0=np.zeros(plant.n), compiled=compiled)
            walls.append(time.perf_counter() - started)
        runs[label] = run
        wall = float(np.median(walls)) * 10.0 / t_end
        error = abs(run["alpha"][-1] - motion["alpha"][run.t.size - 1])
        path = "compiled" if run.info.get("compiled") else "Python"
        print(f"  {label:<34} {path:<8} {wall:8.3f} s per 10 s  ({wall / TARGET:6.2f}x target, "
              f"{'PASS' if wall <= TARGET else 'MISS'})  final |α error| {error:.2e} rad  {run.info['status']}")
    reference = runs["CTC at every stage, Python path"]
    for label, run in runs.items():
        if run is not reference:
            print(f"  max |Δq| {label} vs Python path: {np.abs(run.q - reference.q).max():.2e}")


if __name__ == "__main__":
    main()
