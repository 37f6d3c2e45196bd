#!/usr/bin/env python
"""IFToMM benchmark A04, Bricard's mechanism, in Exudyn beside cmbs: the trajectory of P3 and the
energy over 10 s, and wall times (needs the ``[bench]`` extra for Exudyn).

    python benchmarks/bench_bricard.py                     # Exudyn at h = 1e-3 and 1e-4, cmbs
    python benchmarks/bench_bricard.py --write-reference   # also rewrite tests/data/bricard-exudyn-p3.csv

Exudyn (J. Gerstmayr, Multibody Syst. Dyn. 2023) models the five rods as rigid bodies
(``CreateRigidBody``: inertia of a 1 x 0.1 x 0.1 m box of density 100 kg/m³, 1 kg), joined by
``CreateRevoluteJoint`` at P0-P4 and closed on the ground at P5 by a ``CreateGenericJoint`` that
leaves the rotation about x free; its dense solver ignores the redundant rows
(``ignoreSingularJacobian``).  It integrates by its implicit generalized-α (index 3, spectral
radius 1, Newton tolerance 1e-10) at the step given; P3 (body 2's end) is sampled every 0.05 s.
cmbs runs ``cmbs.load("bricard")`` (natural coordinates, 24 coordinates, 24 rows of rank 23) with
the projection and Udwadia-Kalaba formulations and DOP853 at rtol 1e-10.  Each cmbs run is timed
after an untimed 0.1 s warm-up (numba compilation excluded).

``--write-reference`` stores Exudyn's P3 at h = 1e-4 (its generalized-α is second order: the
difference to cmbs falls from 1e-5 m at h = 1e-3 to 1e-7 m at 1e-4) as the reference of
tests/test_spatial.py, with the Exudyn version and settings in the file's header.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import cmbs  # noqa: E402

REFERENCE = Path(__file__).resolve().parent.parent / "tests" / "data" / "bricard-exudyn-p3.csv"
T_END, OUTPUT = 10.0, 0.05


def exudyn_p3(step: float) -> tuple[np.ndarray, float, str]:
    """(rows t, x, y, z of P3 every 0.05 s, wall time, Exudyn's version)."""
    import exudyn as exu
    from exudyn.utilities import InertiaCuboid, MarkerBodyPosition, ObjectGround, RotationMatrixY, \
        RotationMatrixZ, SensorMarker

    from cmbs.library.spatial import BRICARD_AXES, BRICARD_POINTS

    container = exu.SystemContainer()
    mbs = container.AddSystem()
    inertia = InertiaCuboid(density=100.0, sideLengths=[1.0, 0.1, 0.1]).Translated([0.5, 0.0, 0.0])
    # each rod's local x from its first joint point to its second
    rotations = [np.eye(3), RotationMatrixZ(-0.5 * np.pi), RotationMatrixY(-0.5 * np.pi), RotationMatrixZ(np.pi),
                 RotationMatrixZ(0.5 * np.pi)]
    ground = mbs.AddObject(ObjectGround())
    previous, rods = ground, []
    for k, point in enumerate(BRICARD_POINTS):
        if k < 5:
            body = mbs.CreateRigidBody(inertia=inertia, referencePosition=list(point),
                                       referenceRotationMatrix=rotations[k], gravity=[0.0, -9.81, 0.0])
            mbs.CreateRevoluteJoint(bodyNumbers=[previous, body], position=list(point), axis=list(BRICARD_AXES[k]))
            rods.append(body)
            previous = body
        else:
            mbs.CreateGenericJoint(bodyNumbers=[previous, ground], position=list(point),
                                   constrainedAxes=[1, 1, 1, 0, 1, 1])
    marker = mbs.AddMarker(MarkerBodyPosition(bodyNumber=rods[2], localPosition=[1.0, 0.0, 0.0]))
    sensor = mbs.AddSensor(SensorMarker(markerNumber=marker, outputVariableType=exu.OutputVariableType.Position,
                                        storeInternal=True, writeToFile=False))
    mbs.Assemble()
    settings = exu.SimulationSettings()
    settings.timeIntegration.numberOfSteps = int(round(T_END / step))
    settings.timeIntegration.endTime = T_END
    settings.timeIntegration.verboseMode = 0
    settings.timeIntegration.newton.useModifiedNewton = True
    settings.timeIntegration.newton.relativeTolerance = 1e-10
    settings.timeIntegration.newton.absoluteTolerance = 1e-12
    settings.timeIntegration.generalizedAlpha.spectralRadius = 1.0
    settings.solution.file.write = False
    settings.solution.sensors.writePeriod = OUTPUT
    settings.linearSolver.solverType = exu.LinearSolverType.EigenDense
    settings.linearSolver.ignoreSingularJacobian = True
    start = time.perf_counter()
    mbs.SolveDynamic(simulationSettings=settings)
    return np.asarray(mbs.GetSensorStoredData(sensor)), time.perf_counter() - start, exu.__version__


def cmbs_p3(formulation: str) -> tuple[np.ndarray, np.ndarray, float]:
    """(times, P3 rows, wall time) of cmbs on the benchmark."""
    model = cmbs.load("bricard")
    settings = dict(dt=OUTPUT, formulation=formulation, integrator="dop853", rtol=1e-10, atol=1e-12)
    cmbs.simulate(model, t_end=0.1, **settings)
    start = time.perf_counter()
    run = cmbs.simulate(model, t_end=T_END, **settings)
    wall = time.perf_counter() - start
    index = model.coordinate_index("P3.x")
    energy = model.energy_history(run.q, run.qd)
    print(f"cmbs {formulation:<15} {run.info['status']}, {wall:.3f} s, max |E - E0| = {np.ptp(energy):.2e} J")
    return run.t, run.q[:, index:index + 3], wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write-reference", action="store_true", help="rewrite " + str(REFERENCE))
    args = parser.parse_args()
    runs = {name: cmbs_p3(name) for name in ("projection", "udwadia-kalaba")}
    if importlib.util.find_spec("exudyn") is None:
        print("Exudyn is not installed (pip install '.[bench]'): only cmbs was run")
        return
    for step in (1e-3, 1e-4):
        data, wall, version = exudyn_p3(step)
        for name, (times, p3, cmbs_wall) in runs.items():
            gap = np.abs(p3 - data[:, 1:]).max()
            print(f"Exudyn {version} h = {step:g}: {wall:.3f} s; cmbs {name}: max |P3 - Exudyn's| = {gap:.2e} m, "
                  f"wall ratio cmbs / Exudyn = {cmbs_wall / wall:.3f}")
        if args.write_reference and step == 1e-4:
            header = (f"Bricard's mechanism (IFToMM A04): P3 [m] every {OUTPUT} s over {T_END} s, computed by Exudyn "
                      f"{version} (benchmarks/bench_bricard.py: generalized-alpha, spectral radius 1, h = {step:g} s, "
                      "Newton tolerance 1e-10)\nt,x,y,z")
            np.savetxt(REFERENCE, data, delimiter=",", header=header, fmt="%.12g")
            print(f"reference -> {REFERENCE}")


if __name__ == "__main__":
    sys.exit(main())
