"""Exudyn's generalized-α run as the spatial benchmarks use it (bench_slider_crank_3d.py,
bench_flyball.py): a fixed step, Newton to a relative tolerance of 1e-10, initial accelerations
computed, sensors stored in memory every output interval, no solution file."""

from __future__ import annotations

import time


def solve_generalized_alpha(exu, mbs, *, t_end: float, step: float, output: float, spectral_radius: float) -> float:
    """Runs ``mbs`` (assembled) from 0 to ``t_end`` at ``step`` with the spectral radius given;
    returns the wall time of ``SolveDynamic``."""
    settings = exu.SimulationSettings()
    settings.timeIntegration.numberOfSteps = int(round(t_end / step))
    settings.timeIntegration.endTime = t_end
    settings.timeIntegration.verboseMode = 0
    settings.timeIntegration.newton.relativeTolerance = 1e-10
    settings.timeIntegration.generalizedAlpha.spectralRadius = spectral_radius
    settings.timeIntegration.generalizedAlpha.computeInitialAccelerations = True
    settings.solution.file.write = False
    settings.solution.sensors.writePeriod = output
    start = time.perf_counter()
    mbs.SolveDynamic(simulationSettings=settings)
    return time.perf_counter() - start
