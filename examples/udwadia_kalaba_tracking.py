"""Control through constraints (Udwadia-Kalaba; Nicoara 2016 §5): a two-link arm under gravity,
torques on both joints, whose tip must draw a circle (radius 0.4 m, period 2 s).  The arm starts
at rest off the circle; the task ÿ = ÿ_d + K_d ė + K_p e is stacked with the arm's own
constraints, the Udwadia-Kalaba force of that stack is the control force and the torques realise
it.  The same arm is run in natural coordinates (three forward formulations, and with a 10 %
heavier lower link the controller does not know about) and in joint coordinates; a 3-link arm
with a passive joint shows a task the actuators cannot realise."""

import argparse
import math
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import cmbs
from cmbs.control.faults import mass_fault
from cmbs.control.udwadia_kalaba import CirclePath, TrackingTask, UdwadiaKalabaTracking, point_output
from cmbs.errors import CmbsError
from cmbs.metrics import peak_norm, rms_norm, rmse, settling_time

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--out-dir", default="out", help="folder for the figure")
parser.add_argument("--t-end", type=float, default=6.0, help="simulated time, s (3 turns of the circle)")
parser.add_argument("--settle", type=float, default=2.0, help="RMSE is taken after this time, s")
parser.add_argument("--kp", type=float, default=100.0, help="task stiffness K_p, s^-2 (K_d = 2 sqrt(K_p))")
args = parser.parse_args()
Path(args.out_dir).mkdir(parents=True, exist_ok=True)

START = (-math.pi / 4, math.pi / 4)  # at rest, tip at (1.707, -0.707): 0.32 m from the circle's start
CIRCLE = CirclePath(center=(1.0, -0.6), radius=0.4, period=2.0)
KP, KD = args.kp, 2.0 * math.sqrt(args.kp)


def track(label: str, model: cmbs.Model, tip: str, plant: cmbs.Model | None = None, **options) -> dict:
    """Run the controller (designed on ``model``) on ``plant`` and measure the run."""
    law = UdwadiaKalabaTracking(model, TrackingTask(point_output(model, tip), CIRCLE), kp=KP, kd=KD)
    plant = plant or model
    started = time.perf_counter()
    run = cmbs.simulate(plant, t_end=args.t_end, u=law, q0=cmbs.assemble(model, model.q0), qd0=np.zeros(model.n),
                        rtol=1e-9, atol=1e-11, dt=0.005, **options)
    wall = time.perf_counter() - started
    column = model.point_names.index(tip)
    position = np.array([model.point_positions(q)[column] for q in run.q])
    desired = np.array([CIRCLE(t)[0] for t in run.t])
    error = np.linalg.norm(desired - position, axis=1)
    after = run.t >= min(args.settle, run.t[-1] / 2)
    residual = max(law.step(t, q, qd).residual for t, q, qd in zip(run.t[::20], run.q[::20], run.qd[::20]))
    return {"label": label, "run": run, "tip": position, "desired": desired, "error": error,
            "rmse": float(np.linalg.norm(rmse(run.t[after], position[after], desired[after]))),
            "settling": settling_time(run.t, error), "phi": float(run["constraint_error"].max(initial=0.0)),
            "rms": rms_norm(run.t, run["u"]), "peak": peak_norm(run["u"]), "residual": residual, "wall": wall,
            "status": run.info["status"]}


natural = cmbs.load("two-link-arm", theta1=START[0], theta2=START[1])  # natural coordinates
joint = cmbs.load("two-link-arm-joint", theta1=START[0], theta2=START[1])  # the same arm in joint angles
runs = [track("natural, lagrange", natural, "P2", formulation="lagrange"),
        track("natural, projection", natural, "P2", formulation="projection"),
        track("natural, udwadia-kalaba", natural, "P2", formulation="udwadia-kalaba"),
        track("joint, lagrange", joint, "lower.end", formulation="lagrange"),
        track("natural, lower link +10 % mass", natural, "P2", plant=mass_fault(natural, "lower", factor=1.1),
              formulation="lagrange")]

print(f"two-link arm, tip on a circle r = {CIRCLE.radius} m, T = {CIRCLE.period} s; K_p = {KP:g}, K_d = {KD:g}; "
      f"start {np.linalg.norm(runs[0]['error'][0]):.3f} m off the path, at rest")
