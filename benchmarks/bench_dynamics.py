#!/usr/bin/env python
"""Forward dynamics and simulation of cmbs models, beside MuJoCo, Pinocchio and Exudyn.

    python benchmarks/bench_dynamics.py [--quick] [--json FILE]

Mechanisms (the parameters and start states of the reference measurements of the other tools;
gravity 9.81 downwards):

* ``four-bar``: the anchors' crank-rocker, ground A (0, 0), D (1, 0), crank A-B 0.5 m, coupler
  B-C 1 m, rocker D-C 1 m, uniform 1 kg rods, crank at 30°, upper branch, at rest.  Built here
  with ``cmbs.NaturalModelBuilder`` (4 point coordinates, 3 rigid rows), so that every tool
  simulates the same mechanism;
* ``four-bar-library``: ``cmbs.load("four-bar").without_drivers()`` (the thesis four-bar, 2/10/6 m);
* ``slider-crank`` and ``slider-crank-joint``: ``cmbs.load("slider-crank", gravity=9.81)`` in
  natural coordinates and ``cmbs.load("slider-crank-joint", gravity=9.81)`` in joint angles: 1 m /
  1 kg crank and rod, massless slider, crank 45° at 2 rad/s on the branch θ2 = -2θ1; the crank
  passes ±90°, where the constraint Jacobian loses rank;
* ``chain14-closed``: ``cmbs.load("chain", links=14, closed=True)``;
* ``human``: ``cmbs.load("human")``, hip free, standing, at rest, under gravity (no ground
  contact: it falls freely).

For each it measures

1. µs per forward-dynamics evaluation, ``model.evaluate`` + ``formulation.accelerations``, for
   the six cmbs formulations, at the start state (and ``evaluate`` alone);
2. wall time of ``cmbs.simulate`` over 10 s (the human: 1 s, see below) with RK4 at h = 1 ms and
   RK45 at rtol = atol = 1e-8 (output every 1 ms), per formulation: ``info['wall_time']`` (the
   integration; × real time is computed from it) and the whole call (with the recording of λ,
   energy and constraint errors at the 10 001 output times), the max constraint error |Φ|, |ΔE|
   and, for the slider-crank, the final relative energy error and whether the branch was kept;
3. the same mechanisms in MuJoCo, Pinocchio and Exudyn when importable (``pip install mujoco
   pin exudyn``), measured in this run by minimal code written below, and cmbs / tool ratios;
   when a tool is missing, the anchors' quoted figure, labelled as quoted;
4. the targets of the project issue (PASS/MISS) and where the time of a run goes: model
   evaluation, formulation solve, projection / after-step work, and integrator overhead.

Per-evaluation times: median [min-max] of 7 timeit batches of ~0.2 s after warm-up (the method
of bench_model.py, whose helpers are imported).  Simulation walls: median [min-max] of up to 3
runs (one when a run takes more than 1 s).  ``--quick``: 3 batches of ~0.05 s, one run each, a
simulated span of 1 s (human 0.2 s) except the runs the targets need (four-bar RK4 10 s with
the fastest formulation, slider-crank 10 s).  BLAS runs on one thread unless OPENBLAS_NUM_THREADS
(or OMP_/MKL_NUM_THREADS) is set.  The method and the figures measured here are in
benchmarks/README.md.
"""

from __future__ import annotations

import os

# One BLAS thread unless the caller says otherwise (before numpy is imported): on a 2-core machine
# shared with other work, OpenBLAS's threads on these small matrices make some solves 2-15x
# slower (see the "BLAS threads" section); the other tools are single-threaded too.
BLAS_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
BLAS_THREADS_GIVEN = {name: os.environ.get(name) for name in BLAS_VARIABLES}
for _name in BLAS_VARIABLES:
    os.environ.setdefault(_name, "1")

import argparse  # noqa: E402
import cProfile  # noqa: E402
import importlib  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import pstats  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from typing import Callable  # noqa: E402

import numpy as np  # noqa: E402

import cmbs  # noqa: E402
from cmbs.dynamics.field import CompiledDynamics  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_model import environment, fmt, time_call  # noqa: E402  (same timing method and helpers)
from reporting import write_report  # noqa: E402

FORMULATIONS = ("lagrange", "baumgarte", "penalty", "matrix-r", "projection", "udwadia-kalaba")
COMPILED_FORMULATIONS = ("lagrange", "baumgarte", "projection")   # cmbs.dynamics.field.CompiledDynamics
GRAVITY = 9.81
STEP = 1e-3                  # RK4 step, output interval of RK45, step of the other tools
TOLERANCE = 1e-8             # RK45 rtol = atol
SLIDER_MASS = 1e-4           # MuJoCo and Pinocchio need mass > 0 on the slider block
BRANCH_TOLERANCE = 1e-6      # |θ2 + 2θ1| (mod 2π) below this: the branch θ2 = -2θ1 was kept

# Targets of the project issue
TARGET_FOUR_BAR_RK4_S = 0.1          # 10 s of the four-bar, RK4 h = 1 ms, wall
TARGET_PROJECTION_US = {"four-bar": 5.0, "human": 40.0}
TARGET_SLIDER_CRANK_S = 0.24         # Exudyn's 10 s (anchors), to be beaten ...
TARGET_SLIDER_CRANK_ENERGY = 1e-6    # ... with relative energy error <= this

# Quoted from reference measurements of the other tools (2026-11-21, 2 shared AMD EPYC cores), printed only
# for a tool that is not installed here.  per-eval µs; 10 s walls in s.
ANCHORS_QUOTED = {
    "four-bar": {
        "MuJoCo": {"mj_forward [µs]": 6.98, "implicitfast h=1ms, 10 s run [s]": 0.0512,
                   "RK4 h=1ms, 10 s run [s]": 0.231},
        "Pinocchio": {"constraintDynamics [µs]": 2.98, "RHS with Python wrapper [µs]": 7.85,
                      "RK4 h=1ms, 10 s run [s]": 0.356, "solve_ivp RK45 1e-8, 10 s run [s]": 0.119},
        "Exudyn": {"gen.-alpha step [µs]": 33.8, "gen.-alpha h=1ms, 10 s run [s]": 0.338},
    },
    "slider-crank": {
        "MuJoCo": {"mj_forward [µs]": 5.5, "implicitfast h=1ms, 10 s run [s]": 0.139,
                   "RK4 h=1ms, 10 s run [s]": 0.471},
        "Pinocchio": {"constraintDynamics [µs]": 4.72, "RHS with Python wrapper [µs]": 5.21,
                      "RK4 h=1ms, 10 s run [s]": 0.282, "solve_ivp RK45 1e-8, 10 s run [s]": 0.14},
        "Exudyn": {"gen.-alpha step [µs]": 24.6, "gen.-alpha h=1ms, 10 s run [s]": 0.246},
    },
    "chain14-closed": {
        "MuJoCo": {"mj_forward [µs]": 12.6, "implicitfast h=1ms, 10 s run [s]": 0.293,
                   "RK4 h=1ms, 10 s run [s]": 0.584},
        "Pinocchio": {"constraintDynamics [µs]": 10.6, "RHS with Python wrapper [µs]": 13.1,
                      "RK4 h=1ms, 10 s run [s]": 0.553, "solve_ivp RK45 1e-8, 10 s run [s]": 1.45},
        "Exudyn": {"gen.-alpha step [µs]": 205.0, "gen.-alpha h=1ms, 10 s run [s]": 2.05},
    },
}
ANCHORS_QUOTED["slider-crank-joint"] = ANCHORS_QUOTED["slider-crank"]


# ------------------------------------------------------------------------------------ mechanisms
def anchors_four_bar() -> cmbs.Model:
    """The anchors' crank-rocker in natural coordinates: B, C moving, A, D ground points."""
    crank, coupler, rocker, ground, angle = 0.5, 1.0, 1.0, 1.0, math.radians(30.0)
    b = np.array([crank * math.cos(angle), crank * math.sin(angle)])
    d = np.array([ground, 0.0])
    distance = float(np.linalg.norm(d - b))
    along = (coupler**2 - rocker**2 + distance**2) / (2.0 * distance)   # C from B, along B->D
    unit = (d - b) / distance
    c = b + along * unit + math.sqrt(coupler**2 - along**2) * np.array([-unit[1], unit[0]])  # upper branch
    builder = cmbs.NaturalModelBuilder(
        "four-bar-anchors", gravity=(0.0, -GRAVITY),
        description="crank-rocker 0.5/1/1 m on a 1 m ground, 1 kg uniform rods, crank at 30 deg, at rest",
        source="benchmark crank-rocker of the reference measurements (fourbar)")
    builder.add_point("A", 0.0, 0.0, fixed=True)
    builder.add_point("D", ground, 0.0, fixed=True)
    builder.add_point("B", *b)
    builder.add_point("C", *c)
    for name, i, j, length in (("crank", "A", "B", crank), ("coupler", "B", "C", coupler),
                               ("rocker", "D", "C", rocker)):
        builder.add_segment(name, i, j, mass=1.0, com=(length / 2, 0.0), inertia=length**2 / 12, length=length)
    model = builder.build()
    assert np.abs(model.constraints(model.q0)).max() < 1e-12
    return model


