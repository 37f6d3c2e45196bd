#!/usr/bin/env python
"""The spatial mechanisms Bricard (IFToMM A04) and the spatial slider-crank in MuJoCo beside cmbs
(and Exudyn): µs per forward-dynamics evaluation, and whole runs at equal accuracy (needs the
``[bench]`` extra for MuJoCo; Exudyn is optional).

    python benchmarks/bench_spatial_mujoco.py [--quick] [--plot FILE]   # about 2 min; --quick: no h = 1e-5

MuJoCo models (MJCF below, written from the cmbs models' docstrings; the script checks that the
start energy equals cmbs's):

* Bricard: the open chain ground-rod0-...-rod4 of five hinges (axes y, z, x, y, z at P0-P4, body
  frames parallel to the ground's at the start, each rod's box inertia as ``fullinertia``), gravity
  along -y, from rest.  The sixth revolute joint (rod4 to the ground at P5, axis x) is two
  ``connect`` equalities, at P5 and at P5 + 1 m · x: six rows for a joint of five, and the
  mechanism's own redundancy on top (MuJoCo's soft constraints take redundant rows).
* Slider-crank: crank hinged about x at A; the slider on a ``slide`` joint along x; the rod a child
  of the slider through the universal joint, two hinges in one body (x, then the rod-fixed
  e1 = (0, 2, -1)/√5: x · e1 = 0 holds exactly in the tree).  The spherical joint at B closes the
  loop: one ``connect`` (crank end = rod end).  The crank starts at 6 rad/s; the other joint
  velocities solve the connect's velocity rows.

MuJoCo's constraints are soft.  Each run uses Newton's solver (tolerance 1e-12, 100 iterations),
no contact, no friction loss, no damping or armature, and the stiffest softness MuJoCo takes at the
step: solref (2h, 1) (time constant 2h, the smallest allowed with ``refsafe``), solimp
(0.9999, 0.9999, 0.001, 0.5, 2) (0.9999 is its largest impedance); RK4 at h = 3e-3, 1e-3, 1e-4, 1e-5
and implicitfast (its recommended integrator) at 1e-4.  One RK4 row at h = 1e-3 keeps
MuJoCo's default softness (solref 0.02 1, solimp 0.9 0.95 0.001).

Per evaluation (µs per call at the start state, the method of bench_model.py's ``time_call``): cmbs's
``CompiledDynamics(model, formulation).into`` (model terms and solve in one compiled call, as
bench_dynamics.py times it) against ``mj_forward``, and ``mj_step`` at h = 1e-4 (RK4: four
evaluations; the state moves on from call to call).  Exudyn is timed per step only (wall / steps
of its h = 1e-3 run, Newton iterations included, by the functions of bench_bricard.py and
bench_slider_crank_3d.py).

cmbs: Bricard with the projection formulation (its A has a redundant row: Lagrange is singular;
the projection solves without an SVD where it certifies the row dependent,
cmbs.dynamics.dependent_rows), the slider-crank with Lagrange; both with DOP853 at rtol 1e-5,
1e-7, 1e-9, 1e-11 (atol = rtol / 100) and compiled RK4 at h = 1e-3 and 1e-4 (drift projection
after each step).  Errors: max |P3 - P3_ref| over the 201 outputs
(tests/data/bricard-exudyn-p3.csv, Exudyn at h = 1e-4: ~1e-7 m from converged) and max |x - x_ref|
of the slider over the 501 outputs (tests/data/slider-crank-3d-exudyn.csv, Exudyn at h = 5e-5:
~1e-7 m); "vs converged": the same against cmbs's DOP853 at rtol 1e-13, which resolves errors
below the files' accuracy (it is itself within the files' ~1e-7 m of them, the "max error" of
the finest runs); the end energy error |E(t_end) - E0| and the end constraint violation (MuJoCo:
distance between the connected points; cmbs: max |Φ|).  Then, for each accuracy level 1e-3 ...
1e-9 against the converged run, each tool's least wall time to reach it and cmbs's ratio to the
fastest other.  Wall times are single runs after a warm-up, on a machine that may be shared.
"""

from __future__ import annotations

