#!/usr/bin/env python
"""Robots from URDF: the UR5 and the Panda of example-robot-data in cmbs beside Pinocchio and
MuJoCo (needs the ``[bench]`` extra: MuJoCo, Pinocchio and example-robot-data).

    python benchmarks/bench_robots.py [--quick] [--plot FILE]
    # about 7 min on 2 shared cores; --quick (about 1 min): short timing batches, no MuJoCo
    # run at h = 1e-5 (the reference is then cross-checked at h = 1e-4), a 1 000-variant sweep

All three tools load the same URDF files (``ur_description/urdf/ur5_robot.urdf``: 6 revolute
joints; ``panda_description/urdf/panda.urdf``: 7 revolute joints and the two prismatic finger
joints, kept as the file has them: 9 coordinates in every tool, ``panda_finger_joint2``'s
``<mimic>`` not applied, so each finger slides on its own).  MuJoCo reads a copy of each file
with its ``<visual>`` and ``<collision>`` elements removed (their meshes are
``package://`` paths; without geometry there is nothing to collide), and the joint damping the
Panda's URDF gives (0.003 and 0.3 N·m·s) set to zero, the joint limits and the mimic equality
disabled (``mjDSBL_LIMIT``, ``mjDSBL_EQUALITY``), contacts disabled: the three tools then have
the same mechanism, the script checks it (the mass matrix at the start state from MuJoCo's
``mj_fullM``, Pinocchio's ``crba`` and cmbs's M; the accelerations and the inverse dynamics at
a state with velocities) and prints the differences.  No armature anywhere (none in the files).
A third model, "Panda, fingers fixed", is a copy of panda.urdf with the two finger joints made
fixed (their ``<mimic>`` removed), read by all three tools: without limits the free fingers
slide off the hand (hundreds of metres in the 10 s runs), the fixed ones stay with it.

1. Per evaluation, called from Python for all, at the start state with joint velocities
   (µs per call: median [min-max] over batches, bench_model.py's ``time_interleaved``: the
   calls' batches in turn, round by round, so that all see the same machine load): forward
   dynamics, cmbs's ``CompiledDynamics(model, "lagrange").into`` (one compiled call: M by CRBA,
   Q by RNEA, Cholesky solve of M q̈ = Q) against Pinocchio's ``aba`` and MuJoCo's
   ``mj_forward``; inverse dynamics, τ = M q̈ - Q through the same kernel (one compiled call
   defined here: ``evaluate_terms`` then the product; cmbs has no O(n) inverse dynamics of trees)
   against ``pinocchio.rnea`` and ``mj_inverse``.  Ratios cmbs / other.
2. Whole 10 s runs of each robot falling freely from a bent start at rest (zero torques): cmbs
   compiled RK4 at h = 1e-3 and 1e-4 and DOP853 at rtol 1e-4 ... 1e-10 (atol = rtol / 100);
   MuJoCo RK4, Euler (its default) and implicitfast at h = 1e-3 and 1e-4 (``mj_step`` with ``nstep`` steps
   per output of 0.01 s).  Error: max over the 1 001 outputs and the revolute joints of
   |q - q_ref| (rad) against cmbs's DOP853 at rtol 1e-12 (atol 1e-14), cross-checked against
   MuJoCo's RK4 at h = 1e-5; the energy error |E(10 s) - E(0)| (J, each tool's own energy).
   Then for each accuracy level 1e-2 ... 1e-8 rad each tool's least wall time to reach it.
3. A sweep of the UR5: 10 000 start states (the start joint angles plus uniform offsets in
   ±0.5 rad, at rest; 1 s at RK4 h = 1e-3, 1 000 steps), cmbs's ``cmbs.sweep`` (state-only
   variants: one compiled call over numba's threads) against ``mujoco.rollout.rollout`` of the
   same states (its threads: one MjData per thread), on one thread and on numba's threads (the
   CPUs), variants × steps per second of wall time and of CPU time (the process's, all threads).

Wall times: one run after a warm-up, the least of three for runs shorter than 0.5 s, on a machine
that may be shared: the load average is printed with them.
"""

from __future__ import annotations

