#!/usr/bin/env python
"""IFToMM benchmark A02, the N-four-bar, in Exudyn beside cmbs: error of B0 at every output and
wall time, N = 2, 10, 40 (needs the ``[bench]`` extra: ``pip install -e ".[bench]"``).

    python benchmarks/bench_n_four_bar_tools.py                 # N = 2 10 40, 20 s
    python benchmarks/bench_n_four_bar_tools.py --N 2 --t-end 5

Exudyn (J. Gerstmayr, Multibody Syst. Dyn. 2023) models each bar as a planar rigid body
(``NodeRigidBody2D``: x, y, φ of its centre) joined by ``RevoluteJoint2D``, integrated by its
recommended solver, the implicit generalized-α (index-3, Newton, default spectral radius) at
h = 1 ms; the position of B0 (the top of the first crank) is sampled every 0.05 s by a marker
sensor.  cmbs runs the same benchmark in natural coordinates with the settings
``CMBS_RUNS`` names: its generalized-α at the same step, and the projection formulation with
DOP853 at rtol 1e-8 and drift projection to 1e-12.  Both are
compared with the exact motion (:func:`cmbs.library.n_four_bar.exact_b0`, the 1-DOF reduction on
the parallelogram branch); "HP" is IFToMM's high precision, |B0 - exact| <= 1e-3 m at every
output.  Each run is timed once after an untimed 0.05 s warm-up (numba compilation excluded).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import cmbs  # noqa: E402
from cmbs.library.n_four_bar import B0_SPEED, BAR_LENGTH, BAR_MASS, GRAVITY, exact_b0  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from reporting import write_report  # noqa: E402

HIGH_PRECISION = 1e-3     # m
OUTPUT_INTERVAL = 0.05    # s
STEP = 1e-3               # s
try:
    import exudyn  # noqa: F401
    EXUDYN = True
except ImportError:
    EXUDYN = False

#: the cmbs runs beside Exudyn, as options of ``cmbs.simulate``: generalized-α at STEP, and the
#: projection formulation with DOP853 and a tight drift projection (docs/formulations.md)
CMBS_RUNS = (
    {"integrator": "generalized-alpha", "dt": STEP, "every": int(round(OUTPUT_INTERVAL / STEP))},
    {"formulation": "projection", "integrator": "dop853", "rtol": 1e-8, "dt": OUTPUT_INTERVAL, "project": True,
     "projection_tolerance": 1e-12},
)


def exudyn_b0(N: int, t_end: float) -> tuple[np.ndarray, np.ndarray, float]:
    """(times, B0 (k, 2), wall seconds of the solve) of A02 in Exudyn."""
    import exudyn as exu
    from exudyn.itemInterface import (LoadMassProportional, MarkerBodyMass, MarkerBodyPosition, NodeRigidBody2D,
                                      ObjectGround, ObjectJointRevolute2D, ObjectRigidBody2D, SensorMarker)

    system = exu.SystemContainer()
    mbs = system.AddSystem()
    ground = mbs.AddObject(ObjectGround())
    inertia = BAR_MASS * BAR_LENGTH ** 2 / 12
    half = BAR_LENGTH / 2

    def bar(centre: tuple[float, float], angle: float, velocity: tuple[float, float], spin: float) -> tuple[int, int]:
        """A bar's markers at its two ends (local x along the bar)."""
        node = mbs.AddNode(NodeRigidBody2D(referenceCoordinates=[centre[0], centre[1], angle],
                                           initialVelocities=[velocity[0], velocity[1], spin]))
        body = mbs.AddObject(ObjectRigidBody2D(mass=BAR_MASS, inertia=inertia, nodeNumber=node))
        mbs.AddLoad(LoadMassProportional(markerNumber=mbs.AddMarker(MarkerBodyMass(bodyNumber=body)),
                                         loadVector=[0.0, -GRAVITY, 0.0]))
        return (mbs.AddMarker(MarkerBodyPosition(bodyNumber=body, localPosition=[-half, 0.0, 0.0])),
                mbs.AddMarker(MarkerBodyPosition(bodyNumber=body, localPosition=[half, 0.0, 0.0])))

    spin = -B0_SPEED / BAR_LENGTH    # the cranks turn clockwise: B_i moves along +x at B0_SPEED
    cranks = [bar((i * BAR_LENGTH, half), math.pi / 2, (B0_SPEED / 2, 0.0), spin) for i in range(N + 1)]
    couplers = [bar(((i + 0.5) * BAR_LENGTH, BAR_LENGTH), 0.0, (B0_SPEED, 0.0), 0.0) for i in range(N)]
    for i, (bottom, top) in enumerate(cranks):
        pivot = mbs.AddMarker(MarkerBodyPosition(bodyNumber=ground, localPosition=[i * BAR_LENGTH, 0.0, 0.0]))
        mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[pivot, bottom]))
        if i < N:
            mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[top, couplers[i][0]]))
        if i > 0:
            mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[couplers[i - 1][1], top]))
    sensor = mbs.AddSensor(SensorMarker(markerNumber=cranks[0][1], outputVariableType=exu.OutputVariableType.Position,
                                        storeInternal=True, writeToFile=False))
    mbs.Assemble()
    settings = exu.SimulationSettings()
    settings.timeIntegration.numberOfSteps = int(round(t_end / STEP))
    settings.timeIntegration.endTime = t_end
    settings.timeIntegration.verboseMode = 0
    settings.solution.file.write = False
    settings.solution.sensors.writePeriod = OUTPUT_INTERVAL
    settings.show.computationTime = False
    settings.show.statistics = False
    started = time.perf_counter()
    exu.SolveDynamic(mbs, settings)
    wall = time.perf_counter() - started
    data = np.asarray(mbs.GetSensorStoredData(sensor))
    return data[:, 0], data[:, 1:3], wall