import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse  # noqa: E402
import importlib.util  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import cmbs  # noqa: E402
from cmbs.dynamics.field import CompiledDynamics  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_model import fmt, time_call  # noqa: E402

DATA = Path(__file__).resolve().parent.parent / "tests" / "data"
AXIS_ARM = 1.0          # Bricard: distance along x between the two connect points of the last revolute joint
STIFF_SOLIMP = "0.9999 0.9999 0.001 0.5 2"
DEFAULT_SOFTNESS = ("0.02 1", "0.9 0.95 0.001 0.5 2")


def _v(vector) -> str:
    return " ".join(f"{float(x)!r}" for x in vector)


def _full_inertia(matrix: np.ndarray) -> str:
    """MJCF ``fullinertia``: ixx iyy izz ixy ixz iyz."""
    return _v([matrix[0, 0], matrix[1, 1], matrix[2, 2], matrix[0, 1], matrix[0, 2], matrix[1, 2]])


def _mjcf(name: str, gravity: str, world: str, equality: str) -> str:
    """MJCF with the accuracy options; timestep, integrator and softness are set on the model later."""
    return (f'<mujoco model="{name}"><compiler angle="radian"/>'
            f'<option gravity="{gravity}" solver="Newton" iterations="100" tolerance="1e-12" ls_iterations="50">'
            '<flag contact="disable" frictionloss="disable" energy="enable"/></option>'
            f"<worldbody>{world}</worldbody><equality>{equality}</equality></mujoco>")


def bricard_xml() -> str:
    """Bricard's mechanism: five hinged rods from P0, the joint at P5 as two connects."""
    from cmbs.library.spatial import BRICARD_AXES, BRICARD_POINTS

    points = np.array(BRICARD_POINTS)
    side, length, mass = 0.1, 1.0, 1.0
    moments = mass / 12.0 * np.array([2.0 * side**2, length**2 + side**2, length**2 + side**2])
    chain = ""
    for k in range(5):
        along = points[k + 1] - points[k]
        frame = np.column_stack([along, BRICARD_AXES[k], np.cross(along, BRICARD_AXES[k])])
        origin = points[k] - (points[k - 1] if k else np.zeros(3))
        chain += (f'<body name="rod{k}" pos="{_v(origin)}"><joint type="hinge" axis="{_v(BRICARD_AXES[k])}"/>'
                  f'<inertial pos="{_v(0.5 * along)}" mass="{mass}" '
                  f'fullinertia="{_full_inertia(frame @ np.diag(moments) @ frame.T)}"/>')
    arm = np.array([AXIS_ARM, 0.0, 0.0])
    chain += f'<site name="end" pos="{_v(along)}"/><site name="end_x" pos="{_v(along + arm)}"/>' + "</body>" * 5
    world = f'<site name="P5" pos="{_v(points[5])}"/><site name="P5_x" pos="{_v(points[5] + arm)}"/>' + chain
    return _mjcf("bricard", "0 -9.81 0", world,
                 '<connect site1="end" site2="P5"/><connect site1="end_x" site2="P5_x"/>')


def slider_crank_xml() -> str:
    """The spatial slider-crank: crank and slider-universal-rod branches, the spherical joint a connect."""
    A, B, C = np.array([0.0, 0.1, 0.12]), np.array([0.0, 0.1, 0.20]), np.array([0.2, 0.0, 0.0])
    along = (C - B) / np.linalg.norm(C - B)
    e1 = np.array([0.0, 2.0, -1.0]) / math.sqrt(5.0)
    rod_frame = np.column_stack([along, e1, np.cross(along, e1)])
    world = (f'<body name="crank" pos="{_v(A)}"><joint name="crank" type="hinge" axis="1 0 0"/>'
             f'<inertial pos="{_v(0.5 * (B - A))}" mass="0.12" diaginertia="1e-4 1e-4 1e-5"/>'
             f'<site name="B_crank" pos="{_v(B - A)}"/></body>'
             f'<body name="slider" pos="{_v(C)}"><joint name="slider" type="slide" axis="1 0 0"/>'
             '<inertial pos="0 0 0" mass="2" diaginertia="1e-4 1e-4 1e-4"/>'
             f'<body name="rod"><joint name="u_x" type="hinge" axis="1 0 0"/>'
             f'<joint name="u_e1" type="hinge" axis="{_v(e1)}"/>'
             f'<inertial pos="{_v(0.5 * (B - C))}" mass="0.5" '
             f'fullinertia="{_full_inertia(rod_frame @ np.diag([4e-4, 4e-3, 4e-3]) @ rod_frame.T)}"/>'
             f'<site name="B_rod" pos="{_v(B - C)}"/></body></body>')
    return _mjcf("spatial-slider-crank", "0 0 -9.81", world, '<connect site1="B_crank" site2="B_rod"/>')


