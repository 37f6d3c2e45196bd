#!/usr/bin/env python
"""IFToMM spatial rigid slider-crank in Exudyn beside cmbs and F. González's published solution:
the slider's x over 5 s, and wall times (needs the ``[bench]`` extra for Exudyn).

    python benchmarks/bench_slider_crank_3d.py                     # Exudyn at h = 1e-3, 1e-4, 5e-5; cmbs
    python benchmarks/bench_slider_crank_3d.py --write-reference   # also rewrite tests/data/slider-crank-3d-exudyn.csv

The problem (IFToMM Library of Computational Benchmark Problems, from Haug 1989, §12.2): crank AB
turning about the ground axis x at A = (0, 0.1, 0.12), 0.08 m long, pointing along +z at the
start (0.12 kg, centre of mass at its middle, 1e-4 kg m² about x); rod BC, 0.3 m from B by a
spherical joint to the slider C = (0.2, 0, 0) (0.5 kg, centre of mass at its middle, inertia
diag(4e-4, 4e-3, 4e-3) along and across it); slider 2 kg on the ground x axis (prismatic); a
universal joint at C whose slider-side axis is x and whose rod-side axis is the rod-fixed
e1 = (0, 2, -1)/√5, across the rod and x at the start (x · e1 = 0 throughout).  Gravity along -z.
The crank starts at 6 rad/s about x and is not driven; 5 s.

Exudyn (J. Gerstmayr, Multibody Syst. Dyn. 2023) models the three parts as rigid bodies with
Euler parameters, each placed at its centre of mass (``CreateRigidBody``), with
``CreateRevoluteJoint`` at A, ``CreateSphericalJoint`` at B, ``CreatePrismaticJoint`` for the
slider, and the universal joint as a ``CreateGenericJoint`` at C that locks the three
translations and the one rotation about x × e1 (its axes: x, e1, x × e1; the script checks
max |x · e1| afterwards).  Initial velocities are the consistent ones: slider (0.24, 0, 0) m/s,
rod centre (0.12, -0.24, 0) m/s, rod ω = (1.92, -0.96, 0.48) rad/s.  It integrates with its
implicit generalized-α (index 3, spectral radius 0.9, Newton tolerance 1e-10) at the steps
given; the slider's position and the crank's rotation matrix are sampled every 0.01 s, and the
crank angle about +x from z is unwrapped from them.  cmbs runs ``cmbs.load("spatial-slider-crank")``
(natural coordinates) with DOP853 at rtol 1e-10, timed after an untimed 0.1 s warm-up.

``--write-reference`` stores Exudyn's t, slider x and crank angle at the finest step as
tests/data/slider-crank-3d-exudyn.csv, with the change from the step twice as large in its
header.  tests/data/slider-crank-3d-gonzalez.csv is the published reference: F. González's
solution submitted to the IFToMM library (t and slider x every 0.01 s).
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import cmbs  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from exudyn_runs import solve_generalized_alpha  # noqa: E402

DATA = Path(__file__).resolve().parent.parent / "tests" / "data"
REFERENCE = DATA / "slider-crank-3d-exudyn.csv"
GONZALEZ = DATA / "slider-crank-3d-gonzalez.csv"
T_END, OUTPUT = 5.0, 0.01
STEPS = (1e-3, 1e-4, 5e-5)
SPECTRAL_RADIUS = 0.9


def exudyn_slider_crank(step: float) -> tuple[np.ndarray, float, float, str]:
    """(rows t, slider x, crank angle every 0.01 s, wall time, max |x · e1| over the run, Exudyn's version)."""
    import exudyn as exu
    from exudyn.utilities import RigidBodyInertia, SensorBody

    A, B, C = np.array([0.0, 0.1, 0.12]), np.array([0.0, 0.1, 0.20]), np.array([0.2, 0.0, 0.0])
    x_axis = np.array([1.0, 0.0, 0.0])
    along = (C - B) / np.linalg.norm(C - B)
    e1 = np.array([0.0, 2.0, -1.0]) / math.sqrt(5.0)
    rod_frame = np.column_stack([along, e1, np.cross(along, e1)])   # rod-fixed axes, columns in global
    omega_crank = np.array([6.0, 0.0, 0.0])
    omega_rod = np.array([1.92, -0.96, 0.48])
    gravity = [0.0, 0.0, -9.81]

    container = exu.SystemContainer()
    mbs = container.AddSystem()
    ground = mbs.CreateGround()
    crank_com = 0.5 * (A + B)
    crank = mbs.CreateRigidBody(inertia=RigidBodyInertia(mass=0.12, inertiaTensor=np.diag([1e-4, 1e-4, 1e-5])),
                                referencePosition=list(crank_com), initialAngularVelocity=list(omega_crank),
                                initialVelocity=list(np.cross(omega_crank, crank_com - A)), gravity=gravity)
    rod_com = 0.5 * (B + C)
    v_b = np.cross(omega_crank, B - A)
    rod = mbs.CreateRigidBody(inertia=RigidBodyInertia(mass=0.5, inertiaTensor=np.diag([4e-4, 4e-3, 4e-3])),
                              referencePosition=list(rod_com), referenceRotationMatrix=rod_frame,
                              initialVelocity=list(v_b + np.cross(omega_rod, rod_com - B)),
                              initialAngularVelocity=list(omega_rod), gravity=gravity)
    v_c = v_b + np.cross(omega_rod, C - B)
    assert abs(v_c[1]) < 1e-12 and abs(v_c[2]) < 1e-12 and abs(v_c @ x_axis - 0.24) < 1e-12
    slider = mbs.CreateRigidBody(inertia=RigidBodyInertia(mass=2.0, inertiaTensor=np.diag([1e-4, 1e-4, 1e-4])),
                                 referencePosition=list(C), initialVelocity=list(v_c), gravity=gravity)
    mbs.CreateRevoluteJoint(itemNumbers=[ground, crank], position=list(A), axis=[1.0, 0.0, 0.0])
    mbs.CreateSphericalJoint(itemNumbers=[crank, rod], position=list(B))
    mbs.CreatePrismaticJoint(itemNumbers=[ground, slider], position=list(C), axis=[1.0, 0.0, 0.0])
    # universal joint: joint axes x (free, the slider's), e1 (free, the rod's) and x × e1 (locked)
    mbs.CreateGenericJoint(itemNumbers=[slider, rod], position=list(C),
                           rotationMatrixAxes=np.column_stack([x_axis, e1, np.cross(x_axis, e1)]),
                           constrainedAxes=[1, 1, 1, 0, 0, 1], useGlobalFrame=True)
    sensors = [mbs.AddSensor(SensorBody(bodyNumber=body, outputVariableType=kind, storeInternal=True))
               for body, kind in ((slider, exu.OutputVariableType.Position),
                                  (crank, exu.OutputVariableType.RotationMatrix),
                                  (rod, exu.OutputVariableType.RotationMatrix))]
    mbs.Assemble()
    wall = solve_generalized_alpha(exu, mbs, t_end=T_END, step=step, output=OUTPUT,
                                   spectral_radius=SPECTRAL_RADIUS)
    position, crank_rotation, rod_rotation = (np.asarray(mbs.GetSensorStoredData(s)) for s in sensors)
    # rotation matrices row by row: column j of R is entries 1 + j, 4 + j, 7 + j
    crank_direction = crank_rotation[:, [3, 6, 9]]                   # the crank's local z (A to B), global
    angle = np.unwrap(np.arctan2(-crank_direction[:, 1], crank_direction[:, 2])) + 0.0   # + 0.0: no -0 at t = 0
    rod_e1 = rod_rotation[:, [2, 5, 8]]
    misalignment = float(np.abs(rod_e1 @ x_axis).max())
    return np.column_stack([position[:, 0], position[:, 1], angle]), wall, misalignment, exu.__version__


def cmbs_slider_crank() -> tuple[np.ndarray, np.ndarray, float]:
    """(times, rows slider x and crank angle, wall time) of cmbs on the benchmark."""
    model = cmbs.load("spatial-slider-crank")
    settings = dict(dt=OUTPUT, integrator="dop853", rtol=1e-10, atol=1e-12)
    cmbs.simulate(model, t_end=0.1, **settings)
    start = time.perf_counter()
    run = cmbs.simulate(model, t_end=T_END, **settings)
    wall = time.perf_counter() - start
    columns = [model.coordinate_index("x_slider"), model.coordinate_index("crank_angle")]
    energy = model.energy_history(run.q, run.qd)
    print(f"cmbs dop853 rtol 1e-10: {run.info['status']}, {wall:.3f} s, {len(run.t)} outputs, "
          f"max |E - E0| = {np.ptp(energy):.2e} J")
    return run.t, run.q[:, columns], wall


def gonzalez() -> np.ndarray:
    """Rows t, slider x of the published solution."""
    return np.loadtxt(GONZALEZ, delimiter=",", comments="#")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write-reference", action="store_true", help="rewrite " + str(REFERENCE))
    args = parser.parse_args()
    published = gonzalez()
    times, cmbs_q, cmbs_wall = cmbs_slider_crank()
    assert np.allclose(times, published[:, 0])
    gap = np.abs(cmbs_q[:, 0] - published[:, 1])
    print(f"cmbs vs González: max |Δx| = {gap.max():.2e} m (t = {times[gap.argmax()]:.2f} s), "
          f"on [0, 1] s {gap[times <= 1.0 + 1e-9].max():.2e} m")
    if importlib.util.find_spec("exudyn") is None:
        print("Exudyn is not installed (pip install '.[bench]'): only cmbs and González's solution were compared")
        return
    previous = None
    for step in STEPS:
        data, wall, misalignment, version = exudyn_slider_crank(step)
        assert np.allclose(data[:, 0], times)
        to_gonzalez = np.abs(data[:, 1] - published[:, 1])
        to_cmbs = np.abs(cmbs_q - data[:, 1:]).max(axis=0)
        line = (f"Exudyn {version} h = {step:g}: {wall:.3f} s, max |x · e1| = {misalignment:.1e}; "
                f"vs González max |Δx| = {to_gonzalez.max():.2e} m (t = {times[to_gonzalez.argmax()]:.2f} s); "
                f"cmbs vs Exudyn max |Δx| = {to_cmbs[0]:.2e} m, max |Δθ| = {to_cmbs[1]:.2e} rad; "
                f"wall ratio cmbs / Exudyn = {cmbs_wall / wall:.3f}")
        if previous is not None:
            change = np.abs(data[:, 1:] - previous[1][:, 1:]).max(axis=0)
            line += f"; change from h = {previous[0]:g}: {change[0]:.1e} m, {change[1]:.1e} rad"
        print(line)
        if args.write_reference and step == STEPS[-1]:
            header = (f"IFToMM spatial rigid slider-crank: slider x [m] and crank angle [rad, about +x from z, "
                      f"unwrapped] every {OUTPUT} s over {T_END} s, computed by Exudyn {version} "
                      f"(benchmarks/bench_slider_crank_3d.py: generalized-alpha, index 3, spectral radius "
                      f"{SPECTRAL_RADIUS}, h = {step:g} s, Newton tolerance 1e-10; change from h = {previous[0]:g}: "
                      f"max {change[0]:.1e} m in x, {change[1]:.1e} rad in the angle)\nt,x_slider,crank_angle")
            np.savetxt(REFERENCE, data, delimiter=",", header=header, fmt="%.12g")
            print(f"reference -> {REFERENCE}")
        previous = (step, data)


if __name__ == "__main__":
    sys.exit(main())