@dataclass
class Link:
    """A rigid segment as a link of a kinematic tree, jointed (hinge) at ``start`` to its parent
    (None: to ground, or the floating root)."""

    name: str
    parent: str | None
    start: str
    end: str
    length: float
    mass: float
    along: float    # centre of mass from ``start``, along start -> end
    across: float   # ... and across (+90°)
    inertia: float  # about the centre of mass


@dataclass
class Tree:
    """A planar mechanism as a tree of hinged links plus loop closures, in the form the other
    tools want it; the start state is read from the cmbs model's q0, q̇0."""

    name: str
    links: list[Link]
    positions: dict[str, np.ndarray]
    velocities: dict[str, np.ndarray]
    closures: list[tuple[str, str]] = field(default_factory=list)  # (link whose end is pinned, ground point | "slider")
    floating: bool = False      # root link's start point free in x and z
    slider: str | None = None   # point moving on the ground x axis (a slider block)
    branch: tuple[str, str] | None = None  # (crank, rod): report |θ_rel + 2θ_crank| at the end

    def angle(self, link: Link) -> float:
        d = self.positions[link.end] - self.positions[link.start]
        return math.atan2(d[1], d[0])

    def rate(self, link: Link) -> float:
        d = self.positions[link.end] - self.positions[link.start]
        dd = self.velocities[link.end] - self.velocities[link.start]
        return float((d[0] * dd[1] - d[1] * dd[0]) / (d @ d))

    def link(self, name: str) -> Link:
        return next(link for link in self.links if link.name == name)

    def com(self, link: Link) -> np.ndarray:
        c, s = math.cos(self.angle(link)), math.sin(self.angle(link))
        along, across = link.along, link.across
        return self.positions[link.start] + np.array([c * along - s * across, s * along + c * across])

    def com_velocity(self, link: Link) -> np.ndarray:
        r = self.com(link) - self.positions[link.start]
        return self.velocities[link.start] + self.rate(link) * np.array([-r[1], r[0]])

    def in_frame(self, link: Link, point: np.ndarray, origin: np.ndarray | None = None) -> np.ndarray:
        """``point`` in the frame of ``link`` (origin: its start point unless given, x along it)."""
        c, s = math.cos(self.angle(link)), math.sin(self.angle(link))
        d = point - (self.positions[link.start] if origin is None else origin)
        return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])

    def check(self) -> None:
        for link in self.links:
            length = float(np.linalg.norm(self.positions[link.end] - self.positions[link.start]))
            assert abs(length - link.length) < 1e-9, (self.name, link.name, length, link.length)


def tree_from(model: cmbs.Model, links: list[Link], **options) -> Tree:
    """Point positions and velocities from the model's start state (natural coordinates)."""
    positions = dict(zip(model.point_names, np.asarray(model.point_positions(model.q0))))
    names = list(model.coordinate_names)
    velocities = {}
    for point in model.point_names:
        if f"{point}.x" in names:
            velocities[point] = np.array([model.qd0[names.index(f"{point}.x")], model.qd0[names.index(f"{point}.z")]])
        else:
            velocities[point] = np.zeros(2)
    tree = Tree(model.name, links, positions, velocities, **options)
    tree.check()
    return tree


def rod(name, parent, start, end, length, mass):
    return Link(name, parent, start, end, length, mass, length / 2, 0.0, mass * length**2 / 12)


def four_bar_tree(model) -> Tree:
    return tree_from(model, [rod("crank", None, "A", "B", 0.5, 1.0), rod("coupler", "crank", "B", "C", 1.0, 1.0),
                             rod("rocker", "coupler", "C", "D", 1.0, 1.0)], closures=[("rocker", "D")])


def library_four_bar_tree(model) -> Tree:
    """src/cmbs/library/four-bar.toml: crank A-P1 2 m 1 kg, coupler P1-P2 10 m 5 kg, rocker
    P2-B 6 m 3 kg, uniform rods (the file's inertias)."""
    return tree_from(model, [Link("crank", None, "A", "P1", 2.0, 1.0, 1.0, 0.0, 0.333333333333333),
                             Link("coupler", "crank", "P1", "P2", 10.0, 5.0, 5.0, 0.0, 41.6666666666667),
                             Link("rocker", "coupler", "P2", "B", 6.0, 3.0, 3.0, 0.0, 9.0)], closures=[("rocker", "B")])


def slider_crank_tree(model) -> Tree:
    return tree_from(model, [rod("crank", None, "O", "A", 1.0, 1.0), rod("rod", "crank", "A", "C", 1.0, 1.0)],
                     closures=[("rod", "slider")], slider="C", branch=("crank", "rod"))


def chain_tree(model, links: int = 14) -> Tree:
    return tree_from(model, [rod(f"link{k}", None if k == 1 else f"link{k - 1}", f"P{k - 1}", f"P{k}", 0.3, 1.0)
                             for k in range(1, links + 1)], closures=[(f"link{links}", f"P{links}")])


def human_tree(model) -> Tree:
    from cmbs.library.human import SEGMENTS

    def link(name, kind, parent, start, end):
        length, along, across, mass, inertia = SEGMENTS[kind]
        return Link(name, parent, start, end, length, mass, along, across, inertia)

    links = [link("trunk", "trunk", None, "hip", "neck"), link("head", "head", "trunk", "neck", "head")]
    for side in "rl":
        links += [link(f"{side}_arm", "arm", "trunk", "neck", f"{side}_elbow"),
                  link(f"{side}_forearm", "forearm", f"{side}_arm", f"{side}_elbow", f"{side}_wrist"),
                  link(f"{side}_thigh", "thigh", "trunk", "hip", f"{side}_knee"),
                  link(f"{side}_shank", "shank", f"{side}_thigh", f"{side}_knee", f"{side}_ankle"),
                  link(f"{side}_foot", "foot", f"{side}_shank", f"{side}_ankle", f"{side}_toe")]
    return tree_from(model, links, floating=True)


@dataclass
class Case:
    label: str
    title: str
    load: Callable[[], cmbs.Model]
    tree: Callable[[cmbs.Model], Tree] | None
    span: float                       # simulated seconds (full run)
    quick_span: float
    formulations: tuple[str, ...] = FORMULATIONS   # simulated with; all six are timed per evaluation
    project: tuple[str, ...] = ()     # formulations run with project=True
    singular: bool = False            # slider-crank: passes singular positions; branch and energy reported
    tools_from: str | None = None     # reuse another case's tool measurements (same mechanism)
    quick_extra: tuple[tuple[str, str, float, bool], ...] = ()  # --quick: (formulation, integrator, span, project)


# --quick: the 10 s slider-crank runs of the target (the fastest ones of a full run)
QUICK_SLIDER_CRANK = (("projection", "rk45", 10.0, True), ("matrix-r", "rk45", 10.0, False),
                      ("matrix-r", "rk4", 10.0, False),
                      ("baumgarte", "rk4", 10.0, False), ("baumgarte", "rk45", 10.0, False))
CASES = [
    Case("four-bar", "anchors' four-bar (crank-rocker 0.5/1/1 m, 1 DOF), built with NaturalModelBuilder",
         anchors_four_bar, four_bar_tree, 10.0, 1.0),
    Case("four-bar-library", "library four-bar without its driver (thesis, 2/10/6 m, 1 DOF)",
         lambda: cmbs.load("four-bar").without_drivers(), library_four_bar_tree, 10.0, 1.0),
    Case("slider-crank", "slider-crank, natural coordinates (gravity 9.81, crank 45° at 2 rad/s)",
         lambda: cmbs.load("slider-crank", gravity=GRAVITY), slider_crank_tree, 10.0, 1.0,
         project=("projection", "udwadia-kalaba"), singular=True,
         quick_extra=QUICK_SLIDER_CRANK),
    Case("slider-crank-joint", "slider-crank, joint angles θ1, θ2 (same mechanism and start)",
         lambda: cmbs.load("slider-crank-joint", gravity=GRAVITY), None, 10.0, 1.0,
         project=("projection", "udwadia-kalaba"), singular=True, tools_from="slider-crank",
         quick_extra=QUICK_SLIDER_CRANK),
    Case("chain14-closed", "14-link chain, tip pinned (12 DOF)",
         lambda: cmbs.load("chain", links=14, closed=True), chain_tree, 10.0, 1.0),
    Case("human", "human, 12 segments, hip free, standing, gravity (14 DOF; falls freely)",
         lambda: cmbs.load("human"), human_tree, 1.0, 0.2),
]


# ------------------------------------------------------------------------------------ helpers
def time_runs(run: Callable[[], object], repeat: int, budget: float = 1.0) -> tuple[dict, object]:
    """Wall seconds of ``run()``: median [min-max] of up to ``repeat`` runs; stops repeating once
    a run has taken more than ``budget`` s.  Returns the stats and the last result."""
    walls, result = [], None
    for _ in range(repeat):
        started = time.perf_counter()
        result = run()
        walls.append(time.perf_counter() - started)
        if walls[-1] > budget:
            break
    return {"median": statistics.median(walls), "min": min(walls), "max": max(walls), "runs": walls}, result