def _site_jacobian(mujoco, model, data, site: str) -> np.ndarray:
    jacp = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jacp, None, mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, site))
    return jacp


class MujocoMechanism:
    """A MuJoCo model of one mechanism, its start state, the compared quantity and the loop gap."""

    def __init__(self, name: str):
        import mujoco

        self.mj, self.name = mujoco, name
        self.model = mujoco.MjModel.from_xml_string(bricard_xml() if name == "bricard" else slider_crank_xml())
        self.data = mujoco.MjData(self.model)
        self.pairs = [("end", "P5"), ("end_x", "P5_x")] if name == "bricard" else [("B_crank", "B_rod")]
        self.v0 = np.zeros(self.model.nv)
        if name != "bricard":      # crank at 6 rad/s; slider and universal rates from the connect's velocity rows
            mujoco.mj_forward(self.model, self.data)
            J = _site_jacobian(mujoco, self.model, self.data, "B_crank") - _site_jacobian(mujoco, self.model,
                                                                                           self.data, "B_rod")
            self.v0[0] = 6.0
            self.v0[1:] = np.linalg.solve(J[:, 1:], -J[:, 0] * 6.0)
        self.reset()
        self.E0 = self.energy()

    def configure(self, step: float, integrator: str, softness: tuple[str, str] | None = None) -> None:
        """Time step, integrator and equality softness (default: the stiffest MuJoCo takes at ``step``)."""
        self.model.opt.timestep = step
        self.model.opt.integrator = getattr(self.mj.mjtIntegrator, f"mjINT_{integrator.upper()}")
        solref, solimp = softness or (f"{2 * step!r} 1", STIFF_SOLIMP)
        self.model.eq_solref[:] = [float(x) for x in solref.split()]
        self.model.eq_solimp[:] = [float(x) for x in solimp.split()]

    def reset(self) -> None:
        self.mj.mj_resetData(self.model, self.data)
        self.data.qvel[:] = self.v0
        self.mj.mj_forward(self.model, self.data)

    def energy(self) -> float:
        self.mj.mj_forward(self.model, self.data)
        return float(self.data.energy[0] + self.data.energy[1])

    def quantity(self) -> np.ndarray:
        """Bricard: P3 (rod3's origin); slider-crank: the slider's x."""
        if self.name == "bricard":
            return self.data.body("rod3").xpos.copy()
        return self.data.body("slider").xpos[:1].copy()

    def gap(self) -> float:
        return max(float(np.linalg.norm(self.data.site(a).xpos - self.data.site(b).xpos)) for a, b in self.pairs)

    def run(self, t_end: float, output: float) -> tuple[np.ndarray, float]:
        """Quantity at every output (from t = 0) and the wall time of the stepping."""
        self.reset()
        per_output = int(round(output / self.model.opt.timestep))
        rows = [self.quantity()]
        step, model, data = self.mj.mj_step, self.model, self.data
        start = time.perf_counter()
        for _ in range(int(round(t_end / output))):
            for _ in range(per_output):
                step(model, data)
            rows.append(self.quantity())
        return np.array(rows), time.perf_counter() - start


MECHANISMS = {   # cmbs name, t_end, output interval, reference file and columns, cmbs columns, DOP853 formulation
    "bricard": dict(t_end=10.0, output=0.05, reference="bricard-exudyn-p3.csv", columns=[1, 2, 3],
                    coordinates=["P3.x", "P3.y", "P3.z"], formulation="projection", unit="m (P3)"),
    "spatial-slider-crank": dict(t_end=5.0, output=0.01, reference="slider-crank-3d-exudyn.csv", columns=[1],
                                 coordinates=["x_slider"], formulation="lagrange", unit="m (slider x)"),
}


