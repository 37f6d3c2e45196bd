"""Many runs of one mechanism: parameter, mass-fault, initial-state and input studies.

:func:`sweep` runs N variants of one simulation and returns one :class:`SweepResult` (arrays
with a leading variant dimension, on one common time grid).  It chooses how to run them:

``batched``
    Variants that differ only in the initial state and constant inputs, on a run the compiled
    loops take (:mod:`cmbs.integrate.compiled_plan`: rk4, rk45, rk23 or dop853, no drift
    projection), run in parallel over the variants.  rk4: natural-coordinate models under
    lagrange, baumgarte (without ``least_squares``) or projection in blocks of eight variants
    that share each stage's bookkeeping, on numba's threads
    (:func:`cmbs.integrate.compiled_lanes.rk4_lanes`); other runs, and rk45, rk23, dop853, one
    variant at a time by the compiled loop a single run takes, on Python threads
    (:mod:`cmbs.integrate.variants`; the adaptive ones with their outputs at every dt).  All give
    the numbers of :func:`cmbs.simulate`'s compiled loops bit for bit.
``processes``
    Anything else (library-model parameters, mass faults, other formulations and integrators)
    runs :func:`cmbs.simulate` once per variant, in a local pool of worker processes
    (``workers``; 1 runs them in this process).
``dask``
    The same per-variant runs as tasks on a Dask cluster when ``scheduler`` gives its address
    (``tcp://host:port``).  A task lost with a worker that dies is run again by the scheduler
    (Dask's own retry of lost tasks), so no result is lost; the results do not depend on which
    worker ran a variant.

Every path gives the same numbers for the same variant (tested: batched vs per-variant
:func:`cmbs.simulate`, processes vs serial, Dask vs serial).
"""

from __future__ import annotations

import functools
import json
import os
import sys
import time
from dataclasses import dataclass, field
from itertools import product
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterable, Mapping, Sequence

import numpy as np

from cmbs.errors import CmbsError
from cmbs.files_io import atomic_path, checked_output
from cmbs.jit import compile_seconds
from cmbs.model.model import Model

if TYPE_CHECKING:
    from tqdm import tqdm

#: Layout version of the sweep ``.npz`` file.
FILE_VERSION = 1


@dataclass(frozen=True)
class Variant:
    """One run of a sweep: what differs from the nominal simulation.

    Parameters
    ----------
    parameters
        Keyword parameters of a library model (``cmbs.load(name, **parameters)``); the sweep's
        model must then be given by name.
    masses
        Segment name → mass factor (``cmbs.control.mass_fault`` from t = 0; natural-coordinate
        models); the sweep's energy is that of the changed mechanism.
    q0, qd0
        Initial coordinates and velocities (default: the model's).
    u
        Constant inputs (default: zeros).
    label
        A name for the variant (default: made from the other fields).
    """

    parameters: Mapping[str, object] = field(default_factory=dict)
    masses: Mapping[str, float] = field(default_factory=dict)
    q0: Sequence[float] | None = None
    qd0: Sequence[float] | None = None
    u: Sequence[float] | None = None
    label: str = ""

    def describe(self) -> dict:
        """The variant as plain JSON data."""
        return {"label": self.name(), "parameters": dict(self.parameters), "masses": dict(self.masses),
                **{key: None if value is None else [float(x) for x in value]
                   for key, value in (("q0", self.q0), ("qd0", self.qd0), ("u", self.u))}}

    def name(self) -> str:
        if self.label:
            return self.label
        parts = [f"{key}={value}" for key, value in self.parameters.items()]
        parts += [f"mass[{key}]x{value:g}" for key, value in self.masses.items()]
        parts += [key for key in ("q0", "qd0", "u") if getattr(self, key) is not None]
        return ",".join(parts) or "nominal"

    @property
    def state_only(self) -> bool:
        """True when only the initial state and the inputs differ from the nominal run."""
        return not self.parameters and not self.masses


