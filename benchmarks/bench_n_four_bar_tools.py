#!/usr/bin/env python
"""IFToMM benchmark A02, the N-four-bar, in Exudyn, MuJoCo and Pinocchio beside cmbs: error of B0
at every output and wall time, N = 2, 10, 40 (needs the ``[bench]`` extra:
``pip install -e ".[bench]"``; a tool that is not installed is left out and said so).

    python benchmarks/bench_n_four_bar_tools.py                 # N = 2 10 40, 20 s
    python benchmarks/bench_n_four_bar_tools.py --N 2 --t-end 5

Exudyn (J. Gerstmayr, Multibody Syst. Dyn. 2023) models each bar as a planar rigid body
(``NodeRigidBody2D``: x, y, φ of its centre) joined by ``RevoluteJoint2D``, integrated by its
recommended solver, the implicit generalized-α (index-3, Newton, default spectral radius) at
h = 1 ms; the position of B0 (the top of the first crank) is sampled every 0.05 s by a marker
sensor.  MuJoCo (``MUJOCO_RUNS``) builds the open tree -- each crank hinged (about z) to the
world, each coupler hinged to the crank on its left, bars with mass 1 and in-plane inertia 1/12
about the centre -- and closes each loop by an ``equality connect`` (right end of coupler i to
the top of crank i+1); MuJoCo's constraints are soft (solref/solimp), stepped at h = 1 ms by its
Euler or RK4.  Pinocchio (``PINOCCHIO_RUNS``) builds the same tree of ``JointModelRZ`` joints in
3-D, closes the loops by ``RigidConstraintModel`` CONTACT_3D (the out-of-plane rows are
redundant), computes accelerations by ``constraintDynamics`` (proximal, µ > 0) and is stepped here
at h = 1 ms by semi-implicit Euler or RK4.  cmbs runs the same benchmark in natural coordinates with the settings
``CMBS_RUNS`` names: its generalized-α at the same step, and the projection formulation with
DOP853 at rtol 1e-8 and drift projection to 1e-12.  Both are
compared with the exact motion (:func:`cmbs.library.n_four_bar.exact_b0`, the 1-DOF reduction on
the parallelogram branch); "HP" is IFToMM's high precision, |B0 - exact| <= 1e-3 m at every
output.  Each run is timed once after an untimed 0.05 s warm-up (numba compilation excluded); "t"
is the last output with finite coordinates (a run that diverges stops there).
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
try:
    import mujoco  # noqa: F401
    MUJOCO = True
except ImportError:
    MUJOCO = False
try:
    import pinocchio  # noqa: F401
    PINOCCHIO = True
except ImportError:
    PINOCCHIO = False

#: MuJoCo runs: (integrator, equality-constraint softness); its defaults are solref "0.02 1",
#: solimp "0.9 0.95 0.001"; "stiff" is the shortest time constant MuJoCo accepts at h = 1 ms
#: (2 h) with an impedance near 1
MUJOCO_SOFTNESS = {"default": "", "stiff": 'solref="0.002 1" solimp="0.99 0.999 0.001"'}
MUJOCO_RUNS = (("Euler", "default"), ("Euler", "stiff"), ("RK4", "default"), ("RK4", "stiff"))
#: Pinocchio runs: (fixed-step scheme, proximal µ of constraintDynamics, Baumgarte (Kp, Kd));
#: µ = 0 fails at the first step (the redundant out-of-plane rows make the Delassus matrix singular)
PINOCCHIO_RUNS = (("semi-implicit Euler", 1e-8, (0.0, 0.0)), ("RK4", 1e-8, (0.0, 0.0)),
                  ("RK4", 1e-8, (100.0, 20.0)))
PINOCCHIO_ACCURACY = 1e-12
PINOCCHIO_ITERATIONS = 20

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


def bar_inertia() -> float:
    """In-plane inertia of a uniform bar about its centre, m L²/12."""
    return BAR_MASS * BAR_LENGTH ** 2 / 12


def mujoco_xml(N: int, integrator: str, softness: str) -> str:
    """MJCF of A02: cranks hinged to the world (along local +y), couplers hinged to the crank on
    their left (along local +x), loops closed by ``equality connect``; no contact, gravity -y."""
    inertia, thin = bar_inertia(), 1e-6 * bar_inertia()   # thin: the bar's axial inertia

    def coupler(i: int) -> str:
        return (f'<body name="coupler{i}" pos="0 {BAR_LENGTH} 0"><joint name="coupler{i}" type="hinge" axis="0 0 1"/>'
                f'<inertial pos="{BAR_LENGTH / 2} 0 0" mass="{BAR_MASS}" diaginertia="{thin} {inertia} {inertia}"/>'
                f'<geom type="capsule" fromto="0 0 0 {BAR_LENGTH} 0 0" size="0.01"/></body>')

    def crank(i: int) -> str:
        return (f'<body name="crank{i}" pos="{i * BAR_LENGTH} 0 0"><joint name="crank{i}" type="hinge" axis="0 0 1"/>'
                f'<inertial pos="0 {BAR_LENGTH / 2} 0" mass="{BAR_MASS}" diaginertia="{inertia} {thin} {inertia}"/>'
                f'<geom type="capsule" fromto="0 0 0 0 {BAR_LENGTH} 0" size="0.01"/>'
                f'<site name="B{i}" pos="0 {BAR_LENGTH} 0"/>{coupler(i) if i < N else ""}</body>')

    closures = "".join(f'<connect body1="coupler{i}" body2="crank{i + 1}" anchor="{BAR_LENGTH} 0 0" {softness}/>'
                       for i in range(N))
    return (f'<mujoco><option timestep="{STEP}" gravity="0 {-GRAVITY} 0" integrator="{integrator}"/>'
            '<default><geom contype="0" conaffinity="0"/></default>'
            f'<worldbody>{"".join(crank(i) for i in range(N + 1))}</worldbody><equality>{closures}</equality></mujoco>')


def crank_tops_velocity_error(model: "mujoco.MjModel", data: "mujoco.MjData", N: int) -> float:
    """max over B0..BN of |v(B_i) - (B0_SPEED, 0)|, from MuJoCo's own kinematics."""
    import mujoco
    velocity = np.zeros(6)
    worst = 0.0
    for i in range(N + 1):
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_SITE, model.site(f"B{i}").id, velocity, 0)
        worst = max(worst, float(np.hypot(velocity[3] - B0_SPEED, velocity[4])))
    return worst


