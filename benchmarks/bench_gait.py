"""Inverse dynamics of one recorded stride of the human model (issue 5; docs/gait.md).

Target: full IDA of a stride (114 frames of right stride 1, 14 generalized forces per frame) in
<= 0.2 s wall.  Timed: :func:`cmbs.gait.inverse.inverse` in both modes (contact wrench at the
hip; measured GRF at the centres of pressure, including building their generalized forces); the
data preparation (fit, smoothing) is not part of it and is timed separately.

    python benchmarks/bench_gait.py
    python benchmarks/bench_gait.py --repeat 3
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from cmbs.gait import prepare_stride
from cmbs.gait.inverse import inverse

TARGET = 0.2   # s of wall time for the IDA of one stride


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


if __name__ == "__main__":
    main()