def fmt_s(stats: dict) -> str:
    if len(stats.get("runs", [0, 0])) == 1:
        return f"{stats['median']:.3g}"
    return f"{stats['median']:.3g} [{stats['min']:.3g}-{stats['max']:.3g}]"


def wrap(angle):
    return (np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi


def ratio(a: float | None, b: float | None) -> str:
    if a is None or b is None or not b > 0:
        return "-"
    return f"{a / b:.3g}x"


# ------------------------------------------------------------------------------------ cmbs
def cmbs_per_evaluation(model: cmbs.Model, repeat: int, target: float) -> dict:
    """µs of evaluate alone and of evaluate + accelerations for each formulation, at (q0, q̇0, 0)."""
    q, qd, u = model.q0.copy(), model.qd0.copy(), np.zeros(model.n_u)
    terms = model.new_terms()
    result = {"evaluate": time_call(lambda: model.evaluate(q, qd, 0.0, u, out=terms), repeat, target)}
    for name in FORMULATIONS:
        solver = cmbs.formulation(name).bind(model)

        def forward():
            model.evaluate(q, qd, 0.0, u, out=terms)
            return solver.accelerations(terms, q, qd, 0.0)
        try:
            forward()
        except Exception as error:  # noqa: BLE001 - reported, not fatal
            result[name] = {"error": f"{type(error).__name__}: {error}"[:120]}
            continue
        result[name] = time_call(forward, repeat, target)
    qdd, lam = np.empty(model.n), np.empty(model.m)
    for name in COMPILED_FORMULATIONS:     # model terms and solve in one compiled call
        compiled = CompiledDynamics(model, name)
        result[f"compiled {name}"] = time_call(lambda: compiled.into(q, qd, 0.0, u, qdd, lam), repeat, target)
    return result


def cmbs_run(model: cmbs.Model, formulation: str, integrator: str, span: float, project: bool,
             repeat: int) -> dict:
    """One configuration: a 10-step warm-up call (it triggers any numba compilation of a compiled
    path; its wall is kept as ``first_call_s``), then simulate() repeated; wall = info['wall_time']."""
    options = {"dt": STEP} if integrator == "rk4" else {"dt": STEP, "rtol": TOLERANCE, "atol": TOLERANCE}
    walls, calls, loops, trajectory = [], [], [], None
    result = {"formulation": formulation, "integrator": integrator, "project": project, "span": span}
    try:
        started = time.perf_counter()
        cmbs.simulate(model, t_end=10 * STEP, formulation=formulation, integrator=integrator, project=project,
                      **options)
        result["first_call_s"] = time.perf_counter() - started
        for _ in range(repeat):
            started = time.perf_counter()
            trajectory = cmbs.simulate(model, t_end=span, formulation=formulation, integrator=integrator,
                                       project=project, **options)
            calls.append(time.perf_counter() - started)
            walls.append(trajectory.info["wall_time"])
            loops.append(trajectory.info.get("loop_wall_time"))
            if calls[-1] > 1.0 or trajectory.info["status"] != "success":
                break
    except Exception as error:  # noqa: BLE001 - e.g. a LinAlgError escaping a formulation
        return {**result, "status": "error", "message": f"{type(error).__name__}: {error}"[:160]}
    info = trajectory.info
    energy = trajectory["energy"]
    change = np.abs(energy - energy[0])
    result.update({
        "status": info["status"], "message": info.get("message", ""), "t_reached": float(trajectory.t[-1]),
        "path": "compiled" if info.get("compiled") else "python",
        "wall_s": {"median": statistics.median(walls), "min": min(walls), "max": max(walls), "runs": walls},
        "loop_s": statistics.median(loops) if loops[0] is not None else None,
        "call_s": {"median": statistics.median(calls), "min": min(calls), "max": max(calls), "runs": calls},
        "evaluations": info.get("evaluations"), "steps": info.get("steps"), "rejected": info.get("rejected"),
        "max_constraint_error": float(np.max(trajectory["constraint_error"])),
        "energy_start": float(energy[0]), "dE_max": float(change.max()), "dE_end": float(change[-1]),
        "relative_dE_max": float(change.max() / abs(energy[0])), "relative_dE_end": float(change[-1] / abs(energy[0])),
    })
    result["real_time_factor"] = result["t_reached"] / result["wall_s"]["median"]
    if "theta1" in trajectory.names:
        theta1, theta2 = trajectory["theta1"], trajectory["theta2"]
        result["branch_deviation"] = float(np.abs(wrap(theta2 + 2.0 * theta1)).max())
        result["branch_kept"] = result["branch_deviation"] < BRANCH_TOLERANCE
        result["singular_crossings"] = int(np.sum(np.diff(np.floor((theta1 - np.pi / 2) / np.pi)) != 0))
    return result


#: speed and energy target of the singular slider-crank in the speed issue
TARGET_REAL_TIME, REAL_TIME_STEPS = 100.0, (1e-3, 2e-3, 2.5e-3)


def real_time_slider_crank() -> dict:
    """The singular slider-crank (natural coordinates) for 10 s with matrix R on the compiled RK4
    loop at a few steps: wall (best of 3), max relative energy error over the run, branch; the
    target is relE <= 1e-6 over the whole run at >= 100x real time.  Prints one line a step."""
    model = cmbs.load("slider-crank", gravity=GRAVITY)
    rows = []
    for step in REAL_TIME_STEPS:
        options = dict(t_end=10.0, integrator="rk4", dt=step, formulation="matrix-r")
        cmbs.simulate(model, **{**options, "t_end": 10 * step})
        walls = []
        for _ in range(3):
            started = time.perf_counter()
            run = cmbs.simulate(model, **options)
            walls.append(time.perf_counter() - started)
        energy = run["energy"]
        worst = float(np.abs(energy - energy[0]).max() / abs(energy[0]))
        branch = float(np.abs(wrap(run["theta2"] + 2.0 * run["theta1"])).max())
        ok = run.info["status"] == "success" and worst <= TARGET_SLIDER_CRANK_ENERGY and branch < 1e-6
        rows.append({"dt": step, "wall_s": min(walls), "real_time": 10.0 / min(walls), "relative_dE_max": worst,
                     "branch_kept": branch < 1e-6, "ok": ok})
        print(f"  slider-crank, matrix-r RK4 h = {step * 1e3:g} ms, 10 s: {min(walls):.3g} s = "
              f"{10.0 / min(walls):.0f}x real time, max relE {worst:.1e}, branch {'kept' if branch < 1e-6 else 'lost'}")
    good = [row for row in rows if row["ok"]]
    best = max(good, key=lambda row: row["real_time"]) if good else None
    verdict = "PASS" if best and best["real_time"] >= TARGET_REAL_TIME else "MISS"
    print(f"  slider-crank through its singular positions, max relE <= 1e-6, >= {TARGET_REAL_TIME:g}x real time: "
          + (f"{best['real_time']:.0f}x (h = {best['dt'] * 1e3:g} ms)" if best else "no run") + f"  {verdict}")
    return {"verdict": verdict, "best": best, "runs": rows}


def passed(run: dict, span: float) -> bool:
    return run.get("status") == "success" and abs(run.get("t_reached", 0.0) - span) < 1e-9 and \
        np.isfinite(run.get("dE_end", np.nan))


# ------------------------------------------------------------------------------------ MuJoCo
def mujoco_xml(tree: Tree) -> str:
    """MJCF of ``tree``: hinges, connect equalities for the closures, no contacts."""
    children: dict[str | None, list[Link]] = {}
    for link in tree.links:
        children.setdefault(link.parent, []).append(link)

    def body(link: Link) -> str:
        if link.parent is None:
            origin = np.zeros(2) if tree.floating else tree.positions[link.start]
        else:
            origin = tree.in_frame(tree.link(link.parent), tree.positions[link.start])
        inertia = max(link.inertia, 1e-9)
        xml = f'<body name="{link.name}" pos="{float(origin[0])!r} {float(origin[1])!r} 0">'
        if link.parent is None and tree.floating:
            xml += '<joint name="root_x" type="slide" axis="1 0 0"/><joint name="root_z" type="slide" axis="0 1 0"/>'
        xml += (f'<joint name="{link.name}" type="hinge" axis="0 0 1"/>'
                f'<inertial pos="{float(link.along)!r} {float(link.across)!r} 0" mass="{float(link.mass)!r}" '
                f'diaginertia="{float(inertia)!r} {float(inertia)!r} {float(inertia)!r}"/>'
                f'<site name="{link.name}_end" pos="{float(link.length)!r} 0 0"/>')
        return xml + "".join(body(child) for child in children.get(link.name, [])) + "</body>"

    world, equality = "", ""
    for link_name, target_point in tree.closures:
        if target_point == "slider":
            equality += f'<connect site1="{link_name}_end" site2="slider"/>'
        else:
            p = tree.positions[target_point]
            world += f'<site name="ground_{target_point}" pos="{float(p[0])!r} {float(p[1])!r} 0"/>'
            equality += f'<connect site1="{link_name}_end" site2="ground_{target_point}"/>'
    if tree.slider:
        m = SLIDER_MASS
        world += (f'<body name="slider_block"><joint name="slider" type="slide" axis="1 0 0"/>'
                  f'<inertial pos="0 0 0" mass="{m}" diaginertia="{m * 1e-3} {m * 1e-3} {m * 1e-3}"/>'
                  f'<site name="slider"/></body>')
    xml = (f'<mujoco model="{tree.name}"><option timestep="{STEP}" gravity="0 {-GRAVITY} 0" integrator="implicitfast">'
           '<flag contact="disable" energy="enable"/></option><worldbody>'
           + world + "".join(body(root) for root in children[None])
           + f"</worldbody><equality>{equality}</equality></mujoco>")
    return xml


def mujoco_build(tree: Tree):
    """MuJoCo model and data of ``tree`` (:func:`mujoco_xml`) and its start state: (model, data,
    q0, v0, address of a joint's qpos)."""
    import mujoco

    model = mujoco.MjModel.from_xml_string(mujoco_xml(tree))
    data = mujoco.MjData(model)
    q0, v0 = np.zeros(model.nq), np.zeros(model.nv)

    def address(name: str) -> int:
        return int(model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)])

    for link in tree.links:
        parent = tree.link(link.parent) if link.parent else None
        q0[address(link.name)] = tree.angle(link) - (tree.angle(parent) if parent else 0.0)
        v0[address(link.name)] = tree.rate(link) - (tree.rate(parent) if parent else 0.0)
        if link.parent is None and tree.floating:
            q0[address("root_x")], q0[address("root_z")] = tree.positions[link.start]
            v0[address("root_x")], v0[address("root_z")] = tree.velocities[link.start]
    if tree.slider:
        q0[address("slider")], v0[address("slider")] = tree.positions[tree.slider][0], tree.velocities[tree.slider][0]
    return model, data, q0, v0, address