import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse  # noqa: E402
import importlib.metadata  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import xml.etree.ElementTree as ElementTree  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import cmbs  # noqa: E402
from cmbs.dynamics.field import Bound, CompiledDynamics  # noqa: E402
from cmbs.jit import njit  # noqa: E402
from cmbs.model.compiled import model_kernel  # noqa: E402
from cmbs.model.robot_kernel import evaluate_terms  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_model import fmt, time_interleaved  # noqa: E402

#: URDF file under example-robot-data's robots/, the start angles (rad; m for the fingers)
#: (0.25-0.8 rad from the hanging rest [0, π/2, 0, -π/2, 0, 0] of the UR5 and
#: [0, 2.92, -0.02, -0.50, 0.72, 2.42, 0.55] of the Panda, with the finger axis level there:
#: large, but regular motions, whose errors do not grow exponentially over the 10 s), and the
#: joints made fixed in a copy of the file for the Panda's second variant
ROBOTS = {
    "UR5": dict(file="ur_description/urdf/ur5_robot.urdf", q0=[0.8, 0.83, 0.67, -2.18, 0.54, -0.48]),
    "Panda": dict(file="panda_description/urdf/panda.urdf",
                  q0=[0.5, 3.17, -0.02, -0.25, 0.72, 2.67, 0.55, 0.02, 0.02]),
    "Panda, fingers fixed": dict(file="panda_description/urdf/panda.urdf",
                                 q0=[0.5, 3.17, -0.02, -0.25, 0.72, 2.67, 0.55],
                                 fixed=("panda_finger_joint1", "panda_finger_joint2")),
}
T_END, OUTPUT = 10.0, 0.01
DOP853_RTOLS, REFERENCE_RTOL = (1e-4, 1e-6, 1e-8, 1e-10), 1e-12
#: runs shorter than SHORT s are timed SHORT_REPEAT times, the least wall time kept
SHORT, SHORT_REPEAT = 0.5, 3
LEVELS = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8)
SWEEP_T_END, SWEEP_H, SWEEP_SPREAD = 1.0, 1e-3, 0.5


def urdf_path(robot: str) -> Path:
    distribution = importlib.metadata.distribution("example-robot-data")
    return Path(str(distribution.locate_file("cmeel.prefix/share/example-robot-data/robots"))) / ROBOTS[robot]["file"]


def without_geometry(path: Path, directory: str, fixed: tuple[str, ...] = ()) -> str:
    """A copy of the URDF without ``<visual>`` and ``<collision>`` elements (MuJoCo would look
    for their ``package://`` meshes), the joints ``fixed`` made fixed (their ``<mimic>``
    removed); inertias and the other joints as they are."""
    tree = ElementTree.parse(path)
    for link in tree.getroot().iter("link"):
        for tag in ("visual", "collision"):
            for element in link.findall(tag):
                link.remove(element)
    for joint in tree.getroot().iter("joint"):
        if joint.get("name") in fixed:
            joint.set("type", "fixed")
            for element in joint.findall("mimic"):
                joint.remove(element)
    copy = os.path.join(directory, ("fixed-" if fixed else "") + path.name)
    tree.write(copy)
    return copy


@njit(cache=True)
def _inverse_at(bound, q, qd, qdd, u, tau):
    """τ = M q̈ - Q (Q = u - C q̇ - g) by the robot kernel's CRBA and RNEA: one compiled call."""
    k, buf = bound.model, bound.buffer
    evaluate_terms(k.parent, k.order, k.kind, k.placement, k.axis, k.inertia, k.gravity, q, qd, u, buf)
    n = q.shape[0]
    for i in range(n):
        value = -buf[i]
        row = n + i * n
        for j in range(n):
            value += buf[row + j] * qdd[j]
        tau[i] = value


@njit(cache=True)
def _terms_at(bound, q, qd, u):
    """M and Q alone (the part of both calls above that is the robot kernel), for the breakdown."""
    k = bound.model
    evaluate_terms(k.parent, k.order, k.kind, k.placement, k.axis, k.inertia, k.gravity, q, qd, u, bound.buffer)


