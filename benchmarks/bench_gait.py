"""Inverse dynamics of one recorded stride of the human model (issue 5; docs/gait.md).

Target: full IDA of a stride (114 frames of right stride 1, 14 generalized forces per frame) in
<= 0.2 s wall.  Timed: :func:`cmbs.gait.inverse.inverse` in both modes (contact wrench at the
hip; measured GRF at the centres of pressure, including building their generalized forces); the
data preparation (fit, smoothing) is not part of it and is timed separately.

Target: forward simulation of one stride (1.13 s) under computed-torque control at h = 1 ms
(RK4, Lagrange) in <= 0.5 s wall (issue 5).  Timed: :func:`cmbs.simulate` of the tracking plant
(:mod:`cmbs.gait.track`: residual actuators; measured GRF as tabulated point forces, or none) under
:class:`cmbs.control.ComputedTorque` from a 5° initial error, on the compiled loop
(:mod:`cmbs.integrate.compiled_rk4`, chosen automatically: the plant has no Python wrapper, the law is exactly a
ComputedTorque) and on the Python loop (``compiled=False``); the law's construction is not timed.

    python benchmarks/bench_gait.py
    python benchmarks/bench_gait.py --repeat 3
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from cmbs.gait import prepare_stride
from cmbs.gait.inverse import inverse
from cmbs.gait.track import controller, perturbed_state, tracking_plant
from cmbs.simulate import simulate

TARGET = 0.2   # s of wall time for the IDA of one stride
TRACK_TARGET = 0.5   # s of wall time for one stride under CTC at h = 1 ms


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stride", type=int, default=1, help="right stride")
    parser.add_argument("--repeat", type=int, default=5, help="timed runs per mode (the median is reported)")
    args = parser.parse_args()
    started = time.perf_counter()
    prepared = prepare_stride(args.stride)
    print(f"prepare (fetch cached, fit, smoothing, kinematics): {time.perf_counter() - started:.2f} s, "
          f"{len(prepared.motion.t)} frames")
    for mode in ("hip", "grf"):
        inverse(prepared.model, prepared.motion, mode)          # warm-up (compiled kernels)
        times = []
        for _ in range(args.repeat):
            started = time.perf_counter()
            inverse(prepared.model, prepared.motion, mode)
            times.append(time.perf_counter() - started)
        wall = float(np.median(times))
        print(f"IDA of a stride, mode {mode}: {1e3 * wall:.1f} ms (target {1e3 * TARGET:.0f} ms, "
              f"ratio {wall / TARGET:.3f})")
    model, reference = prepared.model, prepared.motion
    t_end = float(reference.t[-1])
    for contact in ("grf", "hip"):
        plant = tracking_plant(model, reference, contact)
        law = controller("ctc", plant, model, reference, contact)
        q0, qd0 = perturbed_state(plant, reference, 5.0)
        for compiled in (True, False):
            options = dict(t_end=t_end, integrator="rk4", dt=1e-3, q0=q0, qd0=qd0, u=law, compiled=compiled)
            simulate(plant, **{**options, "t_end": 0.01})      # warm-up (compiled kernels)
            times = []
            for _ in range(args.repeat if compiled else 1):
                started = time.perf_counter()
                run = simulate(plant, **options)
                times.append(time.perf_counter() - started)
            wall = float(np.median(times))
            print(f"CTC stride {t_end:.2f} s, h = 1 ms RK4, contact {contact}, "
                  f"{'compiled' if compiled else 'Python'} loop: {wall:.3f} s ({run.info['status']}; "
                  f"target {TRACK_TARGET} s, ratio {wall / TRACK_TARGET:.2f})")


if __name__ == "__main__":
    main()