def mujoco_measure(tree: Tree, span: float, repeat: int, batches: int, target: float) -> dict:
    import mujoco

    model, data, q0, v0, address = mujoco_build(tree)

    def reset():
        mujoco.mj_resetData(model, data)
        data.qpos[:], data.qvel[:] = q0, v0
        mujoco.mj_forward(model, data)

    def energy() -> float:
        mujoco.mj_forward(model, data)
        return float(data.energy[0] + data.energy[1])

    def gap() -> float:
        worst = 0.0
        for link_name, target_point in tree.closures:
            a = data.site(f"{link_name}_end").xpos
            b = data.site("slider" if target_point == "slider" else f"ground_{target_point}").xpos
            worst = max(worst, float(np.linalg.norm(a - b)))
        return worst

    reset()
    start_energy = energy()
    result = {"version": mujoco.__version__, "E0": start_energy,
              "per_eval": {"mj_forward": time_call(lambda: mujoco.mj_forward(model, data), batches, target)},
              "runs": {}}
    steps = int(round(span / STEP))
    for label, integrator in (("implicitfast h=1ms (recommended)", mujoco.mjtIntegrator.mjINT_IMPLICITFAST),
                              ("RK4 h=1ms", mujoco.mjtIntegrator.mjINT_RK4)):
        model.opt.integrator = integrator

        def simulate():
            reset()
            for _ in range(steps):
                mujoco.mj_step(model, data)
        wall, _ = time_runs(simulate, repeat)
        run = {"wall_s": wall, "span": span, "dE_end": abs(energy() - start_energy), "gap_end": gap(),
               "finite": bool(np.all(np.isfinite(data.qpos)))}
        if tree.branch:
            run["branch_deviation_end"] = float(abs(wrap(data.qpos[address(tree.branch[1])]
                                                         + 2.0 * data.qpos[address(tree.branch[0])])))
        result["runs"][label] = run
    return result


# ------------------------------------------------------------------------------------ Pinocchio
def pinocchio_build(tree: Tree):
    """Pinocchio model of ``tree`` (revolute joints, 3-D point contacts for the closures): (name of
    the forward-dynamics call, accelerations(q, v), rhs(y), y0, index of a joint's q, energy(y),
    gap(y), model, data)."""
    import pinocchio as pin

    model = pin.Model()
    model.gravity.linear = np.array([0.0, -GRAVITY, 0.0])
    joint = {}
    for link in tree.links:  # parents come before children in every link table above
        placement = pin.SE3.Identity()
        if link.parent is None and tree.floating:
            x = model.addJoint(0, pin.JointModelPX(), pin.SE3.Identity(), "root_x")
            parent = model.addJoint(x, pin.JointModelPY(), pin.SE3.Identity(), "root_z")
        elif link.parent is None:
            parent = 0
            placement = pin.SE3(np.eye(3), np.array([*tree.positions[link.start], 0.0]))
        else:
            parent = joint[link.parent]
            local = tree.in_frame(tree.link(link.parent), tree.positions[link.start])
            placement = pin.SE3(np.eye(3), np.array([*local, 0.0]))
        joint[link.name] = model.addJoint(parent, pin.JointModelRZ(), placement, link.name)
        inertia = max(link.inertia, 1e-9)
        model.appendBodyToJoint(joint[link.name], pin.Inertia(link.mass, np.array([link.along, link.across, 0.0]),
                                                              np.diag([inertia] * 3)), pin.SE3.Identity())
    if tree.slider:
        joint["slider"] = model.addJoint(0, pin.JointModelPX(), pin.SE3.Identity(), "slider")
        model.appendBodyToJoint(joint["slider"], pin.Inertia(SLIDER_MASS, np.zeros(3), np.eye(3) * SLIDER_MASS * 1e-3),
                                pin.SE3.Identity())
    closures = []
    for link_name, target_point in tree.closures:
        tip = pin.SE3(np.eye(3), np.array([tree.link(link_name).length, 0.0, 0.0]))
        if target_point == "slider":
            other, where = joint["slider"], pin.SE3.Identity()
        else:
            other, where = 0, pin.SE3(np.eye(3), np.array([*tree.positions[target_point], 0.0]))
        closures.append(pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, model, joint[link_name], tip, other,
                                                 where, pin.ReferenceFrame.LOCAL))
    data = model.createData()
    nq = model.nq
    q0, v0 = np.zeros(nq), np.zeros(model.nv)

    def index(name: str) -> int:
        return model.joints[model.getJointId(name)].idx_q

    for link in tree.links:
        parent = tree.link(link.parent) if link.parent else None
        q0[index(link.name)] = tree.angle(link) - (tree.angle(parent) if parent else 0.0)
        v0[index(link.name)] = tree.rate(link) - (tree.rate(parent) if parent else 0.0)
        if link.parent is None and tree.floating:
            q0[index("root_x")], q0[index("root_z")] = tree.positions[link.start]
            v0[index("root_x")], v0[index("root_z")] = tree.velocities[link.start]
    if tree.slider:
        q0[index("slider")], v0[index("slider")] = tree.positions[tree.slider][0], tree.velocities[tree.slider][0]
    tau = np.zeros(model.nv)
    if closures:
        constraint_models = pin.StdVec_RigidConstraintModel()
        constraint_datas = pin.StdVec_RigidConstraintData()
        for closure in closures:
            constraint_models.append(closure)
            constraint_datas.append(closure.createData())
        pin.initConstraintDynamics(model, data, constraint_models, constraint_datas)
        settings = pin.ProximalSettings(1e-12, 1e-8, 20)
        name = "constraintDynamics"

        def accelerations(q, v):
            return pin.constraintDynamics(model, data, q, v, tau, constraint_models, constraint_datas, settings)
    else:
        name = "aba"

        def accelerations(q, v):
            return pin.aba(model, data, q, v, tau)

    def rhs(y):
        return np.concatenate((y[nq:], accelerations(y[:nq], y[nq:])))

    def energy(y) -> float:
        q, v = y[:nq], y[nq:]
        return float(pin.computeKineticEnergy(model, data, q, v) + pin.computePotentialEnergy(model, data, q))

    def gap(y) -> float:
        pin.forwardKinematics(model, data, y[:nq])
        worst = 0.0
        for closure in closures:
            a = data.oMi[closure.joint1_id].act(closure.joint1_placement).translation
            b = data.oMi[closure.joint2_id].act(closure.joint2_placement).translation
            worst = max(worst, float(np.linalg.norm(a - b)))
        return worst

    return name, accelerations, rhs, np.concatenate((q0, v0)), index, energy, gap, model, data


