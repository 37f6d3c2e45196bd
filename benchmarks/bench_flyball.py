#!/usr/bin/env python
"""IFToMM benchmark A05, the stiff flyball governor, in Exudyn beside cmbs: the slider's height
s over 10 s, a work-precision table of cmbs's integrators and Exudyn's step sizes (needs the
``[bench]`` extra for Exudyn).

    python benchmarks/bench_flyball.py                     # Exudyn at h = 1e-3 ... 2.5e-5; cmbs, 11 runs
    python benchmarks/bench_flyball.py --write-reference   # also rewrite tests/data/flyball-exudyn.csv

The problem (M. González, D. Dopico, U. Lugrís, J. Cuadrado, Multibody Syst. Dyn. 16:179-190,
2006; topology as in the MBSbenchmarksInOpenSim A05 model): a vertical shaft, a 1 x 0.01 x 0.01 m
bar of 0.3 kg, free to turn about the ground axis z at its lower end O; a slider (0.1 m cube,
3 kg) on it by a prismatic joint along z, its centre at height s (s = 0.5 m at the start); two
rods (bars of 1 m, 0.3 kg) hinged to the shaft's top at (±0.05, 0, 1) about the shaft's y axis,
30° below the horizontal, each with a 5 kg point mass at its outer end; a spring-damper from each
side of the slider, (±0.05, 0, s), to its rod's middle (K = 8e5 N/m, C = 4e4 N s/m, rest length
0.5 m: unloaded at the start).  Gravity along -z; everything starts turning about z at 2π rad/s
(not driven); 10 s; the reference quantity is s(t).

Exudyn (J. Gerstmayr, Multibody Syst. Dyn. 2023) models the shaft, the slider and each rod with
its point mass as rigid bodies with Euler parameters placed at their centres of mass
(``CreateRigidBody``; rod and point mass as one body with their combined inertia), with
``CreateRevoluteJoint`` ground-shaft (z) and shaft-rods (y), ``CreatePrismaticJoint`` for the
slider and ``CreateSpringDamper`` for the two springs.  It integrates with its implicit
generalized-α (index 3, spectral radius 0.9, Newton tolerance 1e-10) at the steps given and
samples s every 0.01 s.  cmbs runs ``cmbs.load("flyball-governor")`` (natural coordinates, 43
coordinates, 4 DOF) with each integrator setting of ``CMBS_RUNS``, each timed after an untimed
0.1 s warm-up with the same settings (numba compilation excluded); its error is max |s - s_ref|
over the 1001 outputs, s_ref being Exudyn at the finest step.

``--write-reference`` stores Exudyn's t, s at the finest step as tests/data/flyball-exudyn.csv,
with the change from the step twice as large in its header.  tests/data/flyball-a05-digitized.csv
is the library's reference curve as far as it is published: digitized from the comparison plot
of the MBSbenchmarksInOpenSim project (t = 0.1 ... 3 s, about ±1e-3 m).
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
REFERENCE = DATA / "flyball-exudyn.csv"
DIGITIZED = DATA / "flyball-a05-digitized.csv"
T_END, OUTPUT = 10.0, 0.01
STEPS = (1e-3, 5e-4, 2.5e-4, 1e-4, 5e-5, 2.5e-5)
SPECTRAL_RADIUS = 0.9
# (label, cmbs.simulate keywords): adaptive runs output every 0.01 s, fixed-step runs keep every 0.01 s
CMBS_RUNS = (
    ("rk45 rtol 1e-6", dict(integrator="rk45", rtol=1e-6, atol=1e-9)),
    ("rk45 rtol 1e-8", dict(integrator="rk45", rtol=1e-8, atol=1e-10)),
    ("generalized-alpha dt 1e-3", dict(integrator="generalized-alpha", dt=1e-3)),
    ("generalized-alpha dt 5e-4", dict(integrator="generalized-alpha", dt=5e-4)),
    ("generalized-alpha dt 2.5e-4", dict(integrator="generalized-alpha", dt=2.5e-4)),
    ("trapezoidal dt 1e-3", dict(integrator="trapezoidal", dt=1e-3)),
    ("trapezoidal dt 5e-4", dict(integrator="trapezoidal", dt=5e-4)),
    ("trapezoidal dt 2.5e-4", dict(integrator="trapezoidal", dt=2.5e-4)),
    ("backward-euler dt 1e-3", dict(integrator="backward-euler", dt=1e-3)),
    ("backward-euler dt 1e-4", dict(integrator="backward-euler", dt=1e-4)),
    ("backward-euler dt 2.5e-5", dict(integrator="backward-euler", dt=2.5e-5)),
)


def exudyn_flyball(step: float) -> tuple[np.ndarray, float, str]:
    """(rows t, s every 0.01 s, wall time, Exudyn's version)."""
    import exudyn as exu
    from exudyn.utilities import InertiaCuboid, InertiaMassPoint, RigidBodyInertia, SensorBody

    density, gravity = 3000.0, [0.0, 0.0, -9.81]
    spin = np.array([0.0, 0.0, 2.0 * math.pi])
    tilt = math.radians(30.0)
    container = exu.SystemContainer()
    mbs = container.AddSystem()
    ground = mbs.CreateGround()

    def body(inertia, origin: np.ndarray, rotation: np.ndarray):
        """A rigid body whose frame is at ``origin`` with axes ``rotation`` (columns, global) at the
        start and whose ``inertia`` is given in that frame; the body's node is put at its centre of mass."""
        com = origin + rotation @ np.asarray(inertia.COM())
        return mbs.CreateRigidBody(inertia=RigidBodyInertia(mass=inertia.Mass(), inertiaTensor=inertia.InertiaCOM()),
                                   referencePosition=list(com), referenceRotationMatrix=rotation,
                                   initialVelocity=list(np.cross(spin, com)), initialAngularVelocity=list(spin),
                                   gravity=gravity), com

    shaft, _ = body(InertiaCuboid(density, [0.01, 0.01, 1.0]), np.array([0.0, 0.0, 0.5]), np.eye(3))
    slider, slider_com = body(InertiaCuboid(density, [0.1, 0.1, 0.1]), np.array([0.0, 0.0, 0.5]), np.eye(3))
    mbs.CreateRevoluteJoint(itemNumbers=[ground, shaft], position=[0.0, 0.0, 0.0], axis=[0.0, 0.0, 1.0])
    mbs.CreatePrismaticJoint(itemNumbers=[shaft, slider], position=list(slider_com), axis=[0.0, 0.0, 1.0])
    for sign in (1.0, -1.0):
        hinge = np.array([0.05 * sign, 0.0, 1.0])
        along = np.array([sign * math.cos(tilt), 0.0, -math.sin(tilt)])
        frame = np.column_stack([along, [0.0, 1.0, 0.0], np.cross(along, [0.0, 1.0, 0.0])])  # local x along the rod
        rod_and_ball = (InertiaCuboid(density, [1.0, 0.01, 0.01]).Translated([0.5, 0.0, 0.0])
                        + InertiaMassPoint(5.0).Translated([1.0, 0.0, 0.0]))
        rod, rod_com = body(rod_and_ball, hinge, frame)
        mbs.CreateRevoluteJoint(itemNumbers=[shaft, rod], position=list(hinge), axis=[0.0, 1.0, 0.0])
        seat, middle = np.array([0.05 * sign, 0.0, 0.5]), hinge + 0.5 * along
        mbs.CreateSpringDamper(itemNumbers=[slider, rod], localPosition0=list(seat - slider_com),
                               localPosition1=list(frame.T @ (middle - rod_com)),
                               referenceLength=0.5, stiffness=8e5, damping=4e4)
    sensor = mbs.AddSensor(SensorBody(bodyNumber=slider, outputVariableType=exu.OutputVariableType.Position,
                                      storeInternal=True))
    mbs.Assemble()
    wall = solve_generalized_alpha(exu, mbs, t_end=T_END, step=step, output=OUTPUT,
                                   spectral_radius=SPECTRAL_RADIUS)
    data = np.asarray(mbs.GetSensorStoredData(sensor))
    return data[:, [0, 3]], wall, exu.__version__


def cmbs_flyball(settings: dict) -> tuple[np.ndarray, np.ndarray, float, str]:
    """(times, s, wall time, status) of one cmbs run."""
    model = cmbs.load("flyball-governor")
    step = settings.get("dt", OUTPUT)
    keywords = dict(settings, dt=step, every=int(round(OUTPUT / step)))
    cmbs.simulate(model, t_end=0.1, **keywords)
    start = time.perf_counter()
    run = cmbs.simulate(model, t_end=T_END, **keywords)
    wall = time.perf_counter() - start
    return run.t, run.q[:, model.coordinate_index("s")], wall, run.info["status"]


def digitized() -> np.ndarray:
    """Rows t, s of the digitized reference."""
    return np.loadtxt(DIGITIZED, delimiter=",", comments="#")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write-reference", action="store_true", help="rewrite " + str(REFERENCE))
    args = parser.parse_args()
    cmbs_runs = []
    for label, settings in CMBS_RUNS:
        times, s, wall, status = cmbs_flyball(settings)
        cmbs_runs.append((label, times, s, wall, status))
        print(f"cmbs {label}: {status}, {wall:.3f} s")
    if importlib.util.find_spec("exudyn") is None:
        print("Exudyn is not installed (pip install '.[bench]'): only cmbs was run")
        return
    exudyn_runs = []
    for step in STEPS:
        data, wall, version = exudyn_flyball(step)
        assert np.allclose(data[:, 0], cmbs_runs[0][1])
        line, change = f"Exudyn {version} h = {step:g}: {wall:.3f} s", math.nan
        if exudyn_runs:
            change = np.abs(data[:, 1] - exudyn_runs[-1][1][:, 1]).max()
            line += f", change from h = {exudyn_runs[-1][0]:g}: max |Δs| = {change:.1e} m"
        print(line)
        exudyn_runs.append((step, data, wall, change))
    finest_step, reference, finest_wall, finest_change = exudyn_runs[-1]
    points = digitized()
    rows = np.searchsorted(reference[:, 0], points[:, 0] - 1e-9)
    for label, values in ((f"Exudyn h = {finest_step:g}", reference[:, 1]),
                          ("cmbs " + cmbs_runs[1][0], cmbs_runs[1][2])):
        gap = np.abs(values[rows] - points[:, 1])
        order = np.argsort(gap)[::-1]
        print(f"{label} vs the {len(points)} digitized reference points: max |Δs| = {gap[order[0]]:.1e} m "
              f"(t = {points[order[0], 0]:.1f} s), next largest {gap[order[1]]:.1e} m "
              f"(t = {points[order[1], 0]:.1f} s), median {np.median(gap):.1e} m")
    floor = finest_change / 3.0     # second order: the finest run's own error, about a third of its last change
    print(f"\nwork-precision: max |s - Exudyn's at h = {finest_step:g}| over the outputs (that reference is itself "
          f"about {floor:.0e} m off: errors below that are not resolved); wall time; its ratio to Exudyn's at the "
          f"finest step ({finest_wall:.3f} s) and, for a fixed-step cmbs run, to Exudyn's at the same step")
    print(f"{'run':<38} {'max |Δs| [m]':>13} {'wall [s]':>9} {'/ finest':>9} {'/ same h':>9}")
    exudyn_walls = {step: wall for step, _, wall, _ in exudyn_runs}
    for step, data, wall, _ in exudyn_runs:
        error = np.abs(data[:, 1] - reference[:, 1]).max()
        shown = "reference" if step == finest_step else f"{error:.1e}"
        print(f"{'Exudyn gen.-alpha h ' + format(step, 'g'):<38} {shown:>13} {wall:9.3f} {wall / finest_wall:9.3f}")
    for (label, times, s, wall, status), (_, settings) in zip(cmbs_runs, CMBS_RUNS):
        error = np.abs(s - reference[:, 1]).max() if len(s) == len(reference) else math.inf
        same = exudyn_walls.get(settings.get("dt"))
        print(f"{'cmbs ' + label:<38} {error:13.1e} {wall:9.3f} {wall / finest_wall:9.3f} "
              + (f"{wall / same:9.3f}" if same else f"{'-':>9}") + ("" if status == "success" else f"  ({status})"))

    if args.write_reference:
        header = (f"IFToMM A05 stiff flyball governor: slider height s [m] every {OUTPUT} s over {T_END} s, computed "
                  f"by Exudyn {version} (benchmarks/bench_flyball.py: generalized-alpha, index 3, spectral radius "
                  f"{SPECTRAL_RADIUS}, h = {finest_step:g} s, Newton tolerance 1e-10; change from h = "
                  f"{exudyn_runs[-2][0]:g}: max {finest_change:.1e} m)\nt,s")
        np.savetxt(REFERENCE, reference, delimiter=",", header=header, fmt="%.12g")
        print(f"reference -> {REFERENCE}")


if __name__ == "__main__":
    sys.exit(main())