def reference(name: str) -> np.ndarray:
    spec = MECHANISMS[name]
    return np.loadtxt(DATA / spec["reference"], delimiter=",", comments="#")[:, spec["columns"]]


def error(rows: np.ndarray, ref: np.ndarray) -> float:
    """max over the outputs of the distance to the reference (nan if the run diverged)."""
    if rows.shape != ref.shape or not np.all(np.isfinite(rows)):
        return float("nan")
    return float(np.linalg.norm(rows - ref, axis=1).max())


def per_evaluation(name: str, repeat: int, target: float) -> dict[str, dict]:
    """µs per call at the start state: cmbs's compiled ``into`` and MuJoCo's mj_forward and mj_step."""
    model = cmbs.load(name)
    q, qd, qdd, lam = model.q0.copy(), model.qd0.copy(), np.empty(model.n), np.empty(model.m)
    result = {}
    for formulation in ("lagrange", "projection", "udwadia-kalaba"):
        compiled = CompiledDynamics(model, formulation)
        if compiled.into(q, qd, 0.0, None, qdd, lam) != 0:
            continue                 # Bricard: Lagrange is singular (redundant rows)
        result[f"cmbs compiled {formulation}"] = time_call(lambda: compiled.into(q, qd, 0.0, None, qdd, lam),
                                                           repeat, target)
    if importlib.util.find_spec("mujoco") is not None:
        mech = MujocoMechanism(name)
        mj, m, d = mech.mj, mech.model, mech.data
        mech.configure(1e-3, "rk4")
        result["MuJoCo mj_forward"] = time_call(lambda: mj.mj_forward(m, d), repeat, target)
        for integrator in ("rk4", "implicitfast"):     # the state moves on from call to call
            mech.configure(1e-4, integrator)
            mech.reset()
            result[f"MuJoCo mj_step {integrator} (h = 1e-4)"] = time_call(lambda: mj.mj_step(m, d), repeat, target)
    return result


def exudyn_per_step() -> dict[str, tuple[float, float, np.ndarray]]:
    """Exudyn at h = 1e-3 with the scripts bench_bricard.py and bench_slider_crank_3d.py: (µs per step
    (wall / steps: Newton iterations included), wall, outputs)."""
    from bench_bricard import exudyn_p3
    from bench_slider_crank_3d import exudyn_slider_crank

    data, wall, _ = exudyn_p3(1e-3)
    result = {"bricard": (wall / 1e4 * 1e6, wall, data[:, 1:4])}
    data, wall, _, _ = exudyn_slider_crank(1e-3)
    result["spatial-slider-crank"] = (wall / 5e3 * 1e6, wall, data[:, 1:2])
    return result


#: cmbs's DOP853 tolerances (atol = rtol / 100) for the work-precision front, and the converged run's.
TOLERANCES, CONVERGED_RTOL = (1e-5, 1e-7, 1e-9, 1e-11), 1e-13


def converged(name: str) -> np.ndarray:
    """The compared quantity at every output from cmbs's DOP853 at rtol 1e-13 (atol 1e-15): the
    reference errors below the published file's own accuracy (~1e-7 m) are measured against."""
    spec = MECHANISMS[name]
    model = cmbs.load(name)
    run = cmbs.simulate(model, t_end=spec["t_end"], formulation=spec["formulation"], integrator="dop853",
                        rtol=CONVERGED_RTOL, atol=CONVERGED_RTOL / 100, dt=spec["output"])
    return run.q[:, [model.coordinate_index(c) for c in spec["coordinates"]]]