def pinocchio_measure(tree: Tree, span: float, repeat: int, batches: int, target: float) -> dict:
    import pinocchio as pin
    from scipy.integrate import solve_ivp

    name, accelerations, rhs, y0, index, energy, gap, model, _ = pinocchio_build(tree)
    q0, v0 = y0[:model.nq], y0[model.nq:]
    start_energy = energy(y0)
    result = {"version": pin.__version__, "E0": start_energy, "runs": {}, "per_eval": {
        f"{name} (C++ call)": time_call(lambda: accelerations(q0, v0), batches, target),
        "RHS with Python wrapper": time_call(lambda: rhs(y0), batches, target)}}
    steps = int(round(span / STEP))

    def rk4():
        y, h = y0.copy(), STEP
        for _ in range(steps):
            k1 = rhs(y)
            k2 = rhs(y + 0.5 * h * k1)
            k3 = rhs(y + 0.5 * h * k2)
            k4 = rhs(y + h * k3)
            y = y + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        return y

    def rk45():
        solution = solve_ivp(lambda t, y: rhs(y), (0.0, span), y0, method="RK45", rtol=TOLERANCE, atol=TOLERANCE,
                             t_eval=np.linspace(0.0, span, steps + 1))
        return solution.y[:, -1]

    for label, run in (("RK4 h=1ms, Python loop", rk4), ("solve_ivp RK45 1e-8", rk45)):
        try:
            wall, end = time_runs(run, repeat)
        except Exception as error:  # noqa: BLE001
            result["runs"][label] = {"error": f"{type(error).__name__}: {error}"[:120]}
            continue
        entry = {"wall_s": wall, "span": span, "finite": bool(np.all(np.isfinite(end)))}
        if entry["finite"]:
            entry.update(dE_end=abs(energy(end) - start_energy), gap_end=gap(end))
            if tree.branch:
                entry["branch_deviation_end"] = float(abs(wrap(end[index(tree.branch[1])]
                                                               + 2.0 * end[index(tree.branch[0])])))
        result["runs"][label] = entry
    return result


# ------------------------------------------------------------------------------------ Exudyn
def exudyn_measure(tree: Tree, span: float, repeat: int) -> dict:
    with warnings.catch_warnings():  # the parameter names used below work in older versions too
        warnings.simplefilter("ignore", DeprecationWarning)
        return _exudyn_measure(tree, span, repeat)


def _exudyn_measure(tree: Tree, span: float, repeat: int) -> dict:
    import exudyn as exu
    from exudyn.itemInterface import (CoordinateConstraint, LoadMassProportional, MarkerBodyMass, MarkerBodyPosition,
                                      MarkerNodeCoordinate, MarkerNodePosition, NodePoint2D, NodePointGround,
                                      NodeRigidBody2D, ObjectGround, ObjectJointRevolute2D, ObjectMassPoint2D,
                                      ObjectRigidBody2D)

    output = exu.OutputVariableType

    def build(slider_mass: float):
        """Redundant coordinates: one NodeRigidBody2D (x, y, φ of the centre of mass) per link,
        revolute joints between markers, the slider a mass point held on y = 0."""
        container = exu.SystemContainer()
        mbs = container.AddSystem()
        ground = mbs.AddObject(ObjectGround())
        bodies, joints, lines = {}, [], []

        def ground_marker(point):
            return mbs.AddMarker(MarkerBodyPosition(bodyNumber=ground, localPosition=[*point, 0.0]))

        def marker(link: Link, point: np.ndarray) -> int:
            local = tree.in_frame(link, point, origin=tree.com(link))
            return mbs.AddMarker(MarkerBodyPosition(bodyNumber=bodies[link.name][0], localPosition=[*local, 0.0]))

        def revolute(a: int, b: int):
            mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[a, b]))
            joints.append((a, b))

        for link in tree.links:
            com, velocity = tree.com(link), tree.com_velocity(link)
            node = mbs.AddNode(NodeRigidBody2D(referenceCoordinates=[*com, tree.angle(link)],
                                               initialVelocities=[*velocity, tree.rate(link)]))
            body = mbs.AddObject(ObjectRigidBody2D(physicsMass=link.mass, physicsInertia=link.inertia, nodeNumber=node))
            bodies[link.name] = (body, node, link)
            mbs.AddLoad(LoadMassProportional(markerNumber=mbs.AddMarker(MarkerBodyMass(bodyNumber=body)),
                                             loadVector=[0.0, -GRAVITY, 0.0]))
            start = tree.positions[link.start]
            if link.parent is not None:
                revolute(marker(tree.link(link.parent), start), marker(link, start))
            elif not tree.floating:
                revolute(ground_marker(start), marker(link, start))
        points = []
        for link_name, target_point in tree.closures:
            link = tree.link(link_name)
            end = marker(link, tree.positions[link.end])
            if target_point == "slider":
                p, v = tree.positions[tree.slider], tree.velocities[tree.slider]
                node = mbs.AddNode(NodePoint2D(referenceCoordinates=[*p], initialVelocities=[*v]))
                mbs.AddObject(ObjectMassPoint2D(physicsMass=slider_mass, nodeNumber=node))
                points.append((node, slider_mass))
                revolute(end, mbs.AddMarker(MarkerNodePosition(nodeNumber=node)))
                fixed = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=mbs.AddNode(NodePointGround()), coordinate=0))
                mbs.AddObject(CoordinateConstraint(markerNumbers=[fixed, mbs.AddMarker(
                    MarkerNodeCoordinate(nodeNumber=node, coordinate=1))]))
                lines.append(node)
            else:
                revolute(ground_marker(tree.positions[target_point]), end)
        mbs.Assemble()

        def energy() -> float:
            total = 0.0
            for body, node, link in bodies.values():
                p = mbs.GetNodeOutput(node, output.Position)
                v = mbs.GetNodeOutput(node, output.Velocity)
                w = mbs.GetNodeOutput(node, output.AngularVelocity)
                total += (0.5 * link.mass * (v[0]**2 + v[1]**2) + 0.5 * link.inertia * w[2]**2
                          + link.mass * GRAVITY * p[1])
            for node, mass in points:
                p, v = mbs.GetNodeOutput(node, output.Position), mbs.GetNodeOutput(node, output.Velocity)
                total += 0.5 * mass * (v[0]**2 + v[1]**2) + mass * GRAVITY * p[1]
            return total

        def gap() -> float:
            worst = max([float(np.linalg.norm(np.array(mbs.GetMarkerOutput(a, output.Position))
                                              - np.array(mbs.GetMarkerOutput(b, output.Position))))
                         for a, b in joints] + [0.0])
            return max([worst] + [abs(mbs.GetNodeOutput(node, output.Position)[1]) for node in lines])

        def angle(name: str) -> float:
            return float(mbs.GetNodeOutput(bodies[name][1], output.Rotation)[2])

        return container, mbs, energy, gap, angle

    settings = exu.SimulationSettings()
    settings.timeIntegration.numberOfSteps = int(round(span / STEP))
    settings.timeIntegration.endTime = span
    settings.timeIntegration.verboseMode = 0
    settings.solutionSettings.writeSolutionToFile = False
    settings.solutionSettings.sensorsWritePeriod = 1e9
    settings.displayStatistics = False
    settings.displayComputationTime = False
    result = {"version": exu.__version__, "runs": {}, "per_eval": {}}
    slider_mass, message = 0.0, "SolveDynamic returned False"
    for attempt in range(2):
        walls, ok = [], True
        try:
            for _ in range(repeat):
                system = build(slider_mass)   # a fresh system per run (the solver moves its state)
                result["E0"] = system[2]()
                started = time.perf_counter()
                ok = system[1].SolveDynamic(settings, solverType=exu.DynamicSolverType.GeneralizedAlpha)
                walls.append(time.perf_counter() - started)
                if walls[-1] > 1.0:
                    break
        except Exception as error:  # noqa: BLE001
            ok, message = False, f"{type(error).__name__}: {error}"[:120]
        if ok or not tree.slider or attempt:
            break
        slider_mass = SLIDER_MASS     # a massless slider point did not solve: give it a small mass
    label = "gen.-alpha h=1ms, redundant 2D bodies (recommended)"
    if not ok or not walls:
        result["runs"][label] = {"error": message if not walls else "SolveDynamic returned False"}
        return result
    _, mbs, energy, gap, angle = system
    wall = {"median": statistics.median(walls), "min": min(walls), "max": max(walls), "runs": walls}
    run = {"wall_s": wall, "span": span, "slider_mass": slider_mass, "dE_end": abs(energy() - result["E0"]),
           "gap_end": gap(), "t_end": float(mbs.systemData.GetTime()), "finite": True}
    if tree.branch:
        crank, rod_angle = angle(tree.branch[0]), angle(tree.branch[1])
        run["branch_deviation_end"] = float(abs(wrap(rod_angle + crank)))  # θ2 = φ_rod - φ_crank; θ2 + 2θ1
    result["runs"][label] = run
    steps = settings.timeIntegration.numberOfSteps
    result["per_eval"]["gen.-alpha time step (no one-call forward dynamics)"] = {
        key: value / steps * 1e6 for key, value in wall.items() if key != "runs"}
    return result


TOOLS = {"MuJoCo": ("mujoco", mujoco_measure), "Pinocchio": ("pinocchio", pinocchio_measure),
         "Exudyn": ("exudyn", exudyn_measure)}


def installed(module: str) -> bool:
    try:
        importlib.import_module(module)
        return True
    except Exception:  # noqa: BLE001 - a broken install counts as missing
        return False


