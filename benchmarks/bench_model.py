#!/usr/bin/env python
"""Cost of one evaluation of the equations-of-motion terms of a cmbs model.

    python benchmarks/bench_model.py [--quick] [--json FILE]

For the thesis four-bar (5 coordinates), the 14-DOF human model (38 coordinates) and the
14-link tip-pinned chain (26 coordinates) it measures:

1. ``model.evaluate(q, qd, t, u, out=terms)``: M, Q, Φ, A, γ and Φ_t together into a
   preallocated workspace (the fast path), µs per call;
2. the same terms from a plain vectorised-numpy implementation written below from an
   independent description of each mechanism; before timing, the benchmark asserts that it
   reproduces cmbs's M, Q, Φ, A, γ, Φ_t to 1e-12 (relative to the largest entry, or absolute
   below 1), so the ratio numpy/cmbs compares the same computation;
3. the convenience calls (``model.jacobian(q)`` ...), which return fresh arrays;
4. where the time of ``evaluate`` goes: Python wrappers, numba dispatch, kernel body;
5. import + build of the human model in a fresh interpreter, first (cold numba cache) and warm.

Per-call times: median [min-max] of 7 timeit batches of ~0.2 s each after warm-up (the method of
the reference measurements of the other tools; own helper below).  ``--quick``: 3 batches of ~0.05 s,
2 warm launches and no cold launch.  The targets (issue: ≤ 3 µs four-bar, ≤ 10 µs human, all
five terms together) are checked against the median.  Figures of other tools are quoted from
reference measurements made beside them, not measured here.
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import timeit
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

import cmbs
from reporting import write_report

# ------------------------------------------------------------------------------------ targets
TARGETS_US = {"four-bar": 3.0, "human": 10.0}  # project issue: all five terms together

# Quoted from reference measurements of the other tools (2026-11-21, same machine class): per-evaluation
# FORWARD DYNAMICS (terms + KKT solve or ABA -> accelerations), µs, median.  Their four-bar is
# the anchors' 1-DOF 0.5/1/1 m crank-rocker, not the thesis four-bar of cmbs; chain14_closed is
# the same mechanism as cmbs's chain(links=14, closed=True).  Not measured in this run.
ANCHORS_QUOTED = {
    "four-bar": {
        "anchor model": "fourbar (1 DOF, l = 0.5/1/1 m; a different four-bar)",
        "Pinocchio constraintDynamics (C++ call)": "3.0",
        "MuJoCo mj_forward": "3.9-7.0",
        "numba dense natural-coordinate KKT": "3.7",
        "plain numpy natural-coordinate KKT": "105",
    },
    "chain14-closed": {
        "anchor model": "chain14_closed (same mechanism)",
        "Pinocchio constraintDynamics (C++ call)": "10.6",
        "MuJoCo mj_forward": "12.6-13.4",
        "numba dense natural-coordinate KKT": "21",
        "plain numpy natural-coordinate KKT": "144",
    },
}


# ------------------------------------------------------------------------------------ timing
def time_call(fn: Callable[[], object], repeat: int = 7, target: float = 0.2) -> dict:
    """µs per call of ``fn``: median, min, max over ``repeat`` batches of about ``target`` s.

    ``fn`` is called once first (a compiled function's first call loads or compiles its code);
    the batch size is then found by growing it fourfold until one batch takes > target/4 (this is
    also the warm-up), then scaled to ``target``.
    """
    fn()
    timer = timeit.Timer(fn)
    number = 1
    while True:
        elapsed = timer.timeit(number)
        if elapsed > target / 4 or number > 10**7:
            break
        number *= 4
    number = max(1, int(number * target / max(elapsed, 1e-9)))
    samples = [timer.timeit(number) / number * 1e6 for _ in range(repeat)]
    return {"median": statistics.median(samples), "min": min(samples), "max": max(samples),
            "number": number, "repeat": repeat, "samples": samples}


def time_interleaved(fns: dict[str, Callable[[], object]], repeat: int, target: float) -> dict[str, dict]:
    """Like :func:`time_call` for several functions, their batches interleaved round by round so
    that all of them see the same machine load (used for the breakdown, where differences
    matter)."""
    timers, numbers = {}, {}
    for name, fn in fns.items():
        fn()
        timers[name] = timeit.Timer(fn)
        number = 1
        while True:
            elapsed = timers[name].timeit(number)
            if elapsed > target / 4 or number > 10**7:
                break
            number *= 4
        numbers[name] = max(1, int(number * target / max(elapsed, 1e-9)))
    samples: dict[str, list[float]] = {name: [] for name in fns}
    for _ in range(repeat):
        for name in fns:
            samples[name].append(timers[name].timeit(numbers[name]) / numbers[name] * 1e6)
    return {name: {"median": statistics.median(s), "min": min(s), "max": max(s), "number": numbers[name],
                   "repeat": repeat, "samples": s} for name, s in samples.items()}


def fmt(stats: dict, digits: int = 3) -> str:
    return f"{stats['median']:.{digits}g} [{stats['min']:.{digits}g}-{stats['max']:.{digits}g}]"


# ------------------------------------------------------------------------------------ reference
@dataclass
class Mechanism:
    """A planar natural-coordinate mechanism described independently of cmbs's builder.

    Coordinates: (x, z) of every moving point in ``points`` order, then the angles.  Constraints:
    one rigid row per segment, one row per angle, one per driver (cmbs's names: ``rigid <seg>``,
    ``angle <name>``, the driver's name).  ``angles``: (name, u, v) with u, v a pair of point
    names (direction b - a) or None for the x axis; the angle is measured from u to v.
    """

    points: dict[str, tuple[float, float, bool]]                          # name -> (x, z, fixed)
    segments: list[tuple[str, str, str, float, float, float, float, float]]  # name, i, j, L, m, x̄, z̄, I_G
    angles: list[tuple[str, tuple[str, str] | None, tuple[str, str]]] = field(default_factory=list)
    drivers: list[tuple[str, str, Callable[[float], tuple[float, float, float]]]] = field(default_factory=list)
    actuators: list[tuple[str, str, float]] = field(default_factory=list)  # name, coordinate, gain
    gravity: tuple[float, float] = (0.0, -9.81)


class NumpyNatural:
    """Plain vectorised-numpy evaluation of M, Q, Φ, A, γ, Φ_t of a :class:`Mechanism`.

    Same equations as cmbs's natural coordinates (García de Jalón & Bayo): rigid rows
    Φ = d·d - L², angle rows Φ = cos φ (u×v) - sin φ (u·v), driver rows Φ = q_c - f(t); γ is
    -(Ȧq̇) - Φ_tt derived here by hand; M constant (segment mass matrices assembled once);
    Q = gravity (constant) + B u.  Fixed points and the x axis are constants appended to q.
    """

    def __init__(self, mech: Mechanism):
        self.coordinate_names: list[str] = []
        slot: dict[str, tuple[int, int]] = {}
        constants: list[float] = []
        for name, (x, z, fixed) in mech.points.items():
            if not fixed:
                slot[name] = (len(self.coordinate_names), len(self.coordinate_names) + 1)
                self.coordinate_names += [f"{name}.x", f"{name}.z"]
        self.coordinate_names += [name for name, _, _ in mech.angles]
        n = self.n = len(self.coordinate_names)
        for name, (x, z, fixed) in list(mech.points.items()) + [("<origin>", (0.0, 0.0, True)),
                                                                  ("<x axis>", (1.0, 0.0, True))]:
            if fixed:
                slot[name] = (n + len(constants), n + len(constants) + 1)
                constants += [x, z]
        self.constants = np.array(constants)
        self.zero_constants = np.zeros(len(constants))
        n_ext = n + len(constants)
        index = {name: k for k, name in enumerate(self.coordinate_names)}

        # rigid rows: columns (x_i, z_i, x_j, z_j)
        self.rigid_i = np.array([slot[s[1]] for s in mech.segments], dtype=np.int64).reshape(-1, 2)
        self.rigid_j = np.array([slot[s[2]] for s in mech.segments], dtype=np.int64).reshape(-1, 2)
        self.length2 = np.array([s[3] ** 2 for s in mech.segments])
        # angle rows: columns (u_a, u_b, v_a, v_b) x/z, then the angle coordinate
        def direction(spec):
            return (slot["<origin>"], slot["<x axis>"]) if spec is None else (slot[spec[0]], slot[spec[1]])
        self.u_a = np.array([direction(a[1])[0] for a in mech.angles], dtype=np.int64).reshape(-1, 2)
        self.u_b = np.array([direction(a[1])[1] for a in mech.angles], dtype=np.int64).reshape(-1, 2)
        self.v_a = np.array([direction(a[2])[0] for a in mech.angles], dtype=np.int64).reshape(-1, 2)
        self.v_b = np.array([direction(a[2])[1] for a in mech.angles], dtype=np.int64).reshape(-1, 2)
        self.angle_coordinate = np.array([index[a[0]] for a in mech.angles], dtype=np.int64)
        self.driver_coordinate = np.array([index[d[1]] for d in mech.drivers], dtype=np.int64)
        self.driver_functions = [d[2] for d in mech.drivers]
        k_r, k_a, k_d = len(mech.segments), len(mech.angles), len(mech.drivers)
        self.constraint_names = ([f"rigid {s[0]}" for s in mech.segments] + [f"angle {a[0]}" for a in mech.angles]
                                 + [d[0] for d in mech.drivers])
        self.m = k_r + k_a + k_d
        self.n_ext = n_ext
        self.zeros_static = np.zeros(k_r + k_a)
        self.has_angles = k_a > 0

        # gathers in component-major layout: rigid (4, k_r) = x_i, z_i, x_j, z_j; angle (9, k_a) =
        # x, z of u's start and end, of v's start and end, the angle coordinate
        self.rigid_columns = np.hstack([self.rigid_i, self.rigid_j]).T.copy()
        self.angle_columns = np.hstack([self.u_a, self.u_b, self.v_a, self.v_b,
                                        self.angle_coordinate[:, None]]).T.copy()
        # flat positions in the (m, n_ext) Jacobian of every value the evaluation produces, in
        # the order the values are concatenated; np.bincount sums repeated columns of one row
        rows_r = np.arange(k_r)[None, :]
        rows_a = k_r + np.arange(k_a)[None, :]
        rows_d = k_r + k_a + np.arange(k_d)
        self.flat = np.concatenate([(rows_r * n_ext + self.rigid_columns).ravel(),
                                    (rows_a * n_ext + self.angle_columns).ravel(),
                                    rows_d * n_ext + self.driver_coordinate])
        self.driver_ones = np.ones(k_d)

        # constant mass matrix and gravity forces, r_P = C (r_i, r_j) with
        # C = [(1-a) I - b R, a I + b R], a = x̄/L, b = z̄/L, R = 90° rotation; M = ∫CᵀC dm
        mass_ext = np.zeros((n_ext, n_ext))
        gravity_ext = np.zeros(n_ext)
        R = np.array([[0.0, -1.0], [1.0, 0.0]])
        I2 = np.eye(2)
        g = np.array(mech.gravity)
        for (_, i, j, length, mass, along, across, inertia_g), ci, cj in zip(mech.segments, self.rigid_i, self.rigid_j):
            A_ = mass * along / length                                 # ∫ a dm
            B_ = mass * across / length                                # ∫ b dm
            c = (inertia_g + mass * (along**2 + across**2)) / length**2  # ∫ (a² + b²) dm
            block = np.block([[(mass - 2 * A_ + c) * I2, (A_ - c) * I2 + B_ * R],
                              [(A_ - c) * I2 - B_ * R, c * I2]])
            idx = np.concatenate([ci, cj])
            mass_ext[np.ix_(idx, idx)] += block
            gravity_ext[idx] += np.concatenate([((mass - A_) * I2 + B_ * R) @ g, (A_ * I2 - B_ * R) @ g])
        self.M = mass_ext[:n, :n].copy()
        self.M.setflags(write=False)
        self.Q_gravity = gravity_ext[:n].copy()
        self.actuator_names = [a[0] for a in mech.actuators]
        self.B = np.zeros((n, len(mech.actuators)))
        for k, (_, coordinate, gain) in enumerate(mech.actuators):
            self.B[index[coordinate], k] = gain

    def evaluate(self, q, qd, t, u):
        """(M, Q, Φ, A, γ, Φ_t) at the state, fresh arrays (M is the constant matrix)."""
        x = np.concatenate((q, self.constants))
        v = np.concatenate((qd, self.zero_constants))
        # rigid: Φ = d·d - L², A = (-2d, 2d), γ = -2 ḋ·ḋ, d = r_j - r_i
        X, V = x[self.rigid_columns], v[self.rigid_columns]
        dx, dz = X[2] - X[0], X[3] - X[1]
        dvx, dvz = V[2] - V[0], V[3] - V[1]
        phi_r = dx * dx + dz * dz - self.length2
        gamma_r = -2.0 * (dvx * dvx + dvz * dvz)
        values_r = 2.0 * np.concatenate((-dx, -dz, dx, dz))
        if not self.has_angles:  # skip the empty section (the chain has no angles)
            return self._finish(x, t, u, phi_r, gamma_r, values_r)
        # angle: Φ = c (u×w) - s (u·w), c, s = cos, sin of the angle coordinate φ
        X, V = x[self.angle_columns], v[self.angle_columns]
        ux, uz, wx, wz = X[2] - X[0], X[3] - X[1], X[6] - X[4], X[7] - X[5]
        dux, duz, dwx, dwz = V[2] - V[0], V[3] - V[1], V[6] - V[4], V[7] - V[5]
        f, df = X[8], V[8]
        c, s = np.cos(f), np.sin(f)
        cross = ux * wz - uz * wx
        dot = ux * wx + uz * wz
        phi_a = c * cross - s * dot
        gux, guz = c * wz - s * wx, -c * wx - s * wz   # ∂Φ/∂u
        gwx, gwz = -c * uz - s * ux, c * ux - s * uz   # ∂Φ/∂w
        # Φ̈ = A q̈ + (velocity-quadratic terms), these from d²/dt² of c·cross and s·dot
        dcross = dux * wz + ux * dwz - duz * wx - uz * dwx
        ddot = dux * wx + ux * dwx + duz * wz + uz * dwz
        df2 = df * df
        gamma_a = -(-c * df2 * cross - 2.0 * s * df * dcross + 2.0 * c * (dux * dwz - duz * dwx)
                    + s * df2 * dot - 2.0 * c * df * ddot - 2.0 * s * (dux * dwx + duz * dwz))
        values_a = np.concatenate((-gux, -guz, gux, guz, -gwx, -gwz, gwx, gwz, -s * cross - c * dot))
        return self._finish(x, t, u, np.concatenate((phi_r, phi_a)), np.concatenate((gamma_r, gamma_a)),
                            np.concatenate((values_r, values_a)))

    def _finish(self, x, t, u, phi, gamma, values):
        """Append the driver rows, scatter the Jacobian values, add the input forces."""
        phi_t = self.zeros_static.copy()
        if self.driver_functions:  # Φ = q_c - f(t), Φ_t = -f', γ = f''
            ft = np.array([function(t) for function in self.driver_functions])
            phi = np.concatenate((phi, x[self.driver_coordinate] - ft[:, 0]))
            gamma = np.concatenate((gamma, ft[:, 2]))
            phi_t = np.concatenate((phi_t, -ft[:, 1]))
            values = np.concatenate((values, self.driver_ones))
        A = np.bincount(self.flat, values, self.m * self.n_ext).reshape(self.m, self.n_ext)[:, :self.n]
        Q = self.Q_gravity + self.B @ u if self.B.shape[1] else self.Q_gravity.copy()
        return self.M, Q, phi, A, gamma, phi_t


# ------------------------------------------------------------------------------------ mechanisms
def four_bar_mechanism() -> Mechanism:
    """src/cmbs/library/four-bar.toml restated: ground A (0,0), B (10,0); crank A-P1 2 m 1 kg,
    coupler P1-P2 10 m 5 kg, rocker P2-B 6 m 3 kg (the file's inertia literals); absolute crank
    angle alpha driven by (π/4) sin(π t - π/2); torque actuator on alpha."""
    def crank(t):
        a = math.pi * t - math.pi / 2
        return (math.pi / 4 * math.sin(a), math.pi / 4 * math.pi * math.cos(a),
                -math.pi / 4 * math.pi**2 * math.sin(a))
    return Mechanism(
        points={"A": (0.0, 0.0, True), "B": (10.0, 0.0, True), "P1": (0, 0, False), "P2": (0, 0, False)},
        segments=[("crank", "A", "P1", 2.0, 1.0, 1.0, 0.0, 0.333333333333333),
                  ("coupler", "P1", "P2", 10.0, 5.0, 5.0, 0.0, 41.6666666666667),
                  ("rocker", "P2", "B", 6.0, 3.0, 3.0, 0.0, 9.0)],
        angles=[("alpha", None, ("A", "P1"))],
        drivers=[("crank", "alpha", crank)],
        actuators=[("torque", "alpha", 1.0)])


def human_mechanism() -> Mechanism:
    """The 12-segment human of the thesis: topology and angle definitions restated from
    cmbs/library/human.py's docstring; segment parameters from its published table (SEGMENTS)."""
    from cmbs.library.human import SEGMENTS

    points = {name: (0.0, 0.0, False) for name in ("hip", "neck", "head")}
    segments = []

    def segment(name, kind, i, j):
        length, along, across, mass, inertia = SEGMENTS[kind]
        segments.append((name, i, j, length, mass, along, across, inertia))

    segment("trunk", "trunk", "hip", "neck")
    segment("head", "head", "neck", "head")
    down = ("neck", "hip")
    angles = [("trunk", None, ("hip", "neck")), ("neck", ("hip", "neck"), ("neck", "head"))]
    for side in "rl":
        for p in ("knee", "ankle", "toe", "elbow", "wrist"):
            points[f"{side}_{p}"] = (0.0, 0.0, False)
        segment(f"{side}_arm", "arm", "neck", f"{side}_elbow")
        segment(f"{side}_forearm", "forearm", f"{side}_elbow", f"{side}_wrist")
        segment(f"{side}_thigh", "thigh", "hip", f"{side}_knee")
        segment(f"{side}_shank", "shank", f"{side}_knee", f"{side}_ankle")
        segment(f"{side}_foot", "foot", f"{side}_ankle", f"{side}_toe")
        angles += [(f"{side}_hip", down, ("hip", f"{side}_knee")),
                   (f"{side}_knee", ("hip", f"{side}_knee"), (f"{side}_knee", f"{side}_ankle")),
                   (f"{side}_ankle", (f"{side}_knee", f"{side}_ankle"), (f"{side}_ankle", f"{side}_toe")),
                   (f"{side}_shoulder", down, ("neck", f"{side}_elbow")),
                   (f"{side}_elbow", ("neck", f"{side}_elbow"), (f"{side}_elbow", f"{side}_wrist"))]
    joints = ["neck"] + [f"{side}_{j}" for side in "rl" for j in ("hip", "knee", "ankle", "shoulder", "elbow")]
    return Mechanism(points=points, segments=segments, angles=angles,
                     actuators=[(f"tau_{j}", j, 1.0) for j in joints])


def chain_mechanism(links: int = 14) -> Mechanism:
    """The benchmark chain: rods 0.3 m 1 kg (I_G = m l²/12) from the origin in a half circle,
    link angle -(k + ½)π/N; the tip is a ground point at its start position."""
    length, mass = 0.3, 1.0
    points = {"P0": (0.0, 0.0, True)}
    segments = []
    x = z = 0.0
    for k in range(links):
        theta = -(k + 0.5) * math.pi / links
        x, z = x + length * math.cos(theta), z + length * math.sin(theta)
        points[f"P{k + 1}"] = (x, z, k == links - 1)
        segments.append((f"link{k + 1}", f"P{k}", f"P{k + 1}", length, mass, length / 2, 0.0, mass * length**2 / 12))
    return Mechanism(points=points, segments=segments)


CASES = [  # (label, cmbs.load arguments, reference description)
    ("four-bar", ("four-bar",), {}, four_bar_mechanism),
    ("human", ("human",), {}, human_mechanism),
    ("chain14-closed", ("chain",), {"links": 14, "closed": True}, lambda: chain_mechanism(14)),
]


# ------------------------------------------------------------------------------------ checks
TOLERANCE = 1e-12


def compare(model, reference: NumpyNatural, q, qd, t, u) -> tuple[dict[str, float], tuple]:
    """Assert that the numpy reference reproduces cmbs's terms; return the max differences."""
    assert sorted(reference.coordinate_names) == sorted(model.coordinate_names), \
        (reference.coordinate_names, model.coordinate_names)
    assert sorted(reference.constraint_names) == sorted(model.constraint_names), \
        (reference.constraint_names, model.constraint_names)
    assert sorted(reference.actuator_names) == sorted(model.actuator_names)
    pc = np.array([model.coordinate_names.index(c) for c in reference.coordinate_names])  # ref -> cmbs
    pr = np.array([model.constraint_names.index(c) for c in reference.constraint_names])
    pu = np.array([model.actuator_names.index(a) for a in reference.actuator_names], dtype=np.int64)
    terms = model.evaluate(q, qd, t, u, out=model.new_terms())
    M, Q, phi, A, gamma, phi_t = reference.evaluate(q[pc], qd[pc], t, u[pu])
    expected = {"M": terms.M[np.ix_(pc, pc)], "Q": terms.Q[pc], "phi": terms.phi[pr],
                "A": terms.A[np.ix_(pr, pc)], "gamma": terms.gamma[pr], "phi_t": terms.phi_t[pr]}
    got = {"M": M, "Q": Q, "phi": phi, "A": A, "gamma": gamma, "phi_t": phi_t}
    differences = {}
    for key, value in expected.items():
        scale = max(1.0, float(np.max(np.abs(value)))) if value.size else 1.0
        difference = float(np.max(np.abs(got[key] - value))) if value.size else 0.0
        assert got[key].shape == value.shape, (key, got[key].shape, value.shape)
        assert difference <= TOLERANCE * scale, \
            f"{model.name}: numpy reference differs from cmbs in {key} by {difference:.3g} (scale {scale:.3g})"
        differences[key] = difference
    # the state must exercise the terms (not a trivially zero comparison)
    assert np.max(np.abs(terms.phi)) > 1e-6 and np.max(np.abs(terms.gamma)) > 1e-3
    return differences, (pc, pu)


def benchmark_state(model, seed: int = 2026):
    """Assembled q0 perturbed by ~1 mm / 1 mrad (so Φ ≠ 0 is compared), random q̇ and u, t = 0.37."""
    rng = np.random.default_rng(seed)
    q = model.q0 + 1e-3 * rng.standard_normal(model.n)
    qd = 0.5 * rng.standard_normal(model.n)
    u = rng.standard_normal(model.n_u)
    return q, qd, 0.37, u


# ------------------------------------------------------------------------------------ breakdown
def breakdown(model, q, qd, t, u, repeat: int, target: float) -> dict:
    """Time the layers of ``evaluate`` (interleaved): Model.evaluate -> equations.evaluate ->
    compiled kernel through the numba dispatcher -> kernel body alone (called N times from
    inside numba, no dispatch) and a no-op numba function with the kernel's 7 arguments
    (the dispatch floor).  Uses cmbs internals; skipped if they changed."""
    try:
        import numba
        from cmbs.model import natural

        equations = model.equations
        kernel = natural._evaluate
        ints, reals = equations.ints, equations.reals
        terms = model.new_terms()
        buffer = terms.buffer
        if equations.time_functions.python:
            return {"skipped": "model has Python time functions"}
        kernel(q, qd, t, u, ints, reals, buffer)
    except Exception as error:  # noqa: BLE001 - internals may change under this benchmark
        return {"skipped": f"cmbs internals changed: {error!r}"}

    @numba.njit
    def noop(q, qd, t, u, ints, reals, buffer):
        return None

    @numba.njit
    def body_loop(count, q, qd, t, u, ints, reals, buffer):
        for k in range(count):
            kernel(q, qd, t, u, ints, reals, buffer)

    noop(q, qd, t, u, ints, reals, buffer)
    body_loop(1, q, qd, t, u, ints, reals, buffer)
    count = 2000
    body_key = f"kernel body only (x{count} inside numba) / {count}"
    layers = time_interleaved({
        "Model.evaluate": lambda: model.evaluate(q, qd, t, u, out=terms),
        "equations.evaluate": lambda: equations.evaluate(q, qd, t, u, terms),
        "kernel via numba dispatcher": lambda: kernel(q, qd, t, u, ints, reals, buffer),
        "numba dispatch floor (no-op, same 7 args)": lambda: noop(q, qd, t, u, ints, reals, buffer),
        body_key: lambda: body_loop(count, q, qd, t, u, ints, reals, buffer),
    }, repeat, target)
    for key in ("median", "min", "max"):
        layers[body_key][key] /= count
    layers[body_key]["samples"] = [s / count for s in layers[body_key]["samples"]]
    return layers


# ------------------------------------------------------------------------------------ import time
IMPORT_COMMAND = ("import time; t=time.perf_counter(); import cmbs; t1=time.perf_counter(); "
                  "m=cmbs.load('human'); t2=time.perf_counter(); print(t2-t, t1-t)")


def import_times(warm_runs: int, cold: bool) -> dict:
    """Wall time of import cmbs + cmbs.load('human') in fresh interpreters.

    All launches use one fresh NUMBA_CACHE_DIR: the first launch compiles every kernel (cold
    cache), the next ``warm_runs`` load them from that cache.  With ``cold`` False the
    launches use the normal cache (already warm after the in-process part of this run).
    """
    def launch(env) -> tuple[float, float]:
        output = subprocess.run([sys.executable, "-c", IMPORT_COMMAND], env=env, check=True,
                                capture_output=True, text=True).stdout.split()
        return float(output[0]), float(output[1])

    result: dict = {"command": f'{sys.executable} -c "{IMPORT_COMMAND}"',
                    "PYTHONDONTWRITEBYTECODE": os.environ.get("PYTHONDONTWRITEBYTECODE", "")}
    env = dict(os.environ)
    cache = None
    if cold:
        cache = tempfile.mkdtemp(prefix="cmbs-numba-cache-")
        env["NUMBA_CACHE_DIR"] = cache
        total, imported = launch(env)
        result["cold"] = {"total_s": total, "import_s": imported, "NUMBA_CACHE_DIR": "fresh temporary directory"}
    try:
        runs = [launch(env) for _ in range(warm_runs)]
    finally:
        if cache:
            shutil.rmtree(cache, ignore_errors=True)
    totals, imports = [r[0] for r in runs], [r[1] for r in runs]
    result["warm"] = {"total_s": {"median": statistics.median(totals), "min": min(totals), "max": max(totals),
                                  "runs": totals},
                      "import_s": {"median": statistics.median(imports), "min": min(imports), "max": max(imports),
                                   "runs": imports}}
    return result


# ------------------------------------------------------------------------------------ main
def environment() -> dict:
    import numba
    return {"date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
            "python": sys.version.split()[0], "numpy": np.__version__, "numba": numba.__version__,
            "cmbs": cmbs.__version__, "machine": platform.machine(), "cpu_count": os.cpu_count(),
            "processor": _cpu_name(), "load_average_start": os.getloadavg()}


def _cpu_name() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="3 batches of ~0.05 s, 2 warm launches, no cold launch")
    parser.add_argument("--json", metavar="FILE", help="write all figures as JSON")
    args = parser.parse_args(argv)
    repeat, target = (3, 0.05) if args.quick else (7, 0.2)

    report: dict = {"environment": environment(), "method": {
        "per_call": f"µs per call, median [min-max] of {repeat} timeit batches of ~{target} s after warm-up",
        "targets_us": TARGETS_US, "tolerance": TOLERANCE}, "models": {}}
    env = report["environment"]
    print(f"cmbs {env['cmbs']}  python {env['python']}  numpy {env['numpy']}  numba {env['numba']}  "
          f"{env['processor']} x{env['cpu_count']}  load avg {env['load_average_start'][0]:.2f}")
    print(f"per call: µs, median [min-max] of {repeat} batches of ~{target} s\n")

    for label, load_args, load_kwargs, describe in CASES:
        model = cmbs.load(*load_args, **load_kwargs)
        q, qd, t, u = benchmark_state(model)
        reference = NumpyNatural(describe())
        differences, (pc, pu) = compare(model, reference, q, qd, t, u)
        terms = model.new_terms()
        model.evaluate(q, qd, t, u, out=terms)
        rq, rqd, ru = q[pc], qd[pc], u[pu]

        evaluate = time_call(lambda: model.evaluate(q, qd, t, u, out=terms), repeat, target)
        numpy_ref = time_call(lambda: reference.evaluate(rq, rqd, t, ru), repeat, target)
        convenience = {
            "evaluate(q, qd, t, u) (new Terms)": time_call(lambda: model.evaluate(q, qd, t, u), repeat, target),
            "mass_matrix(q)": time_call(lambda: model.mass_matrix(q), repeat, target),
            "forces(q, qd, t, u)": time_call(lambda: model.forces(q, qd, t, u), repeat, target),
            "constraints(q, t)": time_call(lambda: model.constraints(q, t), repeat, target),
            "jacobian(q, t)": time_call(lambda: model.jacobian(q, t), repeat, target),
            "gamma(q, qd, t)": time_call(lambda: model.gamma(q, qd, t), repeat, target),
            "constraints_t(q, t)": time_call(lambda: model.constraints_t(q, t), repeat, target),
        }
        layers = breakdown(model, q, qd, t, u, repeat, target)
        goal = TARGETS_US.get(label)
        verdict = None if goal is None else ("PASS" if evaluate["median"] <= goal else "MISS")
        report["models"][label] = {
            "n": model.n, "m": model.m, "n_u": model.n_u, "evaluate_us": evaluate, "numpy_reference_us": numpy_ref,
            "ratio_numpy_over_cmbs": numpy_ref["median"] / evaluate["median"],
            "max_abs_difference_numpy_vs_cmbs": differences, "convenience_us": convenience,
            "breakdown_us": layers, "target_us": goal, "verdict": verdict,
            "anchors_quoted_not_measured": ANCHORS_QUOTED.get(label)}

        print(f"== {label}: n = {model.n} coordinates, m = {model.m} constraints, {model.n_u} inputs")
        print(f"  model.evaluate(q, qd, t, u, out=terms)   {fmt(evaluate):>24} µs"
              + ("" if goal is None else f"   target <= {goal:g} µs: {verdict}"))
        print(f"  plain numpy reference (same terms)       {fmt(numpy_ref):>24} µs   numpy/cmbs = "
              f"{numpy_ref['median'] / evaluate['median']:.0f}x")
        print("  reference == cmbs to 1e-12: max |diff| " + ", ".join(f"{k} {v:.1e}" for k, v in differences.items()))
        print("  convenience calls (fresh arrays):")
        for name, stats in convenience.items():
            print(f"    model.{name:<36} {fmt(stats):>22} µs")
        if "skipped" in layers:
            print(f"  breakdown: skipped ({layers['skipped']})")
        else:
            print("  where the time goes (interleaved batches):")
            for name, stats in layers.items():
                print(f"    {name:<46} {fmt(stats):>22} µs")
        quoted = ANCHORS_QUOTED.get(label)
        if quoted:
            print("  QUOTED from reference measurements, not measured in this run (forward dynamics, i.e. terms"
                  " + solve for accelerations;")
            print(f"  anchor model: {quoted['anchor model']}):")
            for name, value in quoted.items():
                if name != "anchor model":
                    print(f"    {name:<46} {value:>22} µs")
        print()

    print("== import cmbs + cmbs.load('human') in a fresh interpreter")
    imports = import_times(warm_runs=2 if args.quick else 5, cold=not args.quick)
    report["import_build_human"] = imports
    if "cold" in imports:
        cold = imports["cold"]
        print(f"  first launch, cold numba cache (compiles the kernels): {cold['total_s']:.2f} s "
              f"(import {cold['import_s']:.2f} s)")
    warm = imports["warm"]
    print(f"  warm launches, median [min-max] of {len(warm['total_s']['runs'])}: "
          f"{fmt(warm['total_s'])} s (import alone {fmt(warm['import_s'])} s)")

    report["environment"]["load_average_end"] = os.getloadavg()
    print("\n== summary (medians)")
    for label, result in report["models"].items():
        goal = result["target_us"]
        print(f"  {label:<15} evaluate {result['evaluate_us']['median']:6.2f} µs"
              + (f"  target <= {goal:g} µs: {result['verdict']}" if goal else "  (no target)")
              + f"   numpy reference {result['numpy_reference_us']['median']:6.1f} µs"
              + f" ({result['ratio_numpy_over_cmbs']:.0f}x)")
    print(f"  load average at start / end: {env['load_average_start'][0]:.2f} / {os.getloadavg()[0]:.2f} on "
          f"{env['cpu_count']} cores (other processes on the machine slow every figure; compare runs at low load)")

    write_report(args.json, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