def error_at_outputs(times: np.ndarray, b0: np.ndarray, N: int) -> float:
    """max |B0 - exact| over the samples at multiples of OUTPUT_INTERVAL (inf if not finite)."""
    on_grid = np.abs(times / OUTPUT_INTERVAL - np.round(times / OUTPUT_INTERVAL)) < 1e-6
    exact, _ = exact_b0(times[on_grid], N)
    distance = np.hypot(*(b0[on_grid] - exact).T)
    return float(distance.max()) if np.all(np.isfinite(distance)) else float("inf")


def measure_exudyn(N: int, t_end: float) -> dict[str, object]:
    exudyn_b0(N, OUTPUT_INTERVAL)
    times, b0, wall = exudyn_b0(N, t_end)
    error = error_at_outputs(times, b0, N)
    return {"tool": "exudyn", "method": "generalized-alpha (RevoluteJoint2D, rigid bodies)", "t_reached": times[-1],
            "b0_error": error, "high_precision": bool(times[-1] >= t_end - 1e-9 and error <= HIGH_PRECISION),
            "wall": wall}


def measure_cmbs(N: int, t_end: float, options: dict[str, object]) -> dict[str, object]:
    model = cmbs.load("n-four-bar", N=N)
    cmbs.simulate(model, t_end=OUTPUT_INTERVAL, **options)
    started = time.perf_counter()
    run = cmbs.simulate(model, t_end=t_end, **options)
    wall = time.perf_counter() - started
    b0 = np.column_stack([run["B0.x"], run["B0.z"]])
    error = error_at_outputs(run.t, b0, N)
    success = run.info["status"] == "success"
    settings = [f"{key}={value:g}" for key, value in options.items() if key in ("rtol", "projection_tolerance")]
    method = " ".join([run.info["formulation"], run.info["integrator"], *settings])
    return {"tool": "cmbs", "method": method,
            "status": run.info["status"], "t_reached": float(run.t[-1]), "b0_error": error,
            "high_precision": bool(success and run.t[-1] >= t_end - 1e-9 and error <= HIGH_PRECISION), "wall": wall}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--N", type=int, nargs="+", default=[2, 10, 40])
    parser.add_argument("--t-end", type=float, default=20.0)
    parser.add_argument("--json", help="also write every figure to this JSON file")
    args = parser.parse_args()
    report: dict[str, list[dict[str, object]]] = {}
    for N in args.N:
        print(f"\nIFToMM A02, N = {N}, {args.t_end:g} s, h = {STEP:g} s, outputs every {OUTPUT_INTERVAL:g} s")
        print(f"  {'tool':<7} {'method':<56} {'t [s]':>6} {'max|B0 err|':>11} {'HP':>4} {'wall [s]':>9}")
        results = ([measure_exudyn(N, args.t_end)] if EXUDYN else []) + \
            [measure_cmbs(N, args.t_end, options) for options in CMBS_RUNS]
        for result in results:
            print(f"  {result['tool']:<7} {result['method']:<56} {result['t_reached']:6.2f} "
                  f"{result['b0_error']:11.2e} {'yes' if result['high_precision'] else 'no':>4} "
                  f"{result['wall']:9.3f}", flush=True)
        if not EXUDYN:
            print("  Exudyn is not installed (pip install -e \".[bench]\"): cmbs alone")
        for result in results[1:] if EXUDYN else []:
            print(f"  wall time of cmbs {result['method']} / Exudyn: {result['wall'] / results[0]['wall']:.2f}")
        report[str(N)] = results
    write_report(args.json, report)


if __name__ == "__main__":
    main()
