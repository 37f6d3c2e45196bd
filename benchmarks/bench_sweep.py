#!/usr/bin/env python
"""Sweeps of many four-bar variants (issue target: 10 000 variants x 1 s at h = 1 ms in <= 10 s
wall on 2 cores).

    python benchmarks/bench_sweep.py              # 10 000 variants, batched; 200 through processes
    python benchmarks/bench_sweep.py --quick      # 1 000 and 50
    python benchmarks/bench_sweep.py --integrator rk45    # the adaptive batch (the target is rk4's)

The variants: the undriven thesis four-bar (``cmbs.load("four-bar").without_drivers()``)
released with N crank speeds from -2 to 2 rad/s (velocities made consistent); RK4 at h = 1 ms,
Lagrange, 1 s each, recorded every 100 steps.  Timed: ``cmbs.sweep`` on the batched path (one
compiled call, numba threads over the variants) and, for fewer variants, on the process path
(``cmbs.simulate`` per variant in a pool of processes), reported per variant so the two compare.
The first call (numba compilation, pool start) is excluded by a warm-up.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numba  # noqa: E402
import numpy as np  # noqa: E402

import cmbs  # noqa: E402

TARGET_S = 10.0          # 10 000 variants x 1 s
TARGET_VARIANTS = 10_000


def variants(model: cmbs.Model, count: int) -> list[cmbs.Variant]:
    column = model.coordinate_names.index("alpha")
    result = []
    for speed in np.linspace(-2.0, 2.0, count):
        guess = np.zeros(model.n)
        guess[column] = speed
        result.append(cmbs.Variant(qd0=cmbs.velocities(model, model.q0, qd=guess, fixed=["alpha"])))
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="1 000 batched and 50 process-path variants")
    parser.add_argument("--integrator", default="rk4", choices=("rk4", "rk45", "rk23", "dop853"),
                        help="rk4 (the target's) or an adaptive one (default tolerances; outputs every 1 ms)")
    args = parser.parse_args()
    batched_count, pooled_count = (1_000, 50) if args.quick else (TARGET_VARIANTS, 200)
    model = cmbs.load("four-bar").without_drivers()
    print(f"cmbs {cmbs.__version__}, numba {numba.__version__}, {os.cpu_count()} CPUs, numba threads "
          f"{numba.get_num_threads()}")
    every = dict(t_end=1.0, dt=1e-3, every=100, formulation="lagrange", integrator=args.integrator)
    cmbs.sweep(model, variants(model, 4), **every)                               # compile
    chosen = variants(model, batched_count)
    started = time.perf_counter()
    result = cmbs.sweep(model, chosen, **every)
    wall = time.perf_counter() - started
    scaled = wall * TARGET_VARIANTS / batched_count
    print(f"batched {args.integrator}: {batched_count} variants x 1 s in {wall:.2f} s "
          f"({1e3 * wall / batched_count:.2f} ms per variant, "
          f"{set(result.status)}); 10 000 variants: {scaled:.1f} s"
          f"{' (scaled)' if batched_count != TARGET_VARIANTS else ''}"
          f", target {TARGET_S:g} s, ratio {scaled / TARGET_S:.2f} -> {'PASS' if scaled <= TARGET_S else 'MISS'}")
    pooled = variants(model, pooled_count)
    cmbs.sweep(model, pooled[:2], batched=False, **every)                          # warm the pool's imports
    started = time.perf_counter()
    result = cmbs.sweep(model, pooled, batched=False, **every)
    pool_wall = time.perf_counter() - started
    print(f"processes ({result.info['workers']} workers): {pooled_count} variants in {pool_wall:.2f} s "
          f"({1e3 * pool_wall / pooled_count:.2f} ms per variant; batched / processes per variant = "
          f"{(wall / batched_count) / (pool_wall / pooled_count):.2f})")


if __name__ == "__main__":
    main()