class Robot:
    """One URDF in the three tools, and its start state."""

    def __init__(self, name: str, directory: str):
        import mujoco
        import pinocchio

        self.name, self.mj, self.pin = name, mujoco, pinocchio
        path, fixed = urdf_path(name), ROBOTS[name].get("fixed", ())
        mj_path = without_geometry(path, directory, fixed)
        if fixed:        # every tool reads the changed copy
            path = Path(mj_path)
        self.model = cmbs.load(str(path))
        self.n = self.model.n
        self.q0 = np.array(ROBOTS[name]["q0"], dtype=float)
        self.revolute = np.array([joint.type != "prismatic" for joint in self.model.equations.joints])
        self.pin_model = pinocchio.buildModelFromUrdf(str(path))
        self.pin_data = self.pin_model.createData()
        self.mj_model = mujoco.MjModel.from_xml_path(mj_path)
        m = self.mj_model
        m.dof_damping[:] = 0.0
        m.opt.disableflags |= (mujoco.mjtDisableBit.mjDSBL_LIMIT | mujoco.mjtDisableBit.mjDSBL_EQUALITY
                               | mujoco.mjtDisableBit.mjDSBL_CONTACT)
        self.mj_data = mujoco.MjData(m)
        names = self.model.coordinate_names
        assert [m.joint(i).name for i in range(m.njnt)] == list(names), "MuJoCo's joint order is not the file's"
        assert [self.pin_model.names[i] for i in range(1, self.pin_model.njoints)] == list(names)
        assert m.nq == m.nv == self.pin_model.nq == self.pin_model.nv == self.n
        assert not m.dof_armature.any() and not m.dof_frictionloss.any() and not m.jnt_stiffness.any()

    # -------------------------------------------------------------------- MuJoCo state and energy
    def mj_set(self, q, qd) -> None:
        mj, m, d = self.mj, self.mj_model, self.mj_data
        mj.mj_resetData(m, d)
        d.qpos[:], d.qvel[:] = q, qd
        mj.mj_forward(m, d)

    def mj_energy(self) -> float:
        mj, m, d = self.mj, self.mj_model, self.mj_data
        m.opt.enableflags |= mj.mjtEnableBit.mjENBL_ENERGY
        mj.mj_forward(m, d)
        m.opt.enableflags &= ~int(mj.mjtEnableBit.mjENBL_ENERGY)
        return float(d.energy[0] + d.energy[1])

    def configure(self, integrator: str, h: float) -> None:
        self.mj_model.opt.timestep = h
        self.mj_model.opt.integrator = getattr(self.mj.mjtIntegrator, f"mjINT_{integrator.upper()}")

    # --------------------------------------------------------------------------- the same mechanism
    def agreement(self, rng: np.random.Generator) -> dict[str, float]:
        """Differences between the tools at the start state (M) and at a state with velocities
        (q̈ from rest of the inputs, τ of a q̈): max abs, with the size of the compared values."""
        mj, pin, m, d = self.mj, self.pin, self.mj_model, self.mj_data
        q, qd, qdd = self.q0, rng.uniform(-1.0, 1.0, self.n), rng.uniform(-1.0, 1.0, self.n)
        terms = self.model.evaluate(q, np.zeros(self.n), 0.0, np.zeros(self.n))
        M_cmbs = np.array(terms.M)
        M_pin = pin.crba(self.pin_model, self.pin_data, q)
        M_pin = np.triu(M_pin) + np.triu(M_pin, 1).T
        self.mj_set(q, np.zeros(self.n))
        M_mj = np.zeros((self.n, self.n))
        mj.mj_fullM(m, d, M_mj)
        a_cmbs = CompiledDynamics(self.model, "lagrange").accelerations(q, qd)[0]
        a_pin = pin.aba(self.pin_model, self.pin_data, q, qd, np.zeros(self.n))
        self.mj_set(q, qd)
        a_mj = d.qacc.copy()
        tau_cmbs = np.empty(self.n)
        _inverse_at(self.bound(), q, qd, qdd, np.zeros(self.n), tau_cmbs)
        tau_pin = pin.rnea(self.pin_model, self.pin_data, q, qd, qdd)
        d.qacc[:] = qdd
        mj.mj_inverse(m, d)
        tau_mj = d.qfrc_inverse.copy()
        self.mj_set(q, np.zeros(self.n))
        E_mj = self.mj_energy()
        E_cmbs = float(self.model.energy_history(q[None], np.zeros((1, self.n)))[0])
        return {"|M|": np.abs(M_cmbs).max(), "M cmbs-Pinocchio": np.abs(M_cmbs - M_pin).max(),
                "M cmbs-MuJoCo": np.abs(M_cmbs - M_mj).max(), "|q̈|": np.abs(a_cmbs).max(),
                "q̈ cmbs-Pinocchio": np.abs(a_cmbs - a_pin).max(), "q̈ cmbs-MuJoCo": np.abs(a_cmbs - a_mj).max(),
                "|τ|": np.abs(tau_cmbs).max(), "τ cmbs-Pinocchio": np.abs(tau_cmbs - tau_pin).max(),
                "τ cmbs-MuJoCo": np.abs(tau_cmbs - tau_mj).max(), "E0 cmbs-MuJoCo": abs(E_cmbs - E_mj)}

    def bound(self) -> Bound:
        """The robot's kernel tuple and a terms buffer as one object for :func:`_inverse_at`
        (the formulation slot is unused)."""
        return Bound(model_kernel(self.model), np.zeros(0), self.model.new_terms().buffer)

    # ------------------------------------------------------------------------------ per evaluation
    def per_evaluation(self, repeat: int, target: float, rng: np.random.Generator) -> dict[str, dict]:
        mj, pin, m, d = self.mj, self.pin, self.mj_model, self.mj_data
        q, qd, qdd = self.q0.copy(), rng.uniform(-1.0, 1.0, self.n), rng.uniform(-1.0, 1.0, self.n)
        tau, out, lam, u = np.zeros(self.n), np.empty(self.n), np.empty(0), np.zeros(self.n)
        compiled, bound = CompiledDynamics(self.model, "lagrange"), self.bound()
        pm, pd = self.pin_model, self.pin_data
        self.mj_set(q, qd)
        d_inverse = mj.MjData(m)                 # its own data: mj_forward writes d.qacc
        d_inverse.qpos[:], d_inverse.qvel[:], d_inverse.qacc[:] = q, qd, qdd
        calls = {"forward: cmbs CompiledDynamics.into": lambda: compiled.into(q, qd, 0.0, None, out, lam),
                 "forward: Pinocchio aba": lambda: pin.aba(pm, pd, q, qd, tau),
                 "forward: MuJoCo mj_forward": lambda: mj.mj_forward(m, d),
                 "terms: cmbs M and Q alone (one call)": lambda: _terms_at(bound, q, qd, u),
                 "inverse: cmbs M q̈ - Q (one call)": lambda: _inverse_at(bound, q, qd, qdd, u, out),
                 "inverse: Pinocchio rnea": lambda: pin.rnea(pm, pd, q, qd, qdd),
                 "inverse: MuJoCo mj_inverse": lambda: mj.mj_inverse(m, d_inverse)}
        times = time_interleaved(calls, repeat, target)
        return times

    # -------------------------------------------------------------------------------- whole runs
    def cmbs_run(self, integrator: str, **settings) -> dict:
        """cmbs from q0 at rest for T_END s, outputs every OUTPUT s: joint angles, wall, |ΔE|."""
        zero = np.zeros(self.n)
        if integrator == "rk4":
            settings = dict(dt=settings["h"], every=int(round(OUTPUT / settings["h"])))
        else:
            settings = dict(dt=OUTPUT, rtol=settings["rtol"], atol=settings["rtol"] / 100)
        common = dict(formulation="lagrange", integrator=integrator, q0=self.q0, qd0=zero, **settings)
        cmbs.simulate(self.model, t_end=0.1, **common)       # warm-up: compiles or loads the loop
        walls = []
        while not walls or (len(walls) < SHORT_REPEAT and max(walls) < SHORT):
            start = time.perf_counter()
            run = cmbs.simulate(self.model, t_end=T_END, **common)
            walls.append(time.perf_counter() - start)
        wall = min(walls)
        energy = self.model.energy_history(run.q[[0, -1]], run.qd[[0, -1]])
        return dict(q=run.q, wall=wall, dE=abs(energy[1] - energy[0]))

    def mujoco_run(self, integrator: str, h: float) -> dict:
        mj, m, d = self.mj, self.mj_model, self.mj_data
        self.configure(integrator, h)
        per_output = int(round(OUTPUT / h))
        zero = np.zeros(self.n)
        self.mj_set(self.q0, zero)
        E0 = self.mj_energy()
        mj.mj_step(m, d, nstep=per_output)                    # warm-up
        rows = np.empty((int(round(T_END / OUTPUT)) + 1, self.n))
        step, walls = mj.mj_step, []
        while not walls or (len(walls) < SHORT_REPEAT and max(walls) < SHORT):
            self.mj_set(self.q0, zero)
            rows[0] = d.qpos
            start = time.perf_counter()
            for k in range(1, rows.shape[0]):
                step(m, d, nstep=per_output)
                rows[k] = d.qpos
            walls.append(time.perf_counter() - start)
        return dict(q=rows, wall=min(walls), dE=abs(self.mj_energy() - E0))

    def error(self, q: np.ndarray, reference: np.ndarray) -> float:
        """max over the outputs and the revolute joints of |q - q_ref| (rad); nan for a run that
        diverged."""
        if q.shape != reference.shape or not np.all(np.isfinite(q)):
            return float("nan")
        return float(np.abs(q[:, self.revolute] - reference[:, self.revolute]).max())