header = (f"{'run':<32} {'status':>8} {'RMSE t>' + format(min(args.settle, args.t_end / 2), 'g') + ' s [m]':>16} "
          f"{'settle 1% [s]':>13} {'max|Phi|':>9} {'RMS u [Nm]':>10} {'peak u [Nm]':>11} {'max residual':>12} "
          f"{'wall [s]':>8}")
print(header)
print("-" * len(header))
for r in runs:
    print(f"{r['label']:<32} {r['status']:>8} {r['rmse']:16.3e} {r['settling']:13.3f} {r['phi']:9.1e} "
          f"{r['rms']:10.3f} {r['peak']:11.3f} {r['residual']:12.1e} {r['wall']:8.2f}")
same = np.abs(runs[0]["run"]["u"] - runs[3]["run"]["u"])
print(f"natural vs joint coordinates: |u difference| {same[0].max():.1e} N m at t = 0 (same state), "
      f"{same.max():.1e} N m over the run (integration error, rtol 1e-9); "
      f"max tip difference {np.abs(runs[0]['tip'] - runs[3]['tip']).max():.1e} m")

passive = cmbs.load("passive-manipulator")
try:
    law = UdwadiaKalabaTracking(passive, TrackingTask(point_output(passive, "P3"), CirclePath((7.0, 3.0), 1.0, 4.0)),
                                kp=KP, kd=KD)
    law(0.0, cmbs.assemble(passive, passive.q0), np.zeros(passive.n))
    print("passive manipulator: unexpectedly realisable")
except CmbsError as error:
    print(f"passive manipulator (3 joints, motors on 2), tip on a circle: {error}")

best = runs[0]
figure = plt.figure(figsize=(12, 6.5), constrained_layout=True)
grid = figure.add_gridspec(2, 2, width_ratios=(1.1, 1.0))
plane, torques, errors = figure.add_subplot(grid[:, 0]), figure.add_subplot(grid[0, 1]), figure.add_subplot(grid[1, 1])
angle = np.linspace(0, 2 * np.pi, 200)
plane.plot(best["tip"][:, 0], best["tip"][:, 1], "C0", lw=2.5, alpha=0.6, label="tip (natural, lagrange)")
plane.plot(runs[4]["tip"][:, 0], runs[4]["tip"][:, 1], "C3", lw=0.8, label="tip, lower link +10 % mass")
plane.plot(CIRCLE.center[0] + CIRCLE.radius * np.cos(angle), CIRCLE.center[1] + CIRCLE.radius * np.sin(angle),
           "k--", lw=1, label="desired path")
instants = [instant for instant in (0.0, 0.3, 0.6, 1.0, 1.5) if instant <= best["run"].t[-1]]
for instant in instants:
    points = natural.point_positions(best["run"].q[np.searchsorted(best["run"].t, instant)])
    plane.plot(points[:, 0], points[:, 1], "o-", color="0.7", lw=2, ms=4, zorder=0)
    plane.annotate(f"{instant:g} s", points[2], xytext=(4, -10), textcoords="offset points", fontsize=7, color="0.4")
plane.plot(*best["tip"][0], "C0s", label="start")
plane.set(xlabel="x [m]", ylabel="z [m]", aspect="equal", ylim=(-1.1, 0.45),
          title=f"tip path (arm drawn at {', '.join(f'{i:g}' for i in instants)} s)")
plane.legend(fontsize="small", loc="upper right", ncol=2)
for j, name in enumerate(natural.actuator_names):
    torques.plot(best["run"].t, best["run"]["u"][:, j], label=name)
torques.set(ylabel="torque [N m]", title="actuator torques (natural, lagrange)")
torques.legend()
for r in runs:
    errors.semilogy(r["run"].t, np.maximum(r["error"], 1e-16), label=r["label"], lw=1)
errors.set(xlabel="t [s]", ylabel="|y_d - y| [m]", title="tip error", ylim=(1e-12, 1.0))
errors.legend(fontsize="x-small")
figure.savefig(Path(args.out_dir) / "udwadia_kalaba_tracking.png", dpi=110)
print(f"figure -> {Path(args.out_dir) / 'udwadia_kalaba_tracking.png'}")