def mujoco_b0(N: int, t_end: float, integrator: str, softness: str) -> tuple[np.ndarray, np.ndarray, float]:
    """(times, B0 (k, 2), wall seconds of the stepping) of A02 in MuJoCo.

    Initial velocities: cranks at -B0_SPEED/L rad/s, couplers at +B0_SPEED/L relative to their
    crank (they translate), so every B_i moves at (B0_SPEED, 0) -- checked, a mismatch raises."""
    import mujoco
    model = mujoco.MjModel.from_xml_string(mujoco_xml(N, integrator, MUJOCO_SOFTNESS[softness]))
    data = mujoco.MjData(model)
    spin = B0_SPEED / BAR_LENGTH
    for i in range(N + 1):
        data.qvel[model.jnt_dofadr[model.joint(f"crank{i}").id]] = -spin
        if i < N:
            data.qvel[model.jnt_dofadr[model.joint(f"coupler{i}").id]] = spin
    mujoco.mj_forward(model, data)
    if crank_tops_velocity_error(model, data, N) > 1e-12:
        raise RuntimeError("MuJoCo A02: the initial qvel does not move every B_i at (1, 0) m/s")
    site = model.site("B0").id
    steps_per_output = int(round(OUTPUT_INTERVAL / STEP))
    times, b0 = [0.0], [data.site_xpos[site, :2].copy()]
    started = time.perf_counter()
    for k in range(int(round(t_end / OUTPUT_INTERVAL))):
        mujoco.mj_step(model, data, nstep=steps_per_output)
        if not np.all(np.isfinite(data.qpos)):
            break
        times.append((k + 1) * OUTPUT_INTERVAL)
        b0.append(data.site_xpos[site, :2].copy())
    wall = time.perf_counter() - started
    return np.asarray(times), np.asarray(b0), wall