def grid(**axes: Sequence[object]) -> list[Variant]:
    """The full factorial of library-model parameter values: ``grid(gravity=[0, 9.81],
    crank_speed=[1, 2, 3])`` gives 6 variants."""
    names = list(axes)
    return [Variant(parameters=dict(zip(names, values))) for values in product(*(axes[name] for name in names))]


@dataclass(frozen=True)
class RunSettings:
    """What every variant shares: the :func:`cmbs.simulate` options and the output interval
    (every ``every``-th multiple of ``dt``)."""

    t_end: float
    formulation: str | None = None          # None with an implicit integrator: its own
    formulation_options: Mapping[str, object] = field(default_factory=dict)
    integrator: str = "rk4"
    dt: float = 1e-3
    rtol: float = 1e-6
    atol: float = 1e-9
    project: bool = False
    every: int = 1

    def output_times(self) -> np.ndarray:
        steps = int(round(self.t_end / self.dt))
        return np.arange(0, steps + 1, self.every) * self.dt


@dataclass(frozen=True)
class SweepResult:
    """The runs of a sweep on one time grid.

    Attributes
    ----------
    t
        (k,) output times.
    q, qd
        (N, k, n) coordinates and velocities of the N variants.
    energy, constraint_error
        (N, k) total energy and max |Φ|.
    status, message
        (N,) ``"success"`` or ``"failed"`` and the reason; a failed variant's entries after
        its last output (``recorded[v]`` of them are valid) are NaN.
    recorded
        (N,) number of valid outputs of each variant.
    energy_drift
        (N,) max |E - E0| / max T over each variant's outputs where its exact motion conserves
        T + V (:func:`cmbs.simulate.energy_drift`: a conservative model, zero inputs; with mass
        factors, the changed mechanism's own energy), else NaN.
    names
        The n coordinate names.
    variants
        The variants (as :meth:`Variant.describe` gives them).
    info
        Settings, the mode (batched, processes, dask), workers, ``wall_time`` [s] and, of it,
        ``compile_time`` [s] compiling kernels in this process; a sweep in worker processes or on
        Dask adds ``worker_compile_time``, the workers' compile seconds summed over the variants.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    energy: np.ndarray
    constraint_error: np.ndarray
    status: np.ndarray
    message: np.ndarray
    recorded: np.ndarray
    names: tuple[str, ...]
    variants: tuple[dict, ...]
    info: dict
    energy_drift: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.energy_drift is None:        # a file written before the drift was recorded
            object.__setattr__(self, "energy_drift", np.full(len(self.variants), np.nan))

    def __len__(self) -> int:
        return len(self.variants)

    def coordinate(self, name: str) -> np.ndarray:
        """(N, k) history of coordinate ``name`` over all variants."""
        if name not in self.names:
            raise CmbsError(f"no coordinate {name!r}; coordinates: {', '.join(self.names)}")
        return self.q[:, :, self.names.index(name)]

    def save(self, path: str | os.PathLike) -> Path:
        """Write the sweep as ``.npz`` atomically; arrays ``t``, ``q``, ``qd``, ``energy``,
        ``constraint_error``, ``status``, ``message``, ``recorded``, ``energy_drift``, ``names``, and JSON strings
        ``variants`` and ``info`` (layout version ``FILE_VERSION`` in ``info``)."""
        path = checked_output(path, (".npz",), "sweep result")
        with atomic_path(path) as temporary, open(temporary, "wb") as stream:
            np.savez(stream, t=self.t, q=self.q, qd=self.qd, energy=self.energy,
                     constraint_error=self.constraint_error, status=self.status, message=self.message,
                     recorded=self.recorded, energy_drift=self.energy_drift, names=np.array(self.names),
                     variants=np.array(json.dumps(list(self.variants))),
                     info=np.array(json.dumps({**self.info, "file_version": FILE_VERSION}, default=str)))
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> "SweepResult":
        """Read a file written by :meth:`save`."""
        path = Path(path)
        if not path.is_file():
            raise CmbsError(f"{path}: no such file")
        try:
            with np.load(path, allow_pickle=False) as data:
                return cls(data["t"], data["q"], data["qd"], data["energy"], data["constraint_error"],
                           data["status"], data["message"], data["recorded"],
                           tuple(str(name) for name in data["names"]), tuple(json.loads(str(data["variants"]))),
                           json.loads(str(data["info"])),
                           data["energy_drift"] if "energy_drift" in data.files else None)
        except (ValueError, KeyError, OSError) as error:
            raise CmbsError(f"{path}: not a cmbs sweep file ({error})") from None


def sweep(model: str | Model, variants: Iterable[Variant], *, t_end: float, formulation: str | None = None,
          formulation_options: Mapping[str, object] | None = None, integrator: str = "rk4", dt: float = 1e-3,
          rtol: float = 1e-6, atol: float = 1e-9, project: bool = False, every: int = 1, workers: int | None = None,
          scheduler: str | None = None, batched: bool | None = None, progress: bool = False,
          worker_timeout: float = 60.0) -> SweepResult:
    """Run ``variants`` of the simulation of ``model`` (a :class:`~cmbs.Model`, or a library name
    or model file path, which parameter variants need); options as :func:`cmbs.simulate`.

    Outputs every ``every`` steps of ``dt``.  ``batched`` None chooses the batched compiled path
    when every variant is state-only and the run allows it (False forbids it, True requires
    it); otherwise ``scheduler`` (a Dask address) or a local pool of ``workers`` processes
    (default: the machine's CPUs; 1 runs in this process).  ``progress`` shows a progress bar
    (tqdm, on stderr) counting the variants done; the batched path then runs in about 50 blocks
    of variants, one compiled call each, with the same results.  On Dask, when the cluster has
    had no worker for ``worker_timeout`` seconds (the last one died, or none joined), the
    variants not done fail with that message instead of waiting forever.
    """
    variants = list(variants)
    if not variants:
        raise CmbsError("sweep: no variants given")
    from cmbs.integrate.tableaus import NAMES as EXPLICIT

    if formulation is None and integrator in EXPLICIT:
        formulation = "lagrange"                # an implicit integrator brings its own
    settings = RunSettings(t_end=float(t_end), formulation=formulation,
                           formulation_options=dict(formulation_options or {}), integrator=integrator, dt=float(dt),
                           rtol=rtol, atol=atol, project=project, every=int(every))
    if not worker_timeout > 0:
        raise CmbsError(f"sweep: worker_timeout must be > 0 seconds, got {worker_timeout}")
    if settings.t_end <= 0 or settings.dt <= 0 or settings.every < 1:
        raise CmbsError(f"sweep: t_end and dt must be positive and every >= 1 (got t_end={t_end}, dt={dt}, "
                        f"every={every})")
    if isinstance(model, Model) and any(variant.parameters for variant in variants):
        raise CmbsError("sweep: parameter variants need the model by library name (e.g. 'slider-crank'), "
                        "not a built Model")
    nominal = _build(model, Variant())
    for variant in variants:
        _check(nominal, variant)
    started, compiled_before = time.perf_counter(), compile_seconds()
    plan = _batch_plan(nominal, settings, variants) if batched is not False else None
    if batched and plan is None:
        raise CmbsError("sweep: the batched path needs state-only variants (q0, qd0, u) and a run the compiled "
                        "loops take (rk4, rk45, rk23 or dop853 with t_end a multiple of dt; lagrange, baumgarte, "
                        "penalty, projection, udwadia-kalaba or matrix-r; no project)")
    from tqdm import tqdm   # here: importing it takes about 25 ms, a launch's budget

    with tqdm(total=len(variants), desc=f"sweep {nominal.name}", unit="variant", disable=not progress,
              file=sys.stderr) as bar:
        if plan is not None:
            outputs, mode, used = _run_batched(nominal, settings, variants, plan, bar), "batched", _threads()
        elif scheduler:
            outputs = _run_dask(model, settings, variants, scheduler, bar, nominal.n, worker_timeout)
            mode, used = "dask", scheduler
        else:
            used = workers or os.cpu_count() or 1
            outputs, mode = _run_processes(model, settings, variants, used, bar), "processes"
    info = {"model": nominal.name, "mode": mode, "workers": used, "variants": len(variants),
            "settings": {**settings.__dict__, "formulation_options": dict(settings.formulation_options)},
            "wall_time": time.perf_counter() - started, "compile_time": compile_seconds() - compiled_before}
    if mode == "dask" or (mode == "processes" and used > 1 and len(variants) > 1):
        info["worker_compile_time"] = sum(output.get("compile_time", 0.0) for output in outputs)
    return _assemble(nominal, settings, variants, outputs, info)


# ---------------------------------------------------------------------------------- one variant
def _build(model: str | Model, variant: Variant) -> Model:
    """The model of ``variant``: the library model or file with its parameters, mass faults."""
    from cmbs import load
    from cmbs.control.faults import mass_fault

    built = model if isinstance(model, Model) else load(model, **dict(variant.parameters))
    for segment, factor in variant.masses.items():
        built = mass_fault(built, segment, factor=float(factor))
    return built


def _check(nominal: Model, variant: Variant) -> None:
    for key, size in (("q0", nominal.n), ("qd0", nominal.n), ("u", nominal.n_u)):
        value = getattr(variant, key)
        if value is not None and np.shape(value) != (size,):
            raise CmbsError(f"sweep variant {variant.name()!r}: {key} must have {size} values, got "
                            f"{np.shape(value)}")
        if value is not None and not np.all(np.isfinite(np.asarray(value, dtype=float))):
            raise CmbsError(f"sweep variant {variant.name()!r}: {key} has non-finite values")
    if variant.q0 is not None or variant.qd0 is not None:
        from cmbs.simulate import check_start

        try:
            check_start(nominal, np.asarray(nominal.q0 if variant.q0 is None else variant.q0, dtype=float),
                        np.asarray(nominal.qd0 if variant.qd0 is None else variant.qd0, dtype=float))
        except CmbsError as error:
            raise CmbsError(f"sweep variant {variant.name()!r}: {error}") from None


def run_variant(model: str | Model, settings: RunSettings, variant: Variant) -> dict:
    """One variant through :func:`cmbs.simulate`, sampled on the sweep's output grid (a task of
    the process and Dask paths; a module-level function so that it pickles)."""
    from cmbs.simulate import energy_drift, simulate

    built = _build(model, variant)
    n = built.n
    u = None if variant.u is None else np.asarray(variant.u, dtype=float)
    try:
        run = simulate(built, t_end=settings.t_end, formulation=settings.formulation,
                       formulation_options=settings.formulation_options, integrator=settings.integrator,
                       dt=settings.dt, rtol=settings.rtol, atol=settings.atol, project=settings.project,
                       q0=None if variant.q0 is None else np.asarray(variant.q0, dtype=float),
                       qd0=None if variant.qd0 is None else np.asarray(variant.qd0, dtype=float), u=u)
        status, message, compile_time = run.info["status"], run.info.get("message", ""), run.info["compile_time"]
    except CmbsError as error:
        return _failed_output(n, str(error))
    picked = _output_rows(run.t, settings)
    q, qd = run.q[picked], run.qd[picked]
    kinetic, energy, sources = built.energy_parts(q, qd)[0], run["energy"][picked], built.work_sources
    if variant.masses:          # the heavier or lighter mechanism's own energy, conserved as the nominal one's
        from cmbs.control.faults import mass_fault_energy_parts, nominal_work_sources

        added_kinetic, added_potential = mass_fault_energy_parts(built, q, qd)
        kinetic, energy = kinetic + added_kinetic, energy + added_kinetic + added_potential
        sources = nominal_work_sources(built)
    return {"q": q, "qd": qd, "energy": energy, "phi": run["constraint_error"][picked], "status": status,
            "message": message, "drift": energy_drift(sources, kinetic, energy, run["u"][picked]),
            "compile_time": compile_time}


def _output_rows(t: np.ndarray, settings: RunSettings) -> np.ndarray:
    """The rows of the increasing times ``t`` (a run's outputs) at the sweep's output times, as
    many as ``t`` holds from the first on (to 1e-9 relative)."""
    times = settings.output_times()
    index = np.searchsorted(t, times - 1e-9 * settings.dt)
    valid = index < t.size
    valid[valid] = np.abs(t[index[valid]] - times[valid]) <= 1e-9 * max(1.0, settings.t_end)
    count = int(np.argmin(valid)) if not valid.all() else times.size
    return index[:count]


def _failed_output(n: int, message: str) -> dict:
    """The output of a variant that computed nothing."""
    empty = np.zeros((0, n))
    return {"q": empty, "qd": empty, "energy": np.zeros(0), "phi": np.zeros(0), "status": "failed",
            "message": message}


def _run_processes(model: str | Model, settings: RunSettings, variants: list[Variant], workers: int,
                   bar: tqdm) -> list[dict]:
    if workers <= 1 or len(variants) == 1:
        return _counted((run_variant(model, settings, variant) for variant in variants), bar)
    from concurrent.futures import ProcessPoolExecutor   # here: multiprocessing takes ~5 ms to import

    with ProcessPoolExecutor(max_workers=workers) as pool:
        return _counted(pool.map(run_variant, [model] * len(variants), [settings] * len(variants), variants,
                                 chunksize=max(1, len(variants) // (4 * workers))), bar)


def _counted(outputs: Iterable[dict], bar: tqdm) -> list[dict]:
    """The variants' ``outputs`` as a list, in their order, counting each on ``bar`` as it arrives."""
    collected = []
    for output in outputs:
        collected.append(output)
        bar.update(1)
    return collected


def _run_dask(model: str | Model, settings: RunSettings, variants: list[Variant], scheduler: str,
              bar: tqdm, n: int, worker_timeout: float) -> list[dict]:
    try:
        from distributed import Client
    except ImportError:
        raise CmbsError("sweep: --scheduler needs dask's distributed package (pip install 'cmbs[dask]')") from None
    try:
        client = Client(scheduler, timeout=10)
    except (OSError, TimeoutError) as error:
        raise CmbsError(f"sweep: cannot reach the Dask scheduler at {scheduler!r} ({error})") from None
    with client:
        futures = client.map(run_variant, [model] * len(variants), [settings] * len(variants), variants,
                             pure=False, retries=2)
        lost = _await_with_workers(client, futures, bar, worker_timeout)
        if lost:
            client.cancel(list(lost))
        message = f"no Dask worker for {worker_timeout:g} s (the last worker died or none joined): not run"
        return [_failed_output(n, message) if future in lost else _task_output(future, n) for future in futures]


def _task_output(future, n: int) -> dict:
    """The output of a finished Dask task; a variant whose task killed every worker that ran it
    (Dask's KilledWorker, after its allowed failures) is a failed variant, not a traceback."""
    from distributed import KilledWorker

    try:
        return future.result()
    except KilledWorker as error:
        return _failed_output(n, f"its task was lost with every Dask worker that ran it ({error})")


def _await_with_workers(client, futures: list, bar: tqdm, worker_timeout: float) -> set:
    """Wait for ``futures``, counting each on ``bar`` as it completes; stop when the cluster has
    had no worker for ``worker_timeout`` seconds.  The futures not done then (empty when all are)."""
    from distributed import wait

    pending, idle_since = set(futures), None
    poll = min(1.0, worker_timeout / 4)
    while pending:
        try:
            done, pending = wait(pending, timeout=poll, return_when="FIRST_COMPLETED")
        except TimeoutError:          # nothing finished within poll seconds: is any worker left?
            if client.scheduler_info()["workers"]:
                idle_since = None
            elif idle_since is None:
                idle_since = time.monotonic()
            elif time.monotonic() - idle_since >= worker_timeout:
                return pending
            continue
        bar.update(len(done))
        idle_since = None
    return set()


# ---------------------------------------------------------------------------------- batched path
def _batch_plan(model: Model, settings: RunSettings, variants: list[Variant]) -> tuple | None:
    """(model, formulation and inputs kernels, steps, whether the formulation adjusts the state)
    of the batched path, or None: state-only variants and a run a compiled loop takes with
    constant inputs (:func:`cmbs.integrate.compiled_plan.compiled_run`: rk4, or rk45, rk23,
    dop853), t_end a multiple of dt (so that the adaptive loop's outputs, every dt as
    :func:`run_variant` asks :func:`cmbs.simulate` for them, hold the sweep's)."""
    from cmbs.dynamics import formulation as make_formulation
    from cmbs.integrate.compiled_plan import ADAPTIVE, compiled_run
    from cmbs.integrate.grid import whole_steps

    steps = whole_steps(settings.t_end, settings.dt)
    if not all(variant.state_only for variant in variants) or settings.integrator not in ("rk4", *ADAPTIVE) or \
            steps is None:
        return None
    chosen = make_formulation(settings.formulation, **settings.formulation_options)
    solver = chosen.bind(model)
    plan = compiled_run(model, chosen, solver, settings.integrator, None, settings.project, settings.t_end,
                        settings.dt, batched=True)
    return None if plan is None else (*plan, steps, solver.adjusts_state)


def _threads() -> int:
    from cmbs.jit import threads

    return threads()


#: Blocks of the batched path when it shows progress (one compiled call each).
PROGRESS_BLOCKS = 50


def _run_batched(model: Model, settings: RunSettings, variants: list[Variant], plan: tuple,
                 bar: tqdm) -> list[dict]:
    from cmbs.dynamics.base import OK
    from cmbs.simulate import energy_drift

    count = len(variants)
    Q0 = np.array([model.q0 if v.q0 is None else v.q0 for v in variants], dtype=float).reshape(count, model.n)
    QD0 = np.array([model.qd0 if v.qd0 is None else v.qd0 for v in variants], dtype=float).reshape(count, model.n)
    U0 = np.array([np.zeros(model.n_u) if v.u is None else v.u for v in variants], dtype=float).reshape(count,
                                                                                                       model.n_u)
    records = settings.output_times().size
    Qs, QDs = np.full((count, records, model.n), np.nan), np.full((count, records, model.n), np.nan)
    PHIs, stops = np.full((count, records), np.nan), np.zeros(count)
    statuses, recorded = np.zeros(count, dtype=np.int64), np.zeros(count, dtype=np.int64)
    block = count if bar.disable else max(-(-count // PROGRESS_BLOCKS), 4 * _threads())
    run = _block_runner(model, settings, plan)
    for a in range(0, count, block):        # each variant is independent: blocks change nothing
        b = min(a + block, count)
        run(Q0[a:b], QD0[a:b], U0[a:b], Qs[a:b], QDs[a:b], PHIs[a:b], statuses[a:b], stops[a:b], recorded[a:b])
        bar.update(b - a)
    sources = model.work_sources
    outputs = []
    for v in range(count):
        k = int(recorded[v])
        failed = statuses[v] != OK or k < records
        message = f"{_failure_reason(int(statuses[v]))} at t={stops[v]:.6g}"
        kinetic, potential = model.energy_parts(Qs[v, :k], QDs[v, :k])
        energy = kinetic + potential
        outputs.append({"q": Qs[v, :k], "qd": QDs[v, :k], "energy": energy,
                        "phi": PHIs[v, :k], "status": "failed" if failed else "success",
                        "message": message if failed else "",
                        "drift": energy_drift(sources, kinetic, energy, np.tile(U0[v], (k, 1)))})
    return outputs


def _block_runner(model: Model, settings: RunSettings, plan: tuple) -> Callable[..., None]:
    """``run(Q0, QD0, U0, Qs, QDs, PHIs, statuses, stops, recorded)``: the batched path's
    compiled call for a block of variants (rows of the initial states and inputs), writing their
    kept outputs, statuses, the times these refer to and the outputs each reached."""
    model_part, formulation, inputs, steps, adjusts_state = plan
    buffer_size, m = model.new_terms().buffer.size, model.m
    if settings.integrator == "rk4":
        from cmbs.integrate.compiled_lanes import lane_setup, rk4_lanes
        from cmbs.integrate.variants import rk4_variants

        lanes = lane_setup(model_part, formulation, m, model.n)
        loop = rk4_variants if lanes is None else functools.partial(rk4_lanes, lanes=lanes)

        def run(Q0, QD0, U0, Qs, QDs, PHIs, statuses, stops, recorded):
            loop(model_part, formulation, inputs, Q0, QD0, U0, settings.dt, steps, settings.every, buffer_size, m, Qs,
                 QDs, PHIs, statuses, recorded)
            stops[:] = recorded * settings.every * settings.dt    # a failed run: the first output it missed
        return run
    from cmbs.integrate.tableaus import tableau
    from cmbs.integrate.variants import adaptive_variants
    from cmbs.simulate import output_times

    t_out = output_times(settings.t_end, settings.dt)       # every dt, as run_variant's simulate records
    kept = _output_rows(t_out, settings).astype(np.int64)
    method = tableau(settings.integrator)

    def run(Q0, QD0, U0, Qs, QDs, PHIs, statuses, stops, recorded):
        adaptive_variants(model_part, formulation, Q0, QD0, U0, t_out, kept, float(settings.rtol), float(settings.atol),
                          method, adjusts_state, buffer_size, m, Qs, QDs, PHIs, statuses, stops, recorded)
    return run


def _failure_reason(status: int) -> str:
    """What a batched run's failure ``status`` means."""
    from cmbs.dynamics.base import NON_FINITE, SINGULAR
    from cmbs.integrate.compiled_adaptive import REASONS
    from cmbs.integrate.continuity import LEFT_BRANCH

    return {**REASONS, SINGULAR: "singular system (rank of A)", NON_FINITE: "the motion diverged",
            LEFT_BRANCH: "the motion left its assembly branch (a velocity jump near a singular configuration)"
            }.get(status, "failed")


# ---------------------------------------------------------------------------------- assembly
def _assemble(model: Model, settings: RunSettings, variants: list[Variant], outputs: list[dict],
              info: dict) -> SweepResult:
    times = settings.output_times()
    count, k, n = len(variants), times.size, model.n
    q, qd = np.full((count, k, n), np.nan), np.full((count, k, n), np.nan)
    energy, phi = np.full((count, k), np.nan), np.full((count, k), np.nan)
    recorded = np.zeros(count, dtype=np.int64)
    for v, output in enumerate(outputs):
        size = output["q"].shape[0]
        q[v, :size], qd[v, :size] = output["q"], output["qd"]
        energy[v, :size], phi[v, :size] = output["energy"], output["phi"]
        recorded[v] = size
    drift = np.array([np.nan if output.get("drift") is None else output["drift"] for output in outputs])
    return SweepResult(times, q, qd, energy, phi, np.array([output["status"] for output in outputs]),
                       np.array([output["message"] for output in outputs]), recorded, model.coordinate_names,
                       tuple(variant.describe() for variant in variants), info, drift)
