#!/usr/bin/env python
"""Wall time of the servo-constraint inverse dynamics of the passive manipulator (Quasem, Uhlar &
Betsch 2009; cmbs.inverse.servo).

    python benchmarks/bench_servo.py [--quick] [--json FILE]

The case of examples/passive_manipulator_servo.py: link-3 COM from (7.5, 5) to (5.5, 3) in 3 s
(quintic), backward Euler with h = 0.01 (300 steps), Newton tolerance 1e-10, in natural
coordinates (RED, ``passive-manipulator``, n = 9, m = 6) and joint angles (GEN,
``passive-manipulator-joint``, n = 3), with ``method="full"`` and ``method="projected"``.

For each: the wall time of one ``servo_inverse_dynamics`` call (median [min-max] of 7 runs after
one warm-up run; ``--quick``: 3 runs), its ratio to the target of 1 s, the Newton iterations
per step and, from one profiled run, the model evaluations per step and where the time goes
(top functions by own time).  BLAS runs on one thread unless OPENBLAS_NUM_THREADS (or
OMP_/MKL_NUM_THREADS) is set.
"""

from __future__ import annotations

import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse  # noqa: E402
import cProfile  # noqa: E402
import pstats  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import cmbs  # noqa: E402
from cmbs.inverse.servo import LinePath, segment_point, servo_inverse_dynamics  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_model import environment, fmt  # noqa: E402  (same environment record and format)
from reporting import write_report  # noqa: E402

TARGET_S = 1.0
CASES = (("RED", "passive-manipulator"), ("GEN", "passive-manipulator-joint"))
METHODS = ("full", "projected")
TIMES = np.linspace(0.0, 3.0, 301)


def problem(name: str):
    model = cmbs.load(name)
    output = segment_point(model, "link3")
    start = output.value(model.q0)
    return model, output, LinePath(start, start + np.array([-2.0, -2.0]), 3.0)


def profile(model, output, path, method: str, top: int = 6) -> dict:
    """Model evaluations per step and the functions with the most own time, from one run."""
    profiler = cProfile.Profile()
    profiler.enable()
    servo_inverse_dynamics(model, output, path, TIMES, method=method)
    profiler.disable()
    stats = pstats.Stats(profiler).stats
    total = sum(entry[2] for entry in stats.values())
    evaluations = sum(entry[1] for (file, _, function), entry in stats.items()
                      if function == "evaluate" and file.endswith("model.py"))
    ranked = sorted(stats.items(), key=lambda item: item[1][2], reverse=True)[:top]
    return {"evaluations_per_step": evaluations / (TIMES.size - 1),
            "top_own_time": [(function if file == "~" else f"{os.path.basename(file)}:{function}", entry[2] / total)
                             for (file, _, function), entry in ranked]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="3 timed runs instead of 7")
    parser.add_argument("--json", metavar="FILE", help="write all figures as JSON")
    args = parser.parse_args(argv)
    repeat = 3 if args.quick else 7
    env = environment()
    print(f"cmbs {env['cmbs']}  python {env['python']}  numpy {env['numpy']}  {env['processor']} x{env['cpu_count']}"
          f"  load avg {env['load_average_start'][0]:.2f}")
    print(f"servo inverse dynamics, 300 steps of h = 0.01, wall s: median [min-max] of {repeat} runs after a warm-up;"
          f" target <= {TARGET_S:g} s\n")
    report: dict = {"environment": env, "target_s": TARGET_S, "repeat": repeat, "cases": {}}
    for label, name in CASES:
        model, output, path = problem(name)
        for method in METHODS:
            result = servo_inverse_dynamics(model, output, path, TIMES, method=method)  # warm-up
            walls = []
            for _ in range(repeat):
                began = time.perf_counter()
                servo_inverse_dynamics(model, output, path, TIMES, method=method)
                walls.append(time.perf_counter() - began)
            stats = {"median": statistics.median(walls), "min": min(walls), "max": max(walls), "runs": walls}
            breakdown = profile(model, output, path, method)
            verdict = "PASS" if stats["median"] <= TARGET_S else "MISS"
            report["cases"][f"{label} {method}"] = {
                "model": name, "n": model.n, "m": model.m, "wall_s": stats,
                "ratio_to_target": stats["median"] / TARGET_S,
                "verdict": verdict, "newton_iterations_per_step": float(result.iterations[1:].mean()),
                "max_newton_iterations": int(result.iterations.max()), **breakdown}
            print(f"== {label} ({name}, n = {model.n}, m = {model.m}), method {method}")
            print(f"  wall {fmt(stats)} s   {stats['median'] / TARGET_S:.2f} x target: {verdict}   "
                  f"{1e3 * stats['median'] / (TIMES.size - 1):.2f} ms/step")
            print(f"  Newton iterations/step {result.iterations[1:].mean():.2f} (max {result.iterations.max()}),"
                  f"  model.evaluate calls/step {breakdown['evaluations_per_step']:.1f} (profiled run)")
            print("  own time (profiled run): " + ", ".join(f"{where} {100 * share:.0f}%"
                                                       for where, share in breakdown["top_own_time"]))
    report["environment"]["load_average_end"] = os.getloadavg()
    print("\n== summary (medians)")
    for key, case in report["cases"].items():
        print(f"  {key:<14} {case['wall_s']['median']:.3f} s  ({case['ratio_to_target']:.2f} x the {TARGET_S:g} s "
              f"target: {case['verdict']})")
    print(f"  load average at start / end: {env['load_average_start'][0]:.2f} / {os.getloadavg()[0]:.2f} on "
          f"{env['cpu_count']} cores")
    write_report(args.json, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
