"""Underactuated inverse dynamics of the 3-link manipulator with a passive third joint (Quasem,
Uhlar & Betsch, PAMM 2009): torques τ1, τ2 that move the centre of mass of link 3 along a
prescribed path, in redundant natural coordinates (RED, passive-manipulator) and in joint angles
(GEN, passive-manipulator-joint), by backward Euler with the full servo system and with the
projected one (paper eq. (8)).

Path (chosen: the paper's was lost in extraction): links 5 m, 10 kg, horizontal plane, start
θ = (90°, -90°, 0°) at rest with the link-3 COM at (7.5, 5); the COM moves on the straight line
to (5.5, 3), s(τ) = 10τ³ - 15τ⁴ + 6τ⁵, τ = t/3, over 3 s (2.8 m; the COM stays within 9 m of the
base, the reach being 12.5 m).  The passive link swings through about 200° on the way, like the
paper's θ3.  Prints the RED-GEN and full-projected differences at h and h/2 (first order: they
halve), the open-loop replay error of the inputs in a forward simulation and the wall times, and
writes angles and torques vs time."""

import argparse
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import cmbs
from cmbs.inverse.servo import LinePath, segment_point, servo_inverse_dynamics

parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
parser.add_argument("--out-dir", default="out", help="folder for the figure")
parser.add_argument("--t-end", type=float, default=3.0, help="end of the run (the path itself takes 3 s)")
parser.add_argument("--dt", type=float, default=0.01, help="backward-Euler step h")
args = parser.parse_args()
Path(args.out_dir).mkdir(parents=True, exist_ok=True)

DURATION, SHIFT = 3.0, np.array([-2.0, -2.0])
models = {"RED": cmbs.load("passive-manipulator"), "GEN": cmbs.load("passive-manipulator-joint")}
outputs = {label: segment_point(model, "link3") for label, model in models.items()}
start = outputs["RED"].value(models["RED"].q0)
path = LinePath(start, start + SHIFT, DURATION)


def solve(label: str, method: str, dt: float):
    times = np.linspace(0.0, args.t_end, int(round(args.t_end / dt)) + 1)
    began = time.perf_counter()
    result = servo_inverse_dynamics(models[label], outputs[label], path, times, method=method)
    return result, time.perf_counter() - began


def angles(result) -> np.ndarray:
    return np.column_stack([result.trajectory[f"theta{k}"] for k in (1, 2, 3)])


def differences(first, second) -> tuple[float, float]:
    return float(np.abs(angles(first) - angles(second)).max()), float(np.abs(first.u - second.u).max())


runs = {(label, method, dt): solve(label, method, dt) for label in models for method in ("full", "projected")
        for dt in (args.dt, args.dt / 2)}
steps = runs["RED", "full", args.dt][0].t.size - 1
print(f"link-3 COM from ({start[0]:g}, {start[1]:g}) to ({start[0] + SHIFT[0]:g}, {start[1] + SHIFT[1]:g}) in "
      f"{DURATION:g} s (quintic), run to t = {args.t_end:g} s, h = {args.dt:g} ({steps} steps)\n")
print("method     coords  wall [s]  Newton its/step (max)  max|Φ|     max|c|     max|τ1|, max|τ2| [N m]")
for method in ("full", "projected"):
    for label in models:
        result, wall = runs[label, method, args.dt]
        steps = result.iterations[1:]
        print(f"{method:<10} {label:<6}  {wall:8.3f}  {steps.mean():5.2f} ({steps.max()}){'':<13}"
              f"{result.constraint_residual.max():.1e}    {result.servo_residual.max():.1e}    "
              f"{np.abs(result.u[:, 0]).max():7.1f}, {np.abs(result.u[:, 1]).max():6.1f}")

print(f"\n{'differences (first order in h: they halve with h)':<52} {'h':<8} {'max|Δθ| [rad]':<15} "
      f"{'max|Δτ| [N m]':<15} ratio h/(h/2)")
pairs = [("RED vs GEN, full", ("RED", "full"), ("GEN", "full")),
         ("RED vs GEN, projected", ("RED", "projected"), ("GEN", "projected")),
         ("full vs projected, RED", ("RED", "full"), ("RED", "projected")),
         ("full vs projected, GEN", ("GEN", "full"), ("GEN", "projected"))]
for title, first, second in pairs:
    coarse = differences(runs[(*first, args.dt)][0], runs[(*second, args.dt)][0])
    fine = differences(runs[(*first, args.dt / 2)][0], runs[(*second, args.dt / 2)][0])
    print(f"{title:<52} {args.dt:<8g} {coarse[0]:<15.4g} {coarse[1]:<15.4g}")
    print(f"{'':<52} {args.dt / 2:<8g} {fine[0]:<15.4g} {fine[1]:<15.4g} "
          f"{coarse[0] / fine[0]:.2f}, {coarse[1] / fine[1]:.2f}")

print("\nreplay: τ1, τ2 (cubic spline of the samples) in cmbs.simulate (rk45, rtol 1e-10) from the same start;")
print("max |link-3 COM - path| [m] (the O(h) error of the backward-Euler inputs; tests bound it by 0.06 m at h = 0.01)")
for method in ("full", "projected"):
    for label, model in models.items():
        result = runs[label, method, args.dt][0]
        began = time.perf_counter()
        replay = cmbs.simulate(model, t_end=args.t_end, u=cmbs.SampledInput(result.t, result.u, "spline"), rtol=1e-10,
                               atol=1e-12, dt=args.dt)
        error = max(np.abs(outputs[label].value(q) - path(t)[0]).max() for q, t in zip(replay.q, replay.t))
        print(f"  {method:<10} {label}: {error:.4f} m  ({replay.info['status']}, {time.perf_counter() - began:.2f} s)")

figure, axes = plt.subplots(3, 2, figsize=(11, 9), sharex=True, constrained_layout=True)
styles = {"RED": "-", "GEN": "--"}
colours = {"full": "tab:blue", "projected": "tab:orange"}
for (label, method, dt), (result, _) in runs.items():
    if dt != args.dt:
        continue
    name = f"{label} {method}"
    for k in range(3):
        axes[k, 0].plot(result.t, np.degrees(angles(result)[:, k]), styles[label], color=colours[method], label=name)
    for k in range(2):
        axes[k, 1].plot(result.t, result.u[:, k], styles[label], color=colours[method], label=name)
    if label == "RED" and method == "projected":
        axes[2, 1].plot(result.t, result.trajectory.extras["y"][:, 0], "k-", label="COM x")
        axes[2, 1].plot(result.t, result.trajectory.extras["y"][:, 1], "k--", label="COM z")
for k in range(3):
    axes[k, 0].set(ylabel=f"θ{k + 1} [deg]")
for k in range(2):
    axes[k, 1].set(ylabel=f"τ{k + 1} [N m]")
axes[2, 1].set(ylabel="link-3 COM [m]")
axes[0, 0].set(title=f"relative angles, RED (solid) vs GEN (dashed), h = {args.dt:g} s")
axes[0, 1].set(title="input torques (joint 3 passive)")
axes[0, 0].legend(fontsize="small")
axes[2, 1].legend(fontsize="small")
for axis in axes[2]:
    axis.set(xlabel="t [s]")
figure_path = Path(args.out_dir) / "passive_manipulator_servo.png"
figure.savefig(figure_path, dpi=110)
print(f"figure -> {figure_path}")