# ------------------------------------------------------------------------------------- the sweep
def sweep_states(robot: Robot, count: int) -> np.ndarray:
    rng = np.random.default_rng(2026)
    return robot.q0 + rng.uniform(-SWEEP_SPREAD, SWEEP_SPREAD, (count, robot.n))


def cmbs_sweep(robot: Robot, Q0: np.ndarray) -> tuple[float, np.ndarray, dict]:
    """cmbs.sweep of the start states Q0 (at rest), RK4: wall and CPU time (the process's, all
    threads), the end angles and the sweep's info."""
    steps = int(round(SWEEP_T_END / SWEEP_H))
    variants = [cmbs.Variant(q0=q, qd0=np.zeros(robot.n)) for q in Q0]
    options = dict(t_end=SWEEP_T_END, integrator="rk4", dt=SWEEP_H, every=steps, formulation="lagrange")
    cmbs.sweep(robot.model, variants[:8], **options)          # warm-up: compiles or loads the batch loop
    start, cpu = time.perf_counter(), time.process_time()
    result = cmbs.sweep(robot.model, variants, **options)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    assert result.info["mode"] == "batched", result.info["mode"]
    return wall, cpu, result.q[:, -1, :], result.info


def mujoco_sweep(robot: Robot, Q0: np.ndarray, threads: int, chunk: int = 1000) -> tuple[float, float, np.ndarray]:
    """mujoco.rollout.rollout of the same start states, RK4 at SWEEP_H, ``threads`` MjData, in
    chunks of ``chunk`` states (its output holds every step's state): wall and CPU time (the
    process's, all threads) and the end angles."""
    from mujoco import rollout

    mj, m = robot.mj, robot.mj_model
    robot.configure("rk4", SWEEP_H)
    steps = int(round(SWEEP_T_END / SWEEP_H))
    spec = mj.mjtState.mjSTATE_FULLPHYSICS
    d = mj.MjData(m)
    size = mj.mj_stateSize(m, spec)
    initial = np.empty((Q0.shape[0], size))
    for k, q in enumerate(Q0):
        mj.mj_resetData(m, d)
        d.qpos[:] = q
        mj.mj_getState(m, d, initial[k], spec)
    datas = [mj.MjData(m) for _ in range(threads)]
    out = np.empty((min(chunk, Q0.shape[0]), steps, size))
    rollout.rollout(m, datas, initial[:8], nstep=steps, state=out[:8])      # warm-up
    end = np.empty((Q0.shape[0], robot.n))
    qpos = slice(1, 1 + m.nq)          # FULLPHYSICS: time, qpos, qvel, ...
    start, cpu = time.perf_counter(), time.process_time()
    for a in range(0, Q0.shape[0], chunk):
        b = min(a + chunk, Q0.shape[0])
        rollout.rollout(m, datas, initial[a:b], nstep=steps, state=out[:b - a])
        end[a:b] = out[:b - a, -1, qpos]
    return time.perf_counter() - start, time.process_time() - cpu, end


