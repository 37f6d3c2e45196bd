"""Tracking runs and robustness studies (thesis ch. 6-7: Tables 6.1-6.2, 7.1-7.2).

A tracking run simulates a plant under a control law that follows a reference motion and
measures it: NRMSE of every tracked coordinate (RMSE over the reference's range), settling time
to 1 % of the initial error, RMS norm ``sqrt(1/T ∫ uᵀu dt)`` and peak norm ``max |u_i|`` of the
actuation, and the wall time.  A robustness study repeats the run under a list of faults — what
the controller does not know — each applied alone to the nominal plant and law:

- ``mass:SEGMENT:FACTOR[:T0]`` — the segment's mass and inertia times FACTOR from T0 (thesis:
  2.5 %, i.e. 1.025);
- ``offset:VALUE[:T0]`` / ``scale:FACTOR[:T0]`` — every actuator input becomes u + VALUE or
  FACTOR·u from T0;
- ``noise:SIGMA[:SEED]`` — the controller sees q + N(0, SIGMA²);
- ``initial:DELTA`` — the first tracked coordinate starts DELTA away from the reference (the
  rest re-assembled), the thesis's "wrong initial values".
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from cmbs.control.faults import ActuatorFault, SensorNoise, check_mass_factor, mass_fault
from cmbs.errors import CmbsError, check_in_range
from cmbs.kinematics import assemble
from cmbs.metrics import nrmse, peak_norm, rms_norm, settling_time
from cmbs.model.model import Model
from cmbs.trajectory import Trajectory

Law = Callable[[float, np.ndarray, np.ndarray], np.ndarray]
FAULT_SYNTAX = "mass:SEGMENT:FACTOR[:T0], offset:VALUE[:T0], scale:FACTOR[:T0], noise:SIGMA[:SEED] or initial:DELTA"


@dataclass(frozen=True)
class Fault:
    """One fault case, parsed from its text (see the module docstring); ``text`` is its label."""

    text: str
    kind: str
    values: tuple[float, ...]
    segment: str = ""

    @classmethod
    def parse(cls, text: str) -> "Fault":
        kind, _, rest = text.partition(":")
        parts = rest.split(":") if rest else []
        counts = {"mass": (2, 3), "offset": (1, 2), "scale": (1, 2), "noise": (1, 2), "initial": (1,)}
        if kind in counts and len(parts) in counts[kind]:
            segment = parts.pop(0) if kind == "mass" else ""
            try:
                values = tuple(float(part) for part in parts)
            except ValueError:
                values = ()
            if values and all(np.isfinite(values)):
                check_in_range(values, f"fault {text!r}")
                if kind == "mass":
                    check_mass_factor(segment, values[0])
                return cls(text, kind, values, segment)
        raise CmbsError(f"fault {text!r}: expected {FAULT_SYNTAX}")

    def apply(self, plant: Model, law: Law) -> tuple[Model, Law]:
        """The faulty plant and law (the initial-state fault changes neither)."""
        kind, values = self.kind, self.values
        t0 = values[1] if len(values) > 1 else 0.0
        if kind == "mass":
            return mass_fault(plant, self.segment, factor=values[0], t0=t0), law
        if kind == "offset":
            return plant, ActuatorFault(law, offset=values[0], t0=t0)
        if kind == "scale":
            return plant, ActuatorFault(law, scale=values[0], t0=t0)
        if kind == "noise":
            return plant, SensorNoise(law, position=values[0], seed=int(values[1]) if len(values) > 1 else 0)
        return plant, law


@dataclass(frozen=True)
class TrackingRun:
    """A closed-loop run and its measures (NRMSE per tracked coordinate, in their order, as a
    fraction of the reference's range; ``settling_time`` is NaN when the run starts without error,
    inf when it never settles; ``wall_time`` [s] includes ``compile_time`` [s], the seconds spent
    compiling kernels)."""

    label: str
    run: Trajectory
    coordinates: tuple[str, ...]
    nrmse: np.ndarray
    settling_time: float
    rms_norm: float
    peak_norm: float
    wall_time: float
    compile_time: float = 0.0

    @property
    def succeeded(self) -> bool:
        return self.run.info.get("status") == "success"


def track(plant: Model, law: Law, motion: Trajectory, coordinates: Sequence[str], *, t_end: float,
          faults: Sequence[Fault] = (), q0: np.ndarray | None = None, label: str = "nominal",
          **simulate_options: object) -> TrackingRun:
    """Simulate ``plant`` under ``law`` (after ``faults``) and measure how well it follows
    ``motion`` on ``coordinates``; the motion's sample times are the output grid.

    ``q0`` defaults to the reference's initial configuration, at rest (q̇0 = 0) unless
    ``qd0`` is among ``simulate_options``."""
    from cmbs.simulate import simulate

    if hasattr(law, "reset"):     # a law with memory (sample hold, integral action) starts afresh
        law.reset()
    columns = [motion.names.index(name) for name in coordinates]
    q0 = motion.q[0].copy() if q0 is None else np.asarray(q0, dtype=float).copy()
    for fault in faults:
        plant, law = fault.apply(plant, law)
        if fault.kind == "initial":
            q0[plant.coordinate_index(coordinates[0])] += fault.values[0]
            q0 = assemble(plant, q0, fixed=[coordinates[0]])
    dt = float(motion.t[1] - motion.t[0])
    options = {"qd0": np.zeros(plant.n), **simulate_options}
    started = time.perf_counter()
    run = simulate(plant, t_end=t_end, u=law, q0=q0, dt=dt, **options)
    wall = time.perf_counter() - started
    k = run.t.size
    if k < 2:     # the run failed at (or right after) its first instant: nothing to measure
        return TrackingRun(label, run, tuple(coordinates), np.full(len(coordinates), np.nan), np.nan, np.nan, np.nan,
                           wall)
    reference = motion.q[:k, columns]
    values = run.q[:, [run.names.index(name) for name in coordinates]]
    error = reference - values
    measured_settling = settling_time(run.t, error) if np.abs(error[0]).max() > 0 else np.nan
    return TrackingRun(label, run, tuple(coordinates), np.atleast_1d(nrmse(run.t, values, reference)),
                       measured_settling, rms_norm(run.t, run["u"]), peak_norm(run["u"]), wall,
                       run.info["compile_time"])


def robustness_study(plant: Model, law: Law, motion: Trajectory, coordinates: Sequence[str], *, t_end: float,
                     faults: Sequence[Fault | str], common: Sequence[Fault | str] = (),
                     **simulate_options: object) -> list[TrackingRun]:
    """The nominal run, then one run per fault (each alone, on top of the ``common`` faults,
    e.g. a wrong initial state shared by every case)."""
    common = [f if isinstance(f, Fault) else Fault.parse(f) for f in common]
    cases = [("nominal", [])] + [(f.text if isinstance(f, Fault) else f, [f if isinstance(f, Fault) else
                                                                          Fault.parse(f)]) for f in faults]
    return [track(plant, law, motion, coordinates, t_end=t_end, faults=[*common, *extra], label=label,
                  **simulate_options) for label, extra in cases]


def format_table(runs: Sequence[TrackingRun], title: str = "") -> str:
    """A plain-text table: case, NRMSE per coordinate (% of the reference's range), settling time,
    actuation norms, run time (without compiling) and compile time, status."""
    if not runs:
        raise CmbsError("no runs to tabulate")
    coordinates = runs[0].coordinates
    width = max(12, *(len(run.label) for run in runs))
    header = (f"{'case':<{width}} " + " ".join(f"{'NRMSE ' + name + ' %':>16}" for name in coordinates)
              + f" {'settling s':>10} {'RMS |u|':>10} {'peak |u|':>10} {'run s':>8} {'compile s':>9}  status")
    lines = [title] if title else []
    lines += [header, "-" * len(header)]
    for run in runs:
        lines.append(f"{run.label:<{width}} " + " ".join(f"{100 * v:>16.4g}" for v in run.nrmse)
                     + f" {'-' if np.isnan(run.settling_time) else f'{run.settling_time:.4g}':>10} {run.rms_norm:>10.4g} {run.peak_norm:>10.4g} "
                     f"{run.wall_time - run.compile_time:>8.3g} {run.compile_time:>9.3g}  "
                     f"{run.run.info.get('status', '?')}")
    return "\n".join(lines)
