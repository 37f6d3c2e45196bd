"""The six formulations side by side on the same models (thesis §3.5): the four-bar swinging
freely under gravity and the 14-DOF human body released standing, hip held, falling under
gravity.  Prints a table (deviation from Lagrange, constraint error, energy error and its share
of the largest kinetic energy, wall time) and plots the deviations."""

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import cmbs

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--out-dir", default="out", help="folder for the figure")
parser.add_argument("--t-end", type=float, default=5.0, help="four-bar duration; the human runs a fifth of it")
args = parser.parse_args()
Path(args.out_dir).mkdir(parents=True, exist_ok=True)

cases = {"four-bar": (cmbs.load("four-bar").without_drivers(), args.t_end),
         "human, hip fixed": (cmbs.load("human", fixed_hip=True), args.t_end / 5)}
names = ["lagrange", "baumgarte", "penalty", "matrix-r", "projection", "udwadia-kalaba"]
figure, axes = plt.subplots(1, len(cases), figsize=(12, 4), constrained_layout=True)
for axis, (label, (model, t_end)) in zip(axes, cases.items()):
    runs = {name: cmbs.simulate(model, t_end=t_end, formulation=name, rtol=1e-9, atol=1e-11, dt=t_end / 200)
            for name in names}
    reference = runs["lagrange"]
    print(f"\n{label}: {model.n} coordinates, {model.m} constraints, {t_end:g} s, RK45 rtol 1e-9")
    print(f"{'formulation':<16}{'max |q - q_lagrange|':>22}{'max |phi|':>12}{'max |E - E0| [J]':>18}"
          f"{'/ max T':>10}{'run [s]':>10}{'compile [s]':>13}")
    for name, run in runs.items():
        deviation = np.abs(run.q - reference.q).max(axis=1)
        energy = run["energy"]
        drift = f"{run.info['energy_drift']:.2g}" if "energy_drift" in run.info else "-"   # judged when conservative
        print(f"{name:<16}{deviation.max():>22.3g}{run['constraint_error'].max():>12.3g}"
              f"{np.abs(energy - energy[0]).max():>18.3g}{drift:>10}"
              f"{run.info['wall_time'] - run.info['compile_time']:>10.3g}{run.info['compile_time']:>13.3g}")
        if name != "lagrange":
            axis.semilogy(run.t, np.maximum(deviation, 1e-16), label=name)
    axis.set(title=label, xlabel="t [s]", ylabel="max |q - q_lagrange|")
    axis.legend(fontsize="small")
figure.savefig(Path(args.out_dir) / "compare_formulations.png", dpi=110)
print(f"\nfigure -> {Path(args.out_dir) / 'compare_formulations.png'}")