# ------------------------------------------------------------------------------------- printing
def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def cell(row: dict | None) -> str:
    return "not reached" if row is None else f"{row['wall']:.3g} s ({row['label']})"


def print_levels(robot: str, rows: list[dict]) -> None:
    print(f"\n{robot}: least wall time to reach each accuracy (max joint-angle error vs the reference)")
    print(f"  {'level rad':<10}{'cmbs':>28}{'MuJoCo':>34}   cmbs / MuJoCo")
    for level in LEVELS:
        best = {}
        for tool in ("cmbs", "MuJoCo"):
            reaching = [row for row in rows if row["tool"] == tool and row["error"] <= level]
            best[tool] = min(reaching, key=lambda row: row["wall"]) if reaching else None
        cells = "".join(f"{cell(row):>{width}}" for row, width in ((best["cmbs"], 28), (best["MuJoCo"], 34)))
        ratio = (f"{best['cmbs']['wall'] / best['MuJoCo']['wall']:.2f}" if best["cmbs"] and best["MuJoCo"] else
                 "only cmbs" if best["cmbs"] else "only MuJoCo" if best["MuJoCo"] else "-")
        print(f"  {level:<10.0e}{cells}   {ratio}")


def plot(path: str, tables: dict[str, list[dict]]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, len(tables), figsize=(6 * len(tables), 4.5))
    for axis, (robot, rows) in zip(np.atleast_1d(axes), tables.items()):
        for row in rows:
            if not np.isfinite(row["error"]):
                continue
            axis.loglog(row["wall"], max(row["error"], 1e-12), "o" if row["tool"] == "cmbs" else "s",
                        color="C0" if row["tool"] == "cmbs" else "C1")
            axis.annotate(row["label"], (row["wall"], max(row["error"], 1e-12)), fontsize=6)
        axis.set(xlabel="wall time [s]", ylabel="max joint-angle error [rad]", title=f"{robot}, {T_END:g} s free fall")
        axis.grid(True, which="both", alpha=0.3)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    print(f"figure -> {path}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true",
                        help="short timing batches, no MuJoCo run at h = 1e-5, 1 000 sweep variants")
    parser.add_argument("--plot", metavar="FILE", help="write the work-precision figure (matplotlib)")
    parser.add_argument("--variants", type=int, help="sweep variants (default 10 000, 1 000 with --quick)")
    args = parser.parse_args()
    import mujoco
    import numba
    import pinocchio

    began = time.perf_counter()
    repeat, target = (3, 0.05) if args.quick else (7, 0.2)
    variants = args.variants or (1000 if args.quick else 10000)
    threads = numba.get_num_threads()
    print(f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; {platform.processor() or platform.machine()}, "
          f"{threads} CPUs; load average {load()}")
    print(f"cmbs {cmbs.__version__}, MuJoCo {mujoco.__version__}, Pinocchio {pinocchio.__version__}, "
          f"example-robot-data {importlib.metadata.version('example-robot-data')}; 1 BLAS thread; "
          "all called from Python")
    directory = tempfile.mkdtemp(prefix="cmbs-robots-")
    robots = {name: Robot(name, directory) for name in ROBOTS}
    rng = np.random.default_rng(7)

    print("\n== the same mechanism in the three tools (max abs differences)")
    for name, robot in robots.items():
        agreement = robot.agreement(rng)
        print(f"{name} (n = {robot.n}): " + ", ".join(f"{key} {value:.1e}" for key, value in agreement.items()))

    print("\n== per evaluation, µs per call from Python: median [min-max]; ratio cmbs / other (load "
          f"{load()})")
    for name, robot in robots.items():
        times = robot.per_evaluation(repeat, target, rng)
        print(f"{name}:")
        for label, stats in times.items():
            kind = label.split(":")[0]
            if kind == "terms":
                print(f"  {label:<40} {fmt(stats):>22}")
                continue
            mine = next(v for k, v in times.items() if k.startswith(f"{kind}: cmbs"))
            ratio = "" if "cmbs" in label else f"   cmbs / it {mine['median'] / stats['median']:.2f}"
            print(f"  {label:<40} {fmt(stats):>22}{ratio}")

    tables = {}
    for name, robot in robots.items():
        print(f"\n== {name}: {T_END:g} s free fall from q0 = {ROBOTS[name]['q0']} at rest (load {load()})")
        reference = robot.cmbs_run("dop853", rtol=REFERENCE_RTOL)
        check_h = 1e-4 if args.quick else 1e-5
        check = robot.mujoco_run("rk4", check_h)
        print(f"reference cmbs DOP853 rtol {REFERENCE_RTOL:g}: {reference['wall']:.3g} s, "
              f"|ΔE| {reference['dE']:.1e} J; "
              f"MuJoCo RK4 h = {check_h:g} ({check['wall']:.3g} s) differs from it by "
              f"{robot.error(check['q'], reference['q']):.1e} rad")
        rows = [dict(tool="cmbs", label=f"RK4 h={h:g}", **robot.cmbs_run("rk4", h=h)) for h in (1e-3, 1e-4)]
        rows += [dict(tool="cmbs", label=f"DOP853 rtol {rtol:g}", **robot.cmbs_run("dop853", rtol=rtol))
                 for rtol in DOP853_RTOLS]
        for integrator in ("rk4", "euler", "implicitfast"):
            for h in (1e-3, 1e-4):
                rows.append(dict(tool="MuJoCo", label=f"{integrator} h={h:g}", **robot.mujoco_run(integrator, h)))
        if check_h not in (1e-3, 1e-4):
            rows.append(dict(tool="MuJoCo", label=f"rk4 h={check_h:g}", **check))
        print(f"  {'run':<28} {'wall s':>8} {'max error rad':>14} {'|ΔE| end J':>11}")
        for row in sorted(rows, key=lambda r: r["wall"]):
            row["error"] = robot.error(row["q"], reference["q"])
            print(f"  {row['tool'] + ' ' + row['label']:<28} {row['wall']:>8.3g} {row['error']:>14.2e} "
                  f"{row['dE']:>11.1e}")
        same = {row["tool"] + row["label"].lower(): row["wall"] for row in rows}
        print("  same method, cmbs RK4 / MuJoCo RK4 wall: " + ", ".join(
            f"h = {h:g} {same[f'cmbsrk4 h={h:g}'] / same[f'MuJoCork4 h={h:g}']:.2f}" for h in (1e-3, 1e-4)))
        prismatic = ~robot.revolute
        if prismatic.any():
            reach = np.abs(reference["q"][:, prismatic]).max()
            print(f"  (prismatic joints, not in the errors: |q| up to {reach:.3g} m "
                  "in the reference run)")
        print_levels(name, rows)
        tables[name] = rows

    robot = robots["UR5"]
    Q0 = sweep_states(robot, variants)
    steps = int(round(SWEEP_T_END / SWEEP_H))
    print(f"\n== sweep: UR5, {variants} start states (q0 ± {SWEEP_SPREAD} rad, at rest), {SWEEP_T_END:g} s at "
          f"RK4 h = {SWEEP_H:g} ({steps} steps), on 1 and {threads} threads (load {load()})")
    rate = variants * steps
    print(f"  {'':<40} {'wall s':>8} {'variant-steps/s':>16} {'CPU s':>8} {'per CPU s':>10}")
    for used in sorted({1, threads}):
        numba.set_num_threads(used)
        wall_cmbs, cpu_cmbs, end_cmbs, info = cmbs_sweep(robot, Q0)
        wall_mj, cpu_mj, end_mj = mujoco_sweep(robot, Q0, used)
        for label, wall, cpu in ((f"cmbs.sweep (batched, {info['workers']} numba threads)", wall_cmbs, cpu_cmbs),
                                 (f"mujoco.rollout ({used} MjData)", wall_mj, cpu_mj)):
            print(f"  {label:<40} {wall:>8.3g} {rate / wall:>16.3g} {cpu:>8.3g} {rate / cpu:>10.3g}")
        print(f"  {used} thread(s), cmbs / MuJoCo: wall {wall_cmbs / wall_mj:.2f}, CPU {cpu_cmbs / cpu_mj:.2f}; max "
              f"end-angle difference between the two {np.abs(end_cmbs - end_mj).max():.1e} rad (load {load()})")
    numba.set_num_threads(threads)
    if args.plot:
        plot(args.plot, tables)
    print(f"\nwhole benchmark: {time.perf_counter() - began:.0f} s; load average {load()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