# ------------------------------------------------------------------------------------ profile
def profile_run(model: cmbs.Model, formulation: str, integrator: str, span: float, project: bool) -> dict:
    """Where the wall time of one simulate() goes, by timing wrappers around the model evaluation
    (Model.evaluate), the formulation (accelerations, after_step), the drift projection and the
    integrator call; the remainder of the integration is the integrator's own work (Runge-Kutta
    arithmetic, error norm, dense output, the vector-field glue).  Uses cmbs internals (module
    attributes of cmbs.simulate); skipped if they changed."""
    module = sys.modules["cmbs.simulate"]
    try:
        originals = {"integrate_explicit": module.integrate_explicit, "project_state": module.project_state,
                     "evaluate": cmbs.Model.evaluate}
    except AttributeError as error:
        return {"skipped": f"cmbs internals changed: {error!r}"}
    clock = time.perf_counter
    phase = ["setup"]
    totals: dict[tuple[str, str], list] = {}

    def add(kind: str, seconds: float) -> None:
        entry = totals.setdefault((phase[0], kind), [0.0, 0])
        entry[0] += seconds
        entry[1] += 1

    def timed(kind, function):
        def wrapper(*args, **kwargs):
            started = clock()
            try:
                return function(*args, **kwargs)
            finally:
                add(kind, clock() - started)
        return wrapper

    def integrate(*args, **kwargs):
        phase[0] = "integration"
        started = clock()
        try:
            return originals["integrate_explicit"](*args, **kwargs)
        finally:
            add("total", clock() - started)
            phase[0] = "recording"

    class TimedSolver:
        def __init__(self, solver):
            self.solver = solver
            self.adjusts_state = solver.adjusts_state
            self.accelerations = timed("formulation solve", solver.accelerations)
            self.after_step = timed("formulation after_step", solver.after_step)

        def __getattr__(self, name):
            return getattr(self.solver, name)

    class TimedFormulation:
        def __init__(self, inner):
            self.inner = inner
            self.name = inner.name

        def bind(self, model):
            return TimedSolver(self.inner.bind(model))

    options = {"dt": STEP} if integrator == "rk4" else {"dt": STEP, "rtol": TOLERANCE, "atol": TOLERANCE}
    module.integrate_explicit = integrate
    module.project_state = timed("drift projection", originals["project_state"])
    cmbs.Model.evaluate = timed("model evaluation", originals["evaluate"])
    try:
        started = clock()
        trajectory = cmbs.simulate(model, t_end=span, formulation=TimedFormulation(cmbs.formulation(formulation)),
                                   integrator=integrator, project=project, **options)
        call = clock() - started
    finally:
        module.integrate_explicit = originals["integrate_explicit"]
        module.project_state = originals["project_state"]
        cmbs.Model.evaluate = originals["evaluate"]
    integration = totals.get(("integration", "total"), [0.0, 0])[0]
    parts = {kind: {"s": value[0], "calls": value[1]} for (where, kind), value in totals.items()
             if where == "integration" and kind != "total"}
    # the drift projection evaluates the model itself: count those evaluations once, under projection
    accounted = sum(part["s"] for kind, part in parts.items() if kind != "model evaluation")
    evaluation = parts.get("model evaluation", {"s": 0.0})["s"]
    if "drift projection" in parts:
        evaluation_in_field = trajectory.info.get("evaluations", 0)
        per_call = evaluation / max(parts["model evaluation"]["calls"], 1)
        evaluation = per_call * evaluation_in_field
        parts["model evaluation"] = {"s": evaluation, "calls": evaluation_in_field}
    parts["integrator + vector-field glue (remainder)"] = {"s": integration - accounted - evaluation, "calls": None}
    return {"formulation": formulation, "integrator": integrator, "project": project, "span": span,
            "status": trajectory.info["status"], "evaluations": trajectory.info.get("evaluations"),
            "steps": trajectory.info.get("steps"), "wall_time": trajectory.info["wall_time"],
            "integration_s": integration, "call_s": call, "recording_s": call - integration, "parts": parts,
            "note": "timing wrappers add ~0.3 µs per wrapped call"}


def integrator_alone() -> dict:
    """µs per RK4 step of cmbs's explicit integrator with a vector field that costs almost nothing
    (cmbs internals; empty if they changed)."""
    try:
        from cmbs.integrate.explicit import integrate
        from cmbs.integrate.tableaus import TABLEAUS
    except ImportError:
        return {}
    result = {}
    for size in (8, 76):
        zeros = np.zeros(size)
        times = np.linspace(0.0, 1.0, 1001)
        started = time.perf_counter()
        integrate(lambda t, y: zeros.copy(), np.zeros(size), times, tableau=TABLEAUS["rk4"], step=STEP)
        result[f"d={size}"] = (time.perf_counter() - started) / 1000 * 1e6
    return result


def profile_solve(model: cmbs.Model, formulation: str, calls: int = 3000, top: int = 8) -> list[tuple[str, float]]:
    """cProfile of ``calls`` evaluate + accelerations: share of own time per function (top ones)."""
    q, qd, u = model.q0.copy(), model.qd0.copy(), np.zeros(model.n_u)
    terms = model.new_terms()
    solver = cmbs.formulation(formulation).bind(model)
    profiler = cProfile.Profile()
    profiler.enable()
    for _ in range(calls):
        model.evaluate(q, qd, 0.0, u, out=terms)
        solver.accelerations(terms, q, qd, 0.0)
    profiler.disable()
    stats = pstats.Stats(profiler).stats
    own = {}
    for (filename, line, name), (_, _, tottime, _, _) in stats.items():
        where = os.path.basename(filename) if filename != "~" else ""
        key = f"{where}:{name}" if where else name
        own[key] = own.get(key, 0.0) + tottime
    total = sum(own.values())
    return [(key, value / total) for key, value in sorted(own.items(), key=lambda kv: -kv[1])[:top]]


# ------------------------------------------------------------------------------------ printing
def print_runs(runs: list[dict], singular: bool) -> None:
    head = (f"    {'formulation':<19} {'int.':<4} {'span':>4} {'path':<8} {'wall s':>20} {'x real':>7} {'loop s':>7}"
            f" {'call s':>7} {'evals':>6} {'max|Φ|':>8} {'|ΔE|max':>8} {'|ΔE|end':>8}")
    if singular:
        head += f" {'relE end':>8} {'branch':>6}"
    print(head + "  status")
    for run in runs:
        name = run["formulation"] + ("+proj" if run["project"] else "")
        if run["status"] == "error":
            print(f"    {name:<19} {run['integrator']:<4} {run['span']:>4g}   ERROR {run['message']}")
            continue
        loop = f"{run['loop_s']:.3g}" if run.get("loop_s") is not None else "-"
        line = (f"    {name:<19} {run['integrator']:<4} {run['span']:>4g} {run['path']:<8} {fmt_s(run['wall_s']):>20}"
                f" {run['real_time_factor']:>7.3g} {loop:>7} {run['call_s']['median']:>7.3g} {run['evaluations']:>6}"
                f" {run['max_constraint_error']:>8.1e} {run['dE_max']:>8.1e} {run['dE_end']:>8.1e}")
        if singular:
            kept = "kept" if run.get("branch_kept") else "lost"
            line += f" {run['relative_dE_end']:>8.1e} {kept:>6}"
        status = run["status"] if run["status"] == "success" else \
            f"FAILED at t = {run['t_reached']:.3g} s: {run['message'][:70]}"
        print(line + "  " + status)
    slow = [run for run in runs if run.get("first_call_s", 0.0) > 2.0]
    for run in slow:
        print(f"    (first call of {run['formulation']} {run['integrator']}: {run['first_call_s']:.1f} s, "
              "numba compilation of the compiled path; cached on disk for later processes)")


def best(runs: list[dict], integrator: str, span: float, condition=lambda run: True) -> dict | None:
    candidates = [run for run in runs if run["integrator"] == integrator and passed(run, span) and condition(run)]
    return min(candidates, key=lambda run: run["wall_s"]["median"]) if candidates else None


# ------------------------------------------------------------------------------------ BLAS threads
PROBE = (("chain14-closed", ("udwadia-kalaba", "projection", "lagrange")),
         ("human", ("udwadia-kalaba", "projection", "lagrange")))


def blas_probe(batches: int, target: float) -> dict:
    """evaluate + accelerations, µs, of a few formulations (PROBE) under this process's BLAS threads."""
    result = {}
    for label, names in PROBE:
        model = next(case for case in CASES if case.label == label).load()
        q, qd, u = model.q0.copy(), model.qd0.copy(), np.zeros(model.n_u)
        terms = model.new_terms()
        for name in names:
            solver = cmbs.formulation(name).bind(model)

            def forward():
                model.evaluate(q, qd, 0.0, u, out=terms)
                return solver.accelerations(terms, q, qd, 0.0)
            result[f"{label} {name}"] = time_call(forward, batches, target)
    return result


def blas_probe_threads(threads: int, quick: bool) -> dict:
    """:func:`blas_probe` in a fresh interpreter with ``threads`` BLAS threads."""
    env = dict(os.environ, **{name: str(threads) for name in BLAS_VARIABLES})
    command = [sys.executable, os.path.abspath(__file__), "--blas-probe"] + (["--quick"] if quick else [])
    output = subprocess.run(command, env=env, check=True, capture_output=True, text=True).stdout
    return json.loads(output.strip().splitlines()[-1])


def git_state() -> dict:
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    try:
        head = subprocess.run(["git", "-C", root, "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", root, "status", "--porcelain", "src"], capture_output=True, text=True,
                               check=True).stdout.split("\n")
        return {"head": head, "src_changes_not_committed": [line.strip() for line in dirty if line.strip()]}
    except (OSError, subprocess.CalledProcessError) as error:
        return {"error": repr(error)}