def pinocchio_model(N: int, baumgarte: tuple[float, float]) -> tuple[object, object, list[int]]:
    """(model, loop closures, crank joint ids) of A02 in Pinocchio: revolute-z joints in 3-D,
    CONTACT_3D closures between each coupler's right end and the next crank's top."""
    import pinocchio as pin
    model = pin.Model()
    model.gravity.linear = np.array([0.0, -GRAVITY, 0.0])
    inertia = bar_inertia()

    def placement(x: float, y: float) -> object:
        return pin.SE3(np.eye(3), np.array([x, y, 0.0]))

    cranks, couplers = [], []
    for i in range(N + 1):
        crank = model.addJoint(0, pin.JointModelRZ(), placement(i * BAR_LENGTH, 0.0), f"crank{i}")
        model.appendBodyToJoint(crank, pin.Inertia(BAR_MASS, np.array([0.0, BAR_LENGTH / 2, 0.0]),
                                                   np.diag([inertia, 0.0, inertia])), pin.SE3.Identity())
        cranks.append(crank)
        if i < N:
            coupler = model.addJoint(crank, pin.JointModelRZ(), placement(0.0, BAR_LENGTH), f"coupler{i}")
            model.appendBodyToJoint(coupler, pin.Inertia(BAR_MASS, np.array([BAR_LENGTH / 2, 0.0, 0.0]),
                                                         np.diag([0.0, inertia, inertia])), pin.SE3.Identity())
            couplers.append(coupler)
    closures = pin.StdVec_RigidConstraintModel()
    for i in range(N):
        closure = pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, model, couplers[i], placement(BAR_LENGTH, 0.0),
                                           cranks[i + 1], placement(0.0, BAR_LENGTH), pin.ReferenceFrame.LOCAL)
        closure.setBaumgarteCorrectorParameters(pin.BaumgarteCorrectorParameters(*baumgarte))
        closures.append(closure)
    return model, closures, cranks