def cmbs_runs(name: str) -> list[dict]:
    """cmbs: DOP853 at each of TOLERANCES and compiled RK4 (projection after each step) at h = 1e-3, 1e-4."""
    spec = MECHANISMS[name]
    model = cmbs.load(name)
    columns = [model.coordinate_index(c) for c in spec["coordinates"]]
    configurations = [(f"cmbs {spec['formulation']} dop853 rtol {rtol:g}",
                       dict(formulation=spec["formulation"], integrator="dop853", rtol=rtol, atol=rtol / 100,
                            dt=spec["output"])) for rtol in TOLERANCES]
    for h in (1e-3, 1e-4):
        configurations.append((f"cmbs {spec['formulation']} rk4 h = {h:g} + projection",
                               dict(formulation=spec["formulation"], integrator="rk4", dt=h, project=True,
                                    every=int(round(spec["output"] / h)))))
    ref, rows = reference(name), []
    for label, settings in configurations:
        cmbs.simulate(model, t_end=0.1 if settings["integrator"] == "dop853" else spec["output"], **settings)
        start = time.perf_counter()
        run = cmbs.simulate(model, t_end=spec["t_end"], **settings)
        wall = time.perf_counter() - start
        energy = model.energy_history(run.q, run.qd)
        steps = spec["t_end"] / settings["dt"] if settings["integrator"] == "rk4" else None
        rows.append(dict(label=label, wall=wall, values=run.q[:, columns], error=error(run.q[:, columns], ref),
                         dE=abs(energy[-1] - energy[0]),
                         gap=float(np.abs(run["constraint_error"][-1]).max()),
                         per_step=wall / steps * 1e6 if steps else None))
    return rows


def mujoco_runs(name: str, steps: tuple[float, ...]) -> list[dict]:
    """MuJoCo RK4 at ``steps`` (stiffest softness), implicitfast at 1e-4, RK4 1e-3 with default softness."""
    spec = MECHANISMS[name]
    mech, ref, rows = MujocoMechanism(name), reference(name), []
    configurations = [("rk4", h, None) for h in steps] + [("implicitfast", 1e-4, None), ("rk4", 1e-3, DEFAULT_SOFTNESS)]
    for integrator, h, softness in configurations:
        mech.configure(h, integrator, softness)
        mech.run(spec["output"], spec["output"])                     # warm-up
        values, wall = mech.run(spec["t_end"], spec["output"])
        gap, energy = mech.gap(), mech.energy()
        label = f"MuJoCo {integrator} h = {h:g}" + (", default softness" if softness else "")
        rows.append(dict(label=label, wall=wall, values=values, error=error(values, ref), dE=abs(energy - mech.E0),
                         gap=gap,
                         per_step=wall / (spec["t_end"] / h) * 1e6))
    return rows


def check_start_energy(name: str) -> None:
    model = cmbs.load(name)
    cmbs_energy = float(model.energy_history(model.q0[None], model.qd0[None])[0])
    mech = MujocoMechanism(name)
    print(f"{name}: start energy cmbs {cmbs_energy:.12g} J, MuJoCo {mech.E0:.12g} J, "
          f"start gap {mech.gap():.1e} m")
    assert abs(cmbs_energy - mech.E0) < 1e-9 * max(1.0, abs(cmbs_energy)), "the MuJoCo model is not cmbs's"


def print_table(name: str, rows: list[dict], finest: np.ndarray) -> None:
    spec = MECHANISMS[name]
    print(f"\n{name}, {spec['t_end']:g} s: work-precision, sorted by wall time")
    print(f"  {'run':<46} {'wall s':>7} {'µs/step':>8} {'max error ' + spec['unit']:>22} {'vs converged':>13} "
          f"{'|ΔE| end J':>11} {'gap end':>9}")
    for row in sorted(rows, key=lambda r: r["wall"]):
        row["converged"] = error(row["values"], finest)
        per_step = f"{row['per_step']:.3g}" if row.get("per_step") else "-"
        gap = f"{row['gap']:.1e}" if row.get("gap") is not None else "-"
        dE = f"{row['dE']:.1e}" if row.get("dE") is not None else "-"
        print(f"  {row['label']:<46} {row['wall']:>7.3g} {per_step:>8} {row['error']:>22.2e} "
              f"{row['converged']:>13.2e} {dE:>11} {gap:>9}")