# ------------------------------------------------------------------------------------ main
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true",
                        help="3 batches of ~0.05 s, single runs, shorter spans (targets still over 10 s)")
    parser.add_argument("--json", metavar="FILE", help="write all figures as JSON")
    parser.add_argument("--blas-probe", action="store_true", help=argparse.SUPPRESS)  # internal, see blas_probe
    args = parser.parse_args(argv)
    batches, target = (3, 0.05) if args.quick else (7, 0.2)
    if args.blas_probe:
        print(json.dumps(blas_probe(batches, target)))
        return 0
    repeat = 1 if args.quick else 3
    started = time.perf_counter()

    env = environment()
    env["git"] = git_state()
    env["blas_threads"] = {name: os.environ[name] for name in BLAS_VARIABLES}
    env["blas_threads_given"] = BLAS_THREADS_GIVEN
    tools = {name: installed(module) for name, (module, _) in TOOLS.items()}
    report: dict = {"environment": env, "tools_installed": tools, "method": {
        "per_eval": f"µs per call, median [min-max] of {batches} timeit batches of ~{target} s after warm-up",
        "runs": f"wall s, median [min-max] of up to {repeat} runs (one when a run takes > 1 s)",
        "rk4": f"h = {STEP}", "rk45": f"rtol = atol = {TOLERANCE}, output every {STEP} s"}, "cases": {}}
    print(f"cmbs {env['cmbs']}  python {env['python']}  numpy {env['numpy']}  numba {env['numba']}  "
          f"{env['processor']} x{env['cpu_count']}  load avg {env['load_average_start'][0]:.2f}")
    git = env["git"]
    print(f"cmbs tree: HEAD {git.get('head')}, uncommitted changes under src/: "
          + (", ".join(git.get("src_changes_not_committed", [])) or "none"))
    print("BLAS threads: " + ", ".join(f"{k}={v}" for k, v in env["blas_threads"].items())
          + ("" if any(BLAS_THREADS_GIVEN.values())
             else " (set by this benchmark; give OPENBLAS_NUM_THREADS to change)"))
    print("other tools: " + ", ".join(f"{name} {'installed' if ok else 'not installed'}" for name, ok in tools.items()))
    print(f"per evaluation: µs, median [min-max] of {batches} batches of ~{target} s; simulation walls: "
          f"median [min-max] of up to {repeat} runs{' (quick: shorter spans)' if args.quick else ''}\n")

    tool_cache: dict[str, dict] = {}
    for case in CASES:
        model = case.load()
        span = case.quick_span if args.quick else case.span
        result: dict = {"title": case.title, "n": model.n, "m": model.m, "span": span,
                        "E0": float(model.energy(model.q0, model.qd0))}
        report["cases"][case.label] = result
        print(f"== {case.label}: {case.title}; n = {model.n}, m = {model.m}, E0 = {result['E0']:.6g} J")

        per_eval = result["per_eval_us"] = cmbs_per_evaluation(model, batches, target)
        print("  forward dynamics per evaluation, evaluate + accelerations at the start state, µs:")
        print(f"    {'evaluate alone':<28} {fmt(per_eval['evaluate']):>24}")
        for name in FORMULATIONS + tuple(f"compiled {name}" for name in COMPILED_FORMULATIONS):
            stats = per_eval[name]
            print(f"    {name:<28} " + (f"{fmt(stats):>24}" if "median" in stats else f"ERROR {stats['error']}"))

        runs = []
        for name in case.formulations:
            for integrator in ("rk4", "rk45"):
                runs.append(cmbs_run(model, name, integrator, span, name in case.project, repeat))
        if args.quick and case.label == "four-bar" and span < 10.0:
            # the target is over 10 s: RK4 10 s with the formulation of the fastest 1 s RK4 run
            fastest = best(runs, "rk4", span)["formulation"]   # the fastest 1 s RK4 run
            runs.append(cmbs_run(model, fastest, "rk4", 10.0, False, 1))
        if args.quick:
            runs += [cmbs_run(model, name, integrator, extra_span, project, 1)
                     for name, integrator, extra_span, project in case.quick_extra]
        result["runs"] = runs
        what = "through the singular positions, " if case.singular else ""
        projected = "; +proj = project=True (coordinate and velocity projection after every step)" \
            if case.project else ""
        print(f"  cmbs.simulate {what}wall = info['wall_time'] (python path: the integration; compiled path: its loop "
              f"+ the recording), x real = span / wall, loop = info['loop_wall_time'] (compiled loop alone), "
              f"call = the whole simulate(){projected}:")
        print_runs(runs, case.singular)
        if case.label == "human" and span < 10.0:
            print(f"    (human: {span:g} s instead of 10 s: 10 s would take up to "
                  f"{10.0 / span * max(r['wall_s']['median'] for r in runs if 'wall_s' in r):.0f} s per run)")
        if case.singular:
            print("    branch: |θ2 + 2θ1| (mod 2π) < 1e-6 over the whole run; relE = |E - E0| / E0 at the end; "
                  "projection and udwadia-kalaba need project=True to pass the singular positions")

        # ---- other tools
        key = case.tools_from or case.label
        if case.tree is not None:
            tree = case.tree(model)
            measured = {}
            for name, (module, measure) in TOOLS.items():
                if not tools[name]:
                    continue
                try:
                    if name == "Exudyn":
                        measured[name] = measure(tree, span, repeat)
                    else:
                        measured[name] = measure(tree, span, repeat, batches, target)
                except Exception as error:  # noqa: BLE001 - one tool failing must not stop the benchmark
                    measured[name] = {"error": f"{type(error).__name__}: {error}"[:160]}
            tool_cache[case.label] = measured
        measured = tool_cache.get(key, {})
        result["tools"] = measured
        see = "" if key == case.label else f" (see {key})"
        print(f"  other tools, same mechanism and start, measured in this run{see}:")
        projection_us = per_eval["compiled projection"].get("median")
        fast_name = min((n for n in per_eval if n != "evaluate" and "median" in per_eval[n]),
                        key=lambda n: per_eval[n]["median"])
        fast_us = per_eval[fast_name]["median"]
        # the slider-crank: only runs that keep the energy (final relE <= 1e-6) count as "fastest"
        good = (lambda run: run["relative_dE_end"] <= TARGET_SLIDER_CRANK_ENERGY) if case.singular else \
            (lambda run: True)
        best_rk4, best_rk45 = best(runs, "rk4", span, good), best(runs, "rk45", span, good)
        result["ratios"] = {}
        for name in TOOLS:
            if not tools[name]:
                quoted = ANCHORS_QUOTED.get(case.label)
                print(f"    {name}: not installed" + ("; QUOTED from reference measurements, not measured here: "
                                                    + ", ".join(f"{k} {v:g}" for k, v in quoted[name].items())
                                                    if quoted else "; no quoted figure for this mechanism"))
                continue
            tool = measured.get(name, {})
            if "error" in tool:
                print(f"    {name}: ERROR {tool['error']}")
                continue
            print(f"    {name} {tool['version']} (E0 = {tool['E0']:.6g} J; cmbs {result['E0']:.6g} J):")
            for label, stats in tool["per_eval"].items():
                r1, r2 = ratio(projection_us, stats["median"]), ratio(fast_us, stats["median"])
                result["ratios"][f"{name} {label}"] = {"compiled projection/tool": r1, f"{fast_name}/tool": r2}
                print(f"      {label:<52} {fmt(stats):>22} µs   cmbs compiled projection / it {r1:>7}"
                      + ("" if fast_name == "compiled projection" else f", cmbs {fast_name} / it {r2:>7}"))
            for label, run in tool["runs"].items():
                if "error" in run:
                    print(f"      {label:<52} ERROR {run['error']}")
                    continue
                wall = run["wall_s"]["median"]
                text = f"      {label:<52} {fmt_s(run['wall_s']):>22} s  x{run['span'] / wall:>6.3g} real"
                if run.get("finite"):
                    text += f"  gap end {run['gap_end']:.1e} |ΔE| end {run['dE_end']:.1e}"
                    if "branch_deviation_end" in run:
                        kept = "kept" if run["branch_deviation_end"] < BRANCH_TOLERANCE else "lost"
                        text += f" relE end {run['dE_end'] / abs(tool['E0']):.1e} branch at end {kept}"
                else:
                    text += "  state non-finite"
                r4 = ratio(best_rk4["wall_s"]["median"] if best_rk4 else None, wall)
                r45 = ratio(best_rk45["wall_s"]["median"] if best_rk45 else None, wall)
                result["ratios"][f"{name} {label}"] = {"cmbs best rk4/tool": r4, "cmbs best rk45/tool": r45}
                print(text)
                print(f"      {'':<52} cmbs fastest{' (relE <= 1e-6)' if case.singular else ''} RK4 / it {r4:>7}, "
                      f"RK45 / it {r45:>7}"
                      + (f"  (RK4: {best_rk4['formulation']}, RK45: {best_rk45['formulation']})"
                         if best_rk4 and best_rk45 else ""))
        print()

    # ---- targets
    print("== targets of the project issue")
    cases = report["cases"]
    targets = {}
    four_bar_runs = [run for run in cases["four-bar"]["runs"] if run["integrator"] == "rk4"
                     and run.get("span") == 10.0]
    fastest = best(four_bar_runs, "rk4", 10.0)
    value = fastest["wall_s"]["median"] if fastest else None
    targets["four-bar RK4 h=1ms 10 s wall <= 0.1 s"] = {
        "value_s": value, "formulation": fastest and fastest["formulation"],
        "verdict": "PASS" if value is not None and value <= TARGET_FOUR_BAR_RK4_S else "MISS"}
    library = best(cases["four-bar-library"]["runs"], "rk4", cases["four-bar-library"]["span"])
    print(f"  10 s of the four-bar, RK4 h = 1 ms, wall <= {TARGET_FOUR_BAR_RK4_S} s: "
          + (f"{value:.3g} s ({fastest['formulation']}, the fastest formulation)" if value else "no successful run")
          + f"  {targets['four-bar RK4 h=1ms 10 s wall <= 0.1 s']['verdict']}"
          + (f"   [library four-bar: {library['wall_s']['median']:.3g} s for {library['span']:g} s, "
             f"{library['formulation']}]" if library else ""))
    for label, goal in TARGET_PROJECTION_US.items():
        stats = cases[label]["per_eval_us"]["compiled projection"]
        python_path = cases[label]["per_eval_us"]["projection"]
        verdict = "PASS" if stats["median"] <= goal else "MISS"
        targets[f"projection evaluation {label} <= {goal:g} µs"] = {"value_us": stats["median"], "verdict": verdict,
                                                                     "python_path_us": python_path["median"]}
        extra = f"   [Python path (numpy SVD): {python_path['median']:.3g} µs"
        if label == "four-bar":
            extra += (f"; library four-bar compiled: "
                      f"{cases['four-bar-library']['per_eval_us']['compiled projection']['median']:.3g} µs")
        print(f"  one projection-formulation evaluation (compiled: terms + solve), {label}, <= {goal:g} µs: "
              f"{fmt(stats)} µs  {verdict}{extra}]")
    exudyn = cases["slider-crank"]["tools"].get("Exudyn", {}).get("runs", {})
    exudyn_run = next(iter(exudyn.values()), {}) if exudyn else {}
    exudyn_wall = exudyn_run.get("wall_s", {}).get("median") if exudyn_run.get("span") == 10.0 else None
    for label in ("slider-crank", "slider-crank-joint"):
        case_runs = [run for run in cases[label]["runs"] if run.get("span") == 10.0]
        good = [run for run in case_runs if passed(run, 10.0) and run.get("singular_crossings", 0) >= 1
                and run["relative_dE_end"] <= TARGET_SLIDER_CRANK_ENERGY]
        choice = min(good, key=lambda run: run["wall_s"]["median"]) if good else None
        if choice is None:
            verdict = "MISS"
            text = "no 10 s run through the singular positions with final relative energy error <= 1e-6"
        else:
            wall = choice["wall_s"]["median"]
            verdict = "PASS" if wall < TARGET_SLIDER_CRANK_S else "MISS"
            strict = "also" if choice["relative_dE_max"] <= TARGET_SLIDER_CRANK_ENERGY else "but NOT"
            text = (f"{wall:.3g} s ({choice['formulation']}{'+proj' if choice['project'] else ''}, "
                    f"{choice['integrator'].upper()}; final relE {choice['relative_dE_end']:.1e}, {strict} over the "
                    f"whole run: max relE {choice['relative_dE_max']:.1e}; branch "
                    f"{'kept' if choice.get('branch_kept') else 'lost'})")
            if exudyn_wall:
                text += f"; Exudyn in this run {exudyn_wall:.3g} s, cmbs / Exudyn = {wall / exudyn_wall:.3g}x"
        targets[f"{label} 10 s through singular positions, relE <= 1e-6, < 0.24 s"] = {
            "verdict": verdict, "run": choice and {k: choice[k] for k in ("formulation", "integrator", "project",
                                                                          "relative_dE_end", "relative_dE_max")},
            "wall_s": choice and choice["wall_s"]["median"], "exudyn_this_run_s": exudyn_wall}
        print(f"  {label}: 10 s through the singular positions, final relE <= 1e-6, wall < Exudyn's "
              f"{TARGET_SLIDER_CRANK_S} s: {text}  {verdict}")
    targets["slider-crank at >= 100x real time"] = real_time_slider_crank()
    report["targets"] = targets

    # ---- profile
    print("\n== where the time of a run goes (Python path: the timing wrappers keep the compiled loop off; "
          "the parts add up to the integration wall)")
    profiles = {}
    spans = {label: cases[label]["span"] for label in cases}
    for label, formulation, integrator, project in (("four-bar", "projection", "rk4", False),
                                                    ("four-bar", "lagrange", "rk4", False),
                                                    ("human", "projection", "rk4", False),
                                                    ("slider-crank", "projection", "rk45", True)):
        case = next(c for c in CASES if c.label == label)
        span = min(spans[label], 1.0) if integrator == "rk4" else spans[label]
        profile = profile_run(case.load(), formulation, integrator, span, project)
        profiles[f"{label} {formulation} {integrator}"] = profile
        if "skipped" in profile:
            print(f"  {label}: skipped ({profile['skipped']})")
            continue
        integration = profile["integration_s"]
        print(f"  {label}, {formulation}{'+proj' if project else ''}, {integrator.upper()}, {span:g} s: integration "
              f"{integration:.3g} s for {profile['evaluations']} evaluations = "
              f"{integration / profile['evaluations'] * 1e6:.0f}"
              f" µs per evaluation; recording {profile['recording_s']:.3g} s more")
        for kind, part in sorted(profile["parts"].items(), key=lambda kv: -kv[1]["s"]):
            per = f"{part['s'] / part['calls'] * 1e6:7.1f} µs x {part['calls']}" if part["calls"] else ""
            print(f"    {kind:<44} {part['s']:7.3f} s {100 * part['s'] / integration:5.1f} %  {per}")
    report["profile_runs"] = profiles
    alone = integrator_alone()
    report["integrator_alone_us_per_step"] = alone
    if alone:
        print("  the integrator alone (trivial vector field, 1 s at h = 1 ms, d = 8 / 76 states): RK4 "
              + ", ".join(f"{v:.0f} µs" for v in alone.values()) + " per step (4 evaluations)")
    compiled = [(label, run) for label in cases for run in cases[label]["runs"] if run.get("path") == "compiled"
                and run.get("loop_s") and run["status"] == "success"
                and run["span"] == max(r["span"] for r in cases[label]["runs"])]
    if compiled:
        print("  compiled RK4 path (cmbs.integrate.compiled_rk4): loop = model + solve + RK4 inside numba; the rest of info['wall_time'] "
              "is building the trajectory (energy, -Aᵀλ at every output)")
        for label, run in compiled:
            wall, loop = run["wall_s"]["median"], run["loop_s"]
            print(f"    {label:<18} {run['formulation']:<11} {run['span']:>4g} s: loop {loop:.3g} s "
                  f"({loop / run['evaluations'] * 1e6:.1f} µs per evaluation), recording {wall - loop:.3g} s "
                  f"({100 * (wall - loop) / wall:.0f} % of wall)")
    print("\n  inside one evaluate + accelerations (cProfile, own time per function, top 8):")
    solves = {}
    for label, formulation in (("four-bar", "projection"), ("four-bar", "lagrange"), ("human", "projection")):
        case = next(c for c in CASES if c.label == label)
        top = profile_solve(case.load(), formulation, calls=1000 if args.quick else 3000)
        solves[f"{label} {formulation}"] = top
        print(f"    {label}, {formulation}: " + ", ".join(f"{name} {100 * share:.0f}%" for name, share in top))
    report["profile_solve"] = solves

    print("\n== BLAS threads: evaluate + accelerations, µs, this process vs a fresh one with "
          f"{os.cpu_count()} BLAS threads (OpenBLAS's default here)")
    try:
        single = blas_probe(batches, target)
        threaded = blas_probe_threads(os.cpu_count() or 2, args.quick)
        report["blas_threads_probe"] = {"this_process": single, f"{os.cpu_count()}_threads": threaded}
        for key, stats in single.items():
            other = threaded[key]
            print(f"  {key:<36} {env['blas_threads']['OPENBLAS_NUM_THREADS']} thread(s) {fmt(stats):>24}   "
                  f"{os.cpu_count()} threads {fmt(other):>24}   ratio {other['median'] / stats['median']:.2g}x")
    except Exception as error:  # noqa: BLE001
        print(f"  skipped: {error!r}")

    report["environment"]["load_average_end"] = os.getloadavg()
    report["elapsed_s"] = time.perf_counter() - started
    print(f"\nload average at start / end: {env['load_average_start'][0]:.2f} / {os.getloadavg()[0]:.2f} on "
          f"{env['cpu_count']} cores; elapsed {report['elapsed_s']:.0f} s")
    write_report(args.json, report, default=str)
    return 0


if __name__ == "__main__":
    sys.exit(main())