def pinocchio_b0(N: int, t_end: float, scheme: str, mu: float,
                 baumgarte: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, float]:
    """(times, B0 (k, 2), wall seconds of the stepping) of A02 in Pinocchio, fixed step STEP.

    Semi-implicit Euler: v += h a(q, v), q = integrate(q, h v); RK4: the classical four stages on
    (q, v) (the joints are revolute-z, so integrate is q + h v)."""
    import pinocchio as pin
    model, closures, cranks = pinocchio_model(N, baumgarte)
    data = model.createData()
    closure_data = pin.StdVec_RigidConstraintData()
    for closure in closures:
        closure_data.append(closure.createData())
    pin.initConstraintDynamics(model, data, closures, closure_data)
    settings = pin.ProximalSettings(PINOCCHIO_ACCURACY, mu, PINOCCHIO_ITERATIONS)
    tau = np.zeros(model.nv)

    def acceleration(q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return pin.constraintDynamics(model, data, q, v, tau, closures, closure_data, settings).copy()

    def b0_of(q: np.ndarray) -> np.ndarray:
        pin.forwardKinematics(model, data, q)
        return data.oMi[cranks[0]].act(np.array([0.0, BAR_LENGTH, 0.0]))[:2].copy()

    def step(q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if scheme == "semi-implicit Euler":
            v = v + STEP * acceleration(q, v)
            return pin.integrate(model, q, STEP * v), v
        k1 = acceleration(q, v)
        k2 = acceleration(pin.integrate(model, q, STEP / 2 * v), v + STEP / 2 * k1)
        k3 = acceleration(pin.integrate(model, q, STEP / 2 * (v + STEP / 2 * k1)), v + STEP / 2 * k2)
        k4 = acceleration(pin.integrate(model, q, STEP * (v + STEP / 2 * k2)), v + STEP * k3)
        dq = v + STEP / 6 * (k1 + k2 + k3)     # (v1 + 2 v2 + 2 v3 + v4)/6 with v_j = v + c_j h k_{j-1}
        return pin.integrate(model, q, STEP * dq), v + STEP / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    q = pin.neutral(model)
    v = np.zeros(model.nv)
    spin = B0_SPEED / BAR_LENGTH
    for i, crank in enumerate(cranks):
        v[model.joints[crank].idx_v] = -spin
        if i < N:
            v[model.joints[crank + 1].idx_v] = spin     # the coupler is added right after its crank
    steps_per_output = int(round(OUTPUT_INTERVAL / STEP))
    times, b0 = [0.0], [b0_of(q)]
    started = time.perf_counter()
    for k in range(int(round(t_end / OUTPUT_INTERVAL))):
        for _ in range(steps_per_output):
            q, v = step(q, v)
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
            break
        times.append((k + 1) * OUTPUT_INTERVAL)
        b0.append(b0_of(q))
    wall = time.perf_counter() - started
    return np.asarray(times), np.asarray(b0), wall


def error_at_outputs(times: np.ndarray, b0: np.ndarray, N: int) -> float:
    """max |B0 - exact| over the samples at multiples of OUTPUT_INTERVAL (inf if not finite)."""
    on_grid = np.abs(times / OUTPUT_INTERVAL - np.round(times / OUTPUT_INTERVAL)) < 1e-6
    exact, _ = exact_b0(times[on_grid], N)
    distance = np.hypot(*(b0[on_grid] - exact).T)
    return float(distance.max()) if np.all(np.isfinite(distance)) else float("inf")


def tool_result(tool: str, method: str, N: int, t_end: float, run: tuple[np.ndarray, np.ndarray, float]) -> dict[str, object]:
    """The row of one tool's run (times, B0, wall): time reached, max |B0 - exact|, HP, wall."""
    times, b0, wall = run
    error = error_at_outputs(times, b0, N)
    return {"tool": tool, "method": method, "t_reached": float(times[-1]), "b0_error": error,
            "first_miss": first_miss(times, b0, N),
            "high_precision": bool(times[-1] >= t_end - 1e-9 and error <= HIGH_PRECISION), "wall": wall}


def first_miss(times: np.ndarray, b0: np.ndarray, N: int) -> float:
    """The first output time at which |B0 - exact| > HIGH_PRECISION (nan: none)."""
    exact, _ = exact_b0(times, N)
    missed = ~(np.hypot(*(b0 - exact).T) <= HIGH_PRECISION)
    return float(times[np.argmax(missed)]) if missed.any() else float("nan")


def measure_exudyn(N: int, t_end: float) -> dict[str, object]:
    exudyn_b0(N, OUTPUT_INTERVAL)
    return tool_result("exudyn", "generalized-alpha (RevoluteJoint2D, rigid bodies)", N, t_end, exudyn_b0(N, t_end))


def measure_mujoco(N: int, t_end: float, integrator: str, softness: str) -> dict[str, object]:
    mujoco_b0(N, OUTPUT_INTERVAL, integrator, softness)
    return tool_result("mujoco", f"{integrator}, equality connect, {softness} solref/solimp", N, t_end,
                       mujoco_b0(N, t_end, integrator, softness))


def measure_pinocchio(N: int, t_end: float, scheme: str, mu: float, baumgarte: tuple[float, float]) -> dict[str, object]:
    pinocchio_b0(N, OUTPUT_INTERVAL, scheme, mu, baumgarte)
    method = f"{scheme}, constraintDynamics mu={mu:g} Kp,Kd={baumgarte[0]:g},{baumgarte[1]:g}"
    return tool_result("pinocchio", method, N, t_end, pinocchio_b0(N, t_end, scheme, mu, baumgarte))


def tool_results(N: int, t_end: float) -> list[dict[str, object]]:
    """The rows of every installed tool other than cmbs."""
    results = [measure_exudyn(N, t_end)] if EXUDYN else []
    if MUJOCO:
        results += [measure_mujoco(N, t_end, *run) for run in MUJOCO_RUNS]
    if PINOCCHIO:
        results += [measure_pinocchio(N, t_end, *run) for run in PINOCCHIO_RUNS]
    return results


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
            "first_miss": first_miss(run.t, b0, N),
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
        print(f"  {'tool':<9} {'method':<62} {'t [s]':>6} {'max|B0 err|':>11} {'>1e-3 at':>8} {'HP':>4} {'wall [s]':>9}")
        results = tool_results(N, args.t_end) + [measure_cmbs(N, args.t_end, options) for options in CMBS_RUNS]
        for result in results:
            print(f"  {result['tool']:<9} {result['method']:<62} {result['t_reached']:6.2f} "
                  f"{result['b0_error']:11.2e} {result['first_miss']:8.2f} {'yes' if result['high_precision'] else 'no':>4} "
                  f"{result['wall']:9.3f}", flush=True)
        for name, installed in (("Exudyn", EXUDYN), ("MuJoCo", MUJOCO), ("Pinocchio", PINOCCHIO)):
            if not installed:
                print(f"  {name} is not installed (pip install -e \".[bench]\"): left out")
        projection = results[-1]
        for result in results[:-len(CMBS_RUNS)]:
            print(f"  wall time of cmbs {projection['method'].split()[0]} / {result['tool']} {result['method']}: "
                  f"{projection['wall'] / result['wall']:.3f}")
        report[str(N)] = results
    write_report(args.json, report)


if __name__ == "__main__":
    main()