def print_levels(name: str, rows: list[dict]) -> None:
    """At each accuracy level 1e-3 ... 1e-9 (max error against the converged run), each tool's
    fastest run that reaches it, and cmbs's wall time over the fastest other tool's."""
    print(f"\n{name}: least wall time to reach each accuracy (error vs converged)")
    tools = sorted({row["label"].split()[0] for row in rows})
    print("  level   " + "".join(f"{tool:>22}" for tool in tools) + "   cmbs / fastest other")
    for level in (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9):
        best = {}
        for tool in tools:
            reaching = [row["wall"] for row in rows
                        if row["label"].split()[0] == tool and row["converged"] <= level]
            best[tool] = min(reaching) if reaching else None
        others = [wall for tool, wall in best.items() if tool != "cmbs" and wall is not None]
        ratio = (f"{best['cmbs'] / min(others):.2f}" if best.get("cmbs") and others else
                 "only cmbs" if best.get("cmbs") else "-")
        cells = "".join(f"{(f'{wall:.3g} s' if wall is not None else 'not reached'):>22}" for wall in best.values())
        print(f"  {level:<7.0e} {cells}   {ratio}")


def plot(path: str, tables: dict[str, list[dict]]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, len(tables), figsize=(6 * len(tables), 4.5))
    for axis, (name, rows) in zip(np.atleast_1d(axes), tables.items()):
        for row in rows:
            tool = row["label"].split()[0]
            axis.loglog(row["wall"], max(row["error"], 1e-9), {"cmbs": "o", "MuJoCo": "s", "Exudyn": "^"}[tool],
                        color={"cmbs": "C0", "MuJoCo": "C1", "Exudyn": "C2"}[tool])
            axis.annotate(row["label"].split(" ", 1)[1], (row["wall"], max(row["error"], 1e-9)), fontsize=6)
        axis.set(xlabel="wall time [s]", ylabel=f"max error [{MECHANISMS[name]['unit']}]", title=name)
        axis.grid(True, which="both", alpha=0.3)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    print(f"figure -> {path}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="no MuJoCo run at h = 1e-5, shorter timing batches")
    parser.add_argument("--plot", metavar="FILE", help="write the work-precision figure (matplotlib)")
    args = parser.parse_args()
    have_mujoco = importlib.util.find_spec("mujoco") is not None
    if not have_mujoco:
        print("MuJoCo is not installed (pip install -e '.[bench]'): only cmbs is run")
    have_exudyn = importlib.util.find_spec("exudyn") is not None
    repeat, target = (3, 0.05) if args.quick else (7, 0.2)
    if have_mujoco:
        import mujoco
        print(f"MuJoCo {mujoco.__version__}; cmbs {cmbs.__version__}; 1 BLAS thread")
        for name in MECHANISMS:
            check_start_energy(name)

    print("\n== per evaluation of forward dynamics, µs per call at the start state (median [min-max])")
    for name in MECHANISMS:
        times = per_evaluation(name, repeat, target)
        best = min(v["median"] for k, v in times.items() if k.startswith("cmbs"))
        forward = times.get("MuJoCo mj_forward", {}).get("median")
        print(f"{name}:")
        for label, stats in times.items():
            extra = f"   cmbs / it: {best / stats['median']:.2f}" if label.startswith("MuJoCo") else ""
            if label.startswith("cmbs") and forward:
                extra = f"   / mj_forward: {stats['median'] / forward:.2f}"
            print(f"  {label:<40} {fmt(stats):>24}{extra}")

    exudyn = exudyn_per_step() if have_exudyn else {}
    tables = {}
    for name in MECHANISMS:
        rows = cmbs_runs(name)
        if have_mujoco:
            rows += mujoco_runs(name, (3e-3, 1e-3, 1e-4) if args.quick else (3e-3, 1e-3, 1e-4, 1e-5))
        if name in exudyn:
            per_step, wall, values = exudyn[name]
            rows.append(dict(label="Exudyn gen.-alpha h = 0.001", wall=wall, per_step=per_step, values=values,
                             error=error(values, reference(name)), dE=None, gap=None))
        print_table(name, rows, converged(name))
        print_levels(name, rows)
        tables[name] = rows
    if args.plot:
        plot(args.plot, tables)
    return 0


if __name__ == "__main__":
    sys.exit(main())
