"""The one place that wires a model, a formulation, an integrator and the inputs into a run.

    trajectory = cmbs.simulate(model, t_end=10, formulation="projection", integrator="rk45")

The state is y = (q, q̇); the vector field is f(t, y) = (q̇, q̈(q, q̇, t, u)) with q̈ from the
formulation.  After each accepted step the formulation may adjust the state (matrix-R recovers
its dependent coordinates) and, with ``project``, the drift is removed (Aghili 2005 §VI):

    q ← q - A⁺ Φ(q)   (minimum-norm Newton, repeated until |Φ| < projection_tolerance)
    q̇ ← P q̇ - A⁺ Φ_t  (P = I - A⁺A)

Every run records at the output times q, q̇, q̈, λ, the constraint forces -Aᵀλ, the inputs u,
the total energy T + V, and the position and velocity constraint errors max|Φ|, max|Φ̇|.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from cmbs.blas import small_matrix_loop
from cmbs.dynamics import Formulation, drift, formulation as make_formulation
from cmbs.dynamics.lagrange import KKTSolver
from cmbs.dynamics.matrix_r import MatrixRSolver, rounding_note
from cmbs.dynamics.matrix_r_kernels import PythonEquations
from cmbs.errors import CmbsError, SingularSystemError, did_you_mean
from cmbs.integrate.continuity import LEFT_BRANCH, BranchWatch
from cmbs.integrate.explicit import Integration, integrate as integrate_explicit
from cmbs.integrate.grid import whole_steps
from cmbs.integrate.implicit import BACKWARD_EULER, TRAPEZOIDAL, Scheme, generalized_alpha, integrate_index3
from cmbs.integrate.tableaus import NAMES as EXPLICIT, tableau as explicit_method
from cmbs.jit import compile_seconds, interpreted
from cmbs.model.compiled import model_kernel
from cmbs.model.model import Model
from cmbs.trajectory import Trajectory

Inputs = Callable[[float, np.ndarray, np.ndarray], np.ndarray]
INDEX3 = {"backward-euler": BACKWARD_EULER, "generalized-alpha": generalized_alpha(0.9)}
#: The formulations whose solve the compiled loops run, with the options they need.
COMPILED_FORMULATIONS = ("lagrange and baumgarte (least_squares included), penalty, projection (every inertia), "
                         "udwadia-kalaba without a nonideal term, matrix-r on a holonomic model")
INTEGRATORS = (*EXPLICIT, "trapezoidal", *INDEX3)
#: integrators whose dissipation of energy is part of their design (high-frequency damping)
NUMERICALLY_DAMPED = tuple(INDEX3)
#: relative energy drift (``info["energy_drift"]``) above which a run of a conservative model gets
#: a note.  The library's conservative mechanisms stay well below it at the default settings
#: (rk45, rtol 1e-6: 2e-5 to 4e-4 over 5 s), and exceed it where the motion is visibly wrong
#: (RK4 at 10 ms on the 3-link chain: 0.17; backward Euler at 10 ms: 0.03 to 1.3).
ENERGY_NOTE = 1e-3
#: A run whose constraint error, as a displacement relative to the mechanism's size, passes this
#: gets a note (:func:`cmbs.kinematics.position_errors`).
CONSTRAINT_NOTE = 1e-3
#: ... and a run whose constraints are violated by more than the mechanism's size has diverged: it
#: is marked failed.
DIVERGED = 1.0


def input_law(model: Model, u: Inputs | np.ndarray | None) -> Inputs:
    """The inputs u(t, q, q̇) of a run: zero (None), a constant (n_u,) array, or a function."""
    if u is None:
        zeros = np.zeros(model.n_u)
        return lambda t, q, qd: zeros
    if callable(u):
        return u
    constant = np.asarray(u, dtype=float)
    if constant.shape != (model.n_u,):
        raise CmbsError(f"inputs u must have shape ({model.n_u},) for model {model.name!r}, got {constant.shape}")
    return lambda t, q, qd: constant


#: The start of a run must satisfy the constraints to this: positions as displacements relative to
#: the mechanism's size, velocities relative to ‖A_i‖ max|q̇0| + |Φ_t,i| (the terms of A q̇ + Φ_t).
START_TOLERANCE = 1e-6


def check_start(model: Model, q: np.ndarray, qd: np.ndarray) -> None:
    """Refuse, before any work, a start state off the constraints or with an angle half a turn from
    its points (:func:`cmbs.kinematics.half_turn_angles`): the run would be another mechanism's."""
    from cmbs.kinematics import half_turn_angles, position_errors

    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd))):
        raise CmbsError(f"the start state of model {model.name!r} is not finite")
    if not model.m:
        return
    positions = position_errors(model, q)
    if not positions.max() <= START_TOLERANCE:
        worst = int(np.argmax(positions))
        raise CmbsError(f"q0 violates constraint {model.constraint_names[worst]!r} of model {model.name!r} by "
                        f"{positions.max():.3g} times the mechanism's size: assemble it first (cmbs.assemble)")
    terms = model.evaluate(q, qd, 0.0)
    scale = np.abs(terms.A).max(axis=1) * np.abs(qd).max(initial=0.0) + np.abs(terms.phi_t)
    rates = np.abs(terms.A @ qd + terms.phi_t) / np.where(scale > 0, scale, 1.0)
    if not rates.max() <= START_TOLERANCE:
        worst = int(np.argmax(rates))
        raise CmbsError(f"qd0 violates constraint {model.constraint_names[worst]!r} of model {model.name!r} (A q̇ + Φ_t "
                        f"is {rates.max():.3g} of its terms): make it consistent first (cmbs.velocities)")
    wrong = half_turn_angles(model, q, 0.0, terms.A)
    if wrong:
        name, value = wrong[0]
        raise CmbsError(f"q0 puts angle {name} = {value:.6g} rad of model {model.name!r} half a turn away from the "
                        "direction it measures (the angle constraint's spurious root): assemble it first")


def project_state(model: Model, q: np.ndarray, qd: np.ndarray, t: float, *, tolerance: float = 1e-10,
                  max_iterations: int = 10, threshold: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """Coordinate and velocity projection onto Φ = 0, A q̇ = -Φ_t (Aghili 2005, eq. 45-47), as new
    arrays: the steps of :mod:`cmbs.dynamics.drift` (which the compiled loops take) on the terms
    the model evaluates here, at q̇ = 0.

    The coordinates are projected with the holonomic rows only (a nonholonomic row has no
    position-level constraint), the velocities with all rows (:func:`cmbs.dynamics.drift.project`,
    compiled for a model with a compiled kernel, else run as Python on the model's own
    evaluation).  Non-finite terms leave the state as the last finite step left it (the next
    evaluation of the run fails there)."""
    q, qd = np.array(q, dtype=float), np.array(qd, dtype=float)
    if model.m == 0:
        return q, qd
    terms = model.new_terms()
    kernel = model_kernel(model)
    rows = np.flatnonzero(model.holonomic).astype(np.int64)
    run = drift.project if kernel is not None else interpreted(drift.project)
    run(kernel if kernel is not None else PythonEquations(model, terms), q, qd, float(t), np.zeros(model.n),
        np.zeros(model.n_u), terms.buffer, model.m, rows, float(tolerance), int(max_iterations), float(threshold),
        drift.drift_work(model))
    return q, qd


class _Progress:
    """A one-line progress bar on a terminal (silent when stderr is not a TTY, e.g. in CI)."""

    def __init__(self, t_end: float, enabled: bool):
        self.t_end = t_end
        self.enabled = enabled and sys.stderr.isatty()
        self.shown = -1

    def __call__(self, t: float) -> None:
        percent = int(100 * t / self.t_end) if self.t_end > 0 else 100
        if self.enabled and percent != self.shown:
            self.shown = percent
            bar = "#" * (percent // 4)
            sys.stderr.write(f"\r  t = {t:8.4f} s [{bar:<25}] {percent:3d}%")
            sys.stderr.flush()

    def close(self) -> None:
        if self.enabled and self.shown >= 0:
            sys.stderr.write("\n")


#: output samples above which a time grid is refused (each holds the state, its derivatives, λ, ...)
MAX_SAMPLES = 10_000_000


def output_times(t_end: float, dt: float, names: tuple[str, str] = ("t_end", "dt")) -> np.ndarray:
    """The output instants 0, dt, 2 dt, ... and t_end (the last interval shorter when t_end is not
    a multiple of dt).  CmbsError for a t_end or dt that is not a finite number > 0, or a grid of
    more than MAX_SAMPLES instants, naming them by ``names`` (the CLI's are its options)."""
    for name, value in zip(names, (t_end, dt)):
        if not (isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
                and np.isfinite(value) and value > 0):
            raise CmbsError(f"{name} must be a finite number > 0, got {value!r}")
    if t_end / dt + 1 > MAX_SAMPLES:
        end, step = names
        raise CmbsError(f"{end} = {t_end:g} s with {step} = {dt:g} s gives {t_end / dt + 1:.3g} output instants, "
                        f"more than {MAX_SAMPLES:,}; choose a larger {step}")
    steps = whole_steps(t_end, dt)
    if steps is not None:
        return np.linspace(0.0, steps * dt, steps + 1)
    return np.append(np.arange(0.0, t_end, dt), t_end)


def kept_outputs(grid: np.ndarray, every: object) -> int:
    """``every`` (an integer >= 1) checked against the output ``grid`` of a run: it must divide
    the number of its intervals, so that the kept instants ``grid[::every]`` end at t_end.
    CmbsError otherwise, naming the numbers and the divisors that would do."""
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise CmbsError(f"every must be an integer >= 1, got {every!r}")
    intervals = grid.size - 1
    if intervals % every:
        divisors = [k for k in range(2, min(intervals, 10_000) + 1) if intervals % k == 0][:8]
        raise CmbsError(f"every = {every} does not divide the {intervals} steps of dt to t_end = {grid[-1]:g} s, so "
                        f"t_end would not be kept; choose one that does"
                        + (f" (e.g. {', '.join(map(str, divisors))})" if divisors else " (1)"))
    return int(every)


def simulate(model: Model | str | Path, *, t_end: float, formulation: str | Formulation | None = None,
             integrator: str = "rk45", dt: float = 0.01, every: int = 1, rtol: float = 1e-6, atol: float = 1e-9,
             q0: np.ndarray | None = None, qd0: np.ndarray | None = None, u: Inputs | np.ndarray | None = None,
             project: bool = False, projection_tolerance: float = 1e-10,
             formulation_options: Mapping[str, object] | None = None, newton_tolerance: float = 1e-10,
             compiled: bool | None = None, progress: bool = False) -> Trajectory:
    """Forward dynamics of ``model`` (a model, or a library name or model file for
    :func:`cmbs.load`) from t = 0 to ``t_end``, recorded at :func:`output_times` (t_end, dt),
    every ``every``-th of them.

    Parameters
    ----------
    formulation
        A name (lagrange, baumgarte, penalty, matrix-r, projection, udwadia-kalaba) with
        ``formulation_options``, or a formulation object; default lagrange.  The implicit
        integrators bring their own: ``trapezoidal`` works in independent coordinates (matrix R,
        thesis eq. 3.51-3.57), ``backward-euler`` and ``generalized-alpha`` on the index-3 DAE.
    integrator
        ``rk45`` (Dormand-Prince), ``rk23`` (Bogacki-Shampine), ``dop853`` (Dormand-Prince, 8th
        order, for tight tolerances): adaptive with ``rtol``/``atol``;
        ``rk4``, ``trapezoidal``, ``backward-euler``, ``generalized-alpha`` (ρ∞ = 0.9): fixed
        step ``dt`` (the last two need ``t_end`` a whole number of steps: :func:`short_last_step_message`).
    dt
        Step of fixed-step integrators and output interval of adaptive ones.
    every
        Keep only every ``every``-th output instant: 0, every·dt, 2·every·dt, ..., t_end (it must
        divide the number of dt intervals to t_end, :func:`kept_outputs`).  A fixed-step run
        still steps by dt but stores only the kept instants (2,000,000 steps of 1 ms with
        every=100 store 20,001 rows), and they are those of the same run keeping every step,
        bit for bit; an adaptive run just has the output interval every·dt.  ``energy_drift``,
        the constraint errors and the notes are those of the kept outputs.
    u
        Inputs: a constant (n_u,) array or a function u(t, q, q̇).
    project
        Coordinate and velocity projection after every step (explicit integrators).
    newton_tolerance
        Convergence of the implicit integrators' Newton iterations.
    compiled
        Run the whole loop compiled: None chooses it when the run allows it
        (:mod:`cmbs.integrate.compiled_plan`: a model, formulation and inputs with compiled
        kernels, i.e. no Python callables: no Python time functions, the formulations of
        :data:`COMPILED_FORMULATIONS`, constant inputs or a :class:`~cmbs.control.ComputedTorque`
        law alone or in a :class:`~cmbs.control.ZeroOrderHold` with period ``dt``; with rk4,
        backward-euler or generalized-alpha (:mod:`cmbs.integrate.compiled_index3`) or, constant
        inputs only, rk45/rk23/dop853 or trapezoidal (:mod:`cmbs.integrate.compiled_reduced`); drift
        projection with rk4, rk45, rk23 or dop853), True requires it (else a :class:`CmbsError`
        says why not), False keeps the Python loop.  A run on the Python loop says why in its
        note, first (``"Python loop: <reason>"``).

    Returns
    -------
    Trajectory
        With extras ``lam``, ``constraint_force``, ``u``, ``energy``, ``constraint_error`` and
        ``velocity_constraint_error``; ``info`` holds the options, status, message, counters
        and wall time ``wall_time`` [s], of which ``compile_time`` [s] compiling kernels (0 when
        they were compiled or cached before; :func:`cmbs.jit.compile_seconds`) (matrix R adds
        ``max_condition``, the largest partition condition ‖A_r‖₁ ‖A_d⁻¹‖₁
        (:func:`cmbs.dynamics.matrix_r.partition_condition`) met by its recovery of a stage or
        step state, at ``max_condition_t``; ``note`` warns when it passed
        :data:`cmbs.dynamics.matrix_r.ROUNDING_CONDITION`).  When the exact motion conserves
        T + V (:attr:`~cmbs.model.model.Model.work_sources` empty, zero inputs), ``energy_drift``
        is max |E - E0| / max T over the outputs, and ``note`` says when it passed
        :data:`ENERGY_NOTE`.  A failed run returns the part computed before the failure with
        ``info["status"] == "failed"``.
    """
    grid = output_times(t_end, dt)
    every = kept_outputs(grid, every)
    times = grid[::every]
    if isinstance(model, (str, Path)):
        from cmbs import load

        model = load(model)
    for name, value in (("rtol", rtol), ("atol", atol)):
        if not (value > 0 and np.isfinite(value)):  # a zero or negative scale makes the error norm meaningless
            raise CmbsError(f"{name} must be a finite number > 0, got {value}")
    if rtol >= 1:                                   # a relative error of 100 % accepts any step
        raise CmbsError(f"rtol must be < 1, got {rtol}")
    if integrator not in INTEGRATORS:
        raise CmbsError(f"unknown integrator {integrator!r}{did_you_mean(integrator, INTEGRATORS)}; "
                        f"choose one of {', '.join(INTEGRATORS)}")
    if integrator not in EXPLICIT and model.nonholonomic.any():
        raise CmbsError(f"integrator {integrator!r} enforces constraints at position level and cannot impose the "
                        f"nonholonomic constraints of model {model.name!r}; use rk45, rk23, dop853 or rk4")
    if integrator not in EXPLICIT and formulation is not None:
        raise CmbsError(f"integrator {integrator!r} brings its own formulation (trapezoidal: matrix R in "
                        "independent coordinates, options of matrix-r allowed; backward-euler, "
                        "generalized-alpha: index-3 Lagrange); do not give a formulation with it")
    if integrator in INDEX3 and whole_steps(t_end, dt) is None:
        raise CmbsError(short_last_step_message(integrator, t_end, dt))
    if integrator == "trapezoidal":
        chosen = make_formulation("matrix-r", **(formulation_options or {}))
    elif hasattr(formulation, "bind"):
        chosen = formulation
    else:
        chosen = make_formulation(formulation or "lagrange", **(formulation_options or {}))
    started, compiled_before = time.perf_counter(), compile_seconds()
    solver = chosen.bind(model)
    inputs = input_law(model, u)
    n = model.n
    q_start = np.array(model.q0 if q0 is None else q0, dtype=float)
    qd_start = np.array(model.qd0 if qd0 is None else qd0, dtype=float)
    for label, value in (("q0", q_start), ("qd0", qd_start)):
        if value.shape != (n,):
            raise CmbsError(f"{label} must have shape ({n},) for model {model.name!r}, got {value.shape}")
    check_start(model, q_start, qd_start)
    steps = whole_steps(t_end, dt)
    from cmbs.integrate.compiled_plan import compiled_plan

    plan = compiled_plan(model, chosen, solver, integrator, u, project, t_end, dt,
                         projection_tolerance=projection_tolerance)
    reason = _python_loop_reason(plan, compiled)
    if not reason and compiled is None and integrator in EXPLICIT and _singular_start(model, solver, q_start, qd_start):
        reason = "the formulation cannot solve the start state, where the run ends (nothing to compile)"
    if compiled and reason:
        raise CmbsError(f"the compiled loop cannot run this simulation of model {model.name!r}: {reason}")
    if reason:
        plan = None
    run_options = {"integrator": integrator, "dt": dt, "every": every, "rtol": rtol, "atol": atol, "project": project}
    if plan is not None and integrator in INDEX3:
        trajectory = _run_compiled_index3(model, plan, inputs, q_start, qd_start, grid, INDEX3[integrator],
                                          newton_tolerance, started, run_options)
    elif plan is not None and integrator == "trapezoidal":
        trajectory = _run_compiled_trapezoidal(model, solver, chosen, plan, inputs, q_start, qd_start, grid,
                                               newton_tolerance, started, run_options)
    elif plan is not None and integrator != "rk4":
        trajectory = _run_compiled_adaptive(model, solver, chosen, plan, inputs, q_start, qd_start, times, started,
                                            run_options)
    elif plan is not None:
        trajectory = _run_compiled(model, solver, chosen, plan, inputs, q_start, qd_start, steps, dt, started,
                                   run_options)
    else:
        with small_matrix_loop(model.n):         # one BLAS thread for small matrices (cmbs.blas)
            trajectory = _run_python(model, solver, chosen, inputs, q_start, qd_start, grid, every, integrator,
                                     dt, rtol, atol, project, projection_tolerance, newton_tolerance, reason,
                                     progress, started)
    solver_note = getattr(solver, "run_note", str)()   # the formulation's own, compiled loop or not
    if solver_note:
        _add_note(trajectory.info, solver_note)
    trajectory.info["compile_time"] = compile_seconds() - compiled_before
    _explain_failure(model, trajectory, grid)
    return trajectory


def _singular_start(model: Model, solver, q: np.ndarray, qd: np.ndarray) -> bool:
    """True when Lagrange or Baumgarte (:class:`~cmbs.dynamics.lagrange.KKTSolver`, the
    formulations that stop at a singular configuration) finds the system at the start state
    singular, so that a run would end at t = 0: it then takes the Python loop, which ends there
    with the same message, and no loop is compiled for it (20-40 s on a first run).  The check
    calls the solve the loop would compile; the other formulations' Python paths would compile
    code of their own (Udwadia-Kalaba: 18 s), and they do not stop there.  The inputs are taken
    zero: whether A is singular does not depend on them, and the run's input law (which may keep
    a state, a sampled controller's) is called by the run alone."""
    if not isinstance(solver, KKTSolver):
        return False
    try:
        terms = model.evaluate(q, qd, 0.0, np.zeros(model.n_u))
        solver.accelerations(terms, q, qd, 0.0)
    except SingularSystemError:
        return True
    except (CmbsError, FloatingPointError, np.linalg.LinAlgError):
        return False            # the run meets it and says so, as it would without this check
    return False


def short_last_step_message(integrator: str, t_end: float, dt: float) -> str:
    """Why an index-3 integrator refuses a t_end that is no whole number of steps dt: the last
    step would be shorter, h < dt.  The index-3 equations fix a_{n+1} through Φ(q_n + h v_n +
    h² (b₀ x_n + b₁ x_{n+1})) = 0, so that the velocity-constraint error A v_n that the steps of
    size dt leave (O(dt²)) enters a_{n+1} and λ_{n+1} divided by h b₁: their error grows as dt/h.
    Measured on the pendulum at dt = 10 ms, generalized-α: λ at the last output 0.097 (exact
    0.080) for h = dt/2, 0.18 (0.064) for h = dt/10, 1.25 (0.061) for h = dt/100."""
    return (f"integrator {integrator!r} needs t_end a whole number of steps dt, got t_end = {t_end:g} s with "
            f"dt = {dt:g} s: a shorter last step of its index-3 equations leaves accelerations and multipliers "
            "wrong by about dt/h times their error; choose t_end a multiple of dt")


def _run_python(model: Model, solver, chosen: Formulation, inputs: Inputs, q_start: np.ndarray, qd_start: np.ndarray,
                grid: np.ndarray, every: int, integrator: str, dt: float, rtol: float, atol: float,
                project: bool, projection_tolerance: float, newton_tolerance: float, reason: str,
                progress: bool, started: float) -> Trajectory:
    """The run on the Python loops (every integrator and formulation): fixed-step ones step
    through the output ``grid`` and keep ``grid[::every]``, adaptive ones output there."""
    bar = _Progress(float(grid[-1]), progress)
    try:
        if integrator in EXPLICIT:
            result = _run_explicit(model, solver, inputs, q_start, qd_start, grid, every, integrator, dt, rtol, atol,
                                   project, projection_tolerance, bar)
        elif integrator == "trapezoidal":
            result = _run_reduced(model, solver, inputs, q_start, qd_start, grid, every, TRAPEZOIDAL, dt,
                                  newton_tolerance, bar)
        else:
            result = _run_index3(model, inputs, q_start, qd_start, grid, every, INDEX3[integrator], dt,
                                 newton_tolerance, bar)
    finally:
        bar.close()
    loop_wall = time.perf_counter() - started
    trajectory = _record(model, solver, inputs, result, chosen if integrator in EXPLICIT or integrator == "trapezoidal"
                         else None, {"integrator": integrator, "dt": dt, "every": every, "rtol": rtol, "atol": atol,
                                     "project": project, "loop_wall_time": loop_wall})
    trajectory.info["wall_time"] = time.perf_counter() - started
    _add_note(trajectory.info, f"Python loop: {reason}", first=True)   # before the energy note of the recording
    _note_rounding(trajectory.info, solver)
    return trajectory


def _explain_failure(model: Model, trajectory: Trajectory, times: np.ndarray) -> None:
    """A failed run whose cause is a function of time that is not finite (e.g. ``1/(t - 0.5)`` at
    0.5, ``sqrt(1 - t)`` past 1) names it in ``info["message"]``: the functions are evaluated at the
    output instants from the last one recorded to the next, and on a fine grid between them (the
    failing stage lies there)."""
    if trajectory.info.get("status") != "failed":
        return
    last = float(trajectory.t[-1]) if len(trajectory.t) else 0.0
    after = times[times > last + 1e-12 * max(1.0, abs(last))]
    following = float(after[0]) if after.size else last
    problem = model.time_function_problem(np.linspace(last, following, 1001))   # both ends exact
    if problem:
        trajectory.info["message"] = f"{trajectory.info['message']} ({problem})"


def _note_rounding(info: dict, solver) -> None:
    """For matrix R: its number of re-partitions (``repartitions``), the largest κ₁ = ‖A_r‖₁ ‖A_d⁻¹‖₁
    met by its recovery (``max_condition``, at ``max_condition_t``) and, when rounding there may
    have spoilt the motion, a warning in the note."""
    if not isinstance(solver, MatrixRSolver):
        return
    info["repartitions"] = solver.repartitions
    info["max_condition"], info["max_condition_t"] = solver.worst_condition, solver.worst_time
    warning = rounding_note(solver.worst_condition, solver.worst_time)
    if warning:
        _add_note(info, warning)


def _add_note(info: dict, text: str, *, first: bool = False) -> None:
    """``text`` joined to ``info["note"]`` (notes separated by '; '), before the others when
    ``first``."""
    parts = (text, info.get("note")) if first else (info.get("note"), text)
    info["note"] = "; ".join(part for part in parts if part)


def _python_loop_reason(plan: tuple | str, compiled: bool | None) -> str:
    """Why a run takes the Python loop (tens of µs per step more than a compiled one), in a few
    words, or "" when a compiled loop runs it: ``plan`` is :func:`~cmbs.integrate.compiled_plan.compiled_plan`'s."""
    from cmbs import jit

    if compiled is False:
        return "compiled=False"
    if not isinstance(plan, str):
        return ""
    if not jit.COMPILED:
        return "numba is not installed, the kernels run as Python"
    return f"{plan} (compiled: {COMPILED_FORMULATIONS})" if plan.startswith("formulation") else plan


def _run_explicit(model: Model, solver, inputs: Inputs, q0: np.ndarray, qd0: np.ndarray, grid: np.ndarray,
                  every: int, integrator: str, dt: float, rtol: float, atol: float, project: bool,
                  projection_tolerance: float, bar: _Progress) -> Integration:
    n = model.n
    terms = model.new_terms()

    def field(t: float, y: np.ndarray) -> np.ndarray:
        q, qd = solver.stage_state(y[:n], y[n:], t)
        model.evaluate(q, qd, t, inputs(t, q, qd), out=terms)
        return np.concatenate([qd, _solve(solver, model, terms, q, qd, t).qdd])

    def after_step(t: float, y: np.ndarray) -> np.ndarray:
        q, qd = solver.after_step(y[:n], y[n:], t)
        if project:
            q, qd = project_state(model, q, qd, t, tolerance=projection_tolerance)
        return np.concatenate([q, qd])

    tableau = explicit_method(integrator)
    fixed = tableau.b_error is None
    result = integrate_explicit(field, np.concatenate([q0, qd0]), grid if fixed else grid[::every], tableau=tableau,
                                rtol=rtol, atol=atol, step=dt if fixed else None,
                                after_step=after_step if project or solver.adjusts_state else None, progress=bar,
                                stop_on=(CmbsError,), retry_on=(SingularSystemError,), keep_every=every if fixed else 1,
                                watch=BranchWatch(model))
    if project and tableau.b_error is not None:     # adaptive: outputs between steps are interpolated
        for row, t in zip(result.y, result.t):
            q, qd = project_state(model, row[:n], row[n:], float(t), tolerance=projection_tolerance)
            row[:n], row[n:] = q, qd
    return result


def _solve(solver, model: Model, terms, q: np.ndarray, qd: np.ndarray, t: float):
    """The formulation's accelerations; a singular linear system becomes a SingularSystemError
    (so that the run ends with a failed status and the message, not a traceback)."""
    try:
        return solver.accelerations(terms, q, qd, t)
    except np.linalg.LinAlgError as error:           # scipy.linalg raises numpy's
        raise SingularSystemError(f"model {model.name!r} at t={t:.6g}: the formulation's linear system is singular "
                                  f"({error}); try formulation 'projection' or 'udwadia-kalaba'") from None


def _force_derivatives(model: Model, inputs: Inputs, q: np.ndarray, qd: np.ndarray,
                       t: float) -> tuple[np.ndarray, np.ndarray]:
    """C_t = -∂Q/∂q̇ and K_t = -∂Q/∂q, the inputs evaluated at each state, by the forward
    differences of :func:`cmbs.integrate.implicit.forward_difference_tangents`;
    :class:`~cmbs.integrate.implicit.NonFiniteResidual` where they meet a non-finite value."""
    from cmbs.integrate.implicit import python_tangents

    terms = model.new_terms()

    def residual(qq: np.ndarray, vv: np.ndarray) -> np.ndarray:
        model.evaluate(qq, vv, t, inputs(t, qq, vv), out=terms)
        return -terms.Q.copy()

    K, C = python_tangents(residual, q, qd)
    return C, K


def _require_finite_dynamics(terms) -> None:
    """:class:`~cmbs.integrate.implicit.NonFiniteResidual` unless Q, M and A are finite: checked
    before r_dyn = M a + Aᵀλ - Q is formed, where numpy would warn of inf - inf or inf·0."""
    from cmbs.integrate.implicit import NonFiniteResidual

    if not (np.isfinite(terms.Q).all() and np.isfinite(terms.M).all() and np.isfinite(terms.A).all()):
        raise NonFiniteResidual("non-finite forces, mass matrix or constraint Jacobian")


def _consistent_start(model: Model, inputs: Inputs, q0: np.ndarray, qd0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The accelerations and multipliers the index-3 integrators start from: Lagrange's, with
    least-squares multipliers (redundant constraints allowed)."""
    from cmbs.dynamics import Lagrange

    terms = model.evaluate(q0, qd0, 0.0, inputs(0.0, q0, qd0))
    start = Lagrange(least_squares=True).bind(model).accelerations(terms, q0, qd0, 0.0)
    return start.qdd, start.lam


def _run_index3(model: Model, inputs: Inputs, q0: np.ndarray, qd0: np.ndarray, grid: np.ndarray, every: int,
                scheme: Scheme, dt: float, tolerance: float, bar: _Progress) -> Integration:
    """Backward Euler / generalized-α on M a + Aᵀλ = Q, Φ(q) = 0 (consistent start from Lagrange)
    with the model and inputs as Python calls: :func:`cmbs.integrate.implicit.integrate_index3`,
    the loop of :func:`_run_compiled_index3` interpreted."""
    from cmbs.integrate.implicit import dynamic_residual, python_tangents

    a0, lam0 = _consistent_start(model, inputs, q0, qd0)
    terms = model.new_terms()

    def dynamic(t: float, a: np.ndarray, lam: np.ndarray) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
        """r_dyn = M a + Aᵀλ - Q as a function of (q, v) at t, with the inputs applied there, by
        the compiled problem's routine (:func:`~cmbs.integrate.implicit.dynamic_residual`); the
        terms stay in ``terms``."""
        def at(qq: np.ndarray, vv: np.ndarray) -> np.ndarray:
            model.evaluate(qq, vv, t, inputs(t, qq, vv), out=terms)
            _require_finite_dynamics(terms)
            r = np.empty(model.n)
            dynamic_residual(terms.M, terms.A, terms.Q, a, lam, r)
            return r

        return at

    def residual(t, q, v, a, lam):
        at = dynamic(t, a, lam)
        r = at(q, v)
        M, A, phi = terms.M.copy(), terms.A.copy(), terms.phi.copy()
        K, C = python_tangents(at, q, v)
        return r, phi, M, A, C, K

    def value(t, q, v, a, lam):
        return dynamic(t, a, lam)(q, v), terms.phi.copy()

    return integrate_index3(residual, q0, qd0, a0, lam0, grid, scheme=scheme, step=dt,
                            tolerance=tolerance, progress=bar, stop_on=(CmbsError,), keep_every=every, value=value,
                            branch=BranchWatch(model))


def _run_compiled_index3(model: Model, plan: tuple, inputs: Inputs, q0: np.ndarray, qd0: np.ndarray,
                         grid: np.ndarray, scheme: Scheme, tolerance: float, started: float,
                         options: dict) -> Trajectory:
    """Backward Euler / generalized-α compiled (:mod:`cmbs.integrate.compiled_index3`): the loop of
    :func:`cmbs.integrate.implicit.integrate` on the model's and inputs' kernels, from the
    consistent start of :func:`_consistent_start`; outputs at ``grid[::options["every"]]`` with
    Newton's λ."""
    from cmbs.integrate.compiled_index3 import index3_problem
    from cmbs.integrate.implicit import integrate

    model_part, _, law = plan
    every, dt = options["every"], options["dt"]
    u0 = np.array(inputs(0.0, q0, qd0), dtype=float)
    a0, lam0 = _consistent_start(model, inputs, q0, qd0)
    problem = index3_problem(model_part, law, u0, model.new_terms().buffer.size, model.n, model.m,
                             (grid.size - 1) // every + 1)
    loop_started = time.perf_counter()
    result = integrate(problem, q0, qd0, a0, lam0, grid, scheme=scheme, step=dt, tolerance=tolerance,
                       keep_every=every)
    loop_wall = time.perf_counter() - loop_started
    info = _info(model, None, {**options, "compiled": True, "loop_wall_time": loop_wall}, result.status,
                 result.message, result.counters)
    k, n = result.t.size, model.n
    lam, u, position_error, velocity_error, force = (record[:k] for record in problem.records)
    trajectory = _trajectory(model, result.t, result.y[:, :n], result.y[:, n:], result.dy[:, n:], lam, u,
                             position_error, velocity_error, info, force)
    info["wall_time"] = time.perf_counter() - started
    return trajectory


def _run_reduced(model: Model, solver, inputs: Inputs, q0: np.ndarray, qd0: np.ndarray, grid: np.ndarray, every: int,
                 scheme: Scheme, dt: float, tolerance: float, bar: _Progress | None,
                 kernel: object | None = None) -> Integration:
    """Implicit trapezoidal rule in the independent coordinates z of matrix R (thesis eq. 3.51-3.57):
    Newton on f = Rᵀ(M q̈ - Q) = M̄ z̈ - Q̄ with tangent M̄ + h/2 RᵀC̄R + h²/4 RᵀK̄R.  The dependent
    coordinates follow by position, velocity and acceleration analysis with z held, and the step's
    full state is the expansion of its last iterate.  After each step the partition is chosen
    again if its dependent block became ill-conditioned (κ₂ grown by ``condition_growth``, or above
    1e12, which stops the run for a user's partition: the problem's after-step hook, as
    :meth:`MatrixRSolver.update_partition`) and the steps go on in its independent coordinates;
    a step that fails is tried once more with independent coordinates chosen at its start
    (automatic partition).  The branch watch sees each accepted full state: a run that left its
    assembly branch fails there, keeping the outputs up to the jump.  Of the instants of ``grid``
    only ``grid[::every]`` are stored.

    The loop is :func:`cmbs.integrate.implicit.newton_steps`, compiled on the problem of
    :mod:`cmbs.integrate.compiled_reduced` when the model's ``kernel`` is given (constant
    inputs), else interpreted on the Python problem of :func:`_python_reduced_problem`; this
    function drives both alike."""
    from cmbs.dynamics.base import OK
    from cmbs.integrate.continuity import watch_array
    from cmbs.integrate.implicit import (NEWTON_ITERATIONS, counter_dict, failure_message, newton_counters,
                                         newton_run, newton_state, stored_outputs)

    terms = model.evaluate(q0, qd0, 0.0, inputs(0.0, q0, qd0))
    full = (q0.copy(), qd0.copy(), solver.accelerations(terms, q0, qd0, 0.0).qdd)
    last = tuple(value.copy() for value in full)
    times = grid[::every]
    y, dy = np.zeros((times.size, 2 * model.n)), np.zeros((times.size, 2 * model.n))
    if kernel is None:
        branch = BranchWatch(model)
        watch = branch.watch
        problem_for = _python_reduced_problem(model, solver, inputs, full, last, y, dy, bar, branch)
    else:
        watch = interpreted(watch_array)(model.n, model.m)
        from cmbs.integrate.compiled_reduced import reduced_problems

        problem_for = reduced_problems(kernel, model, solver, np.array(inputs(0.0, q0, qd0), dtype=float), full,
                                       last, times.size)
    counts = newton_counters()
    first, retried, message, stored = 0, -1, "", times.size
    while True:
        problem = problem_for()
        independent = solver.partition.independent
        state = newton_state(full[0][independent], full[1][independent], full[2][independent], np.zeros(0))
        out = np.zeros((times.size, 2 * independent.size))       # the loop's own (z, ż) records: unused
        status, next_out, t_stop, change = newton_run(problem, state, grid, first, scheme, dt, tolerance,
                                                      NEWTON_ITERATIONS, every, out, out.copy(), counts,
                                                      kernel is not None, watch)
        if kernel is not None:
            solver.note_loop_conditions()
        if status == OK:
            break
        reached = next_out - 1                      # the state is that of grid[reached]
        if status != LEFT_BRANCH and solver.user is None and retried != reached:   # once more, partition chosen here
            retried = reached
            solver.repartition(model.jacobian(full[0], grid[reached]))
        else:
            message = failure_message(problem, status, t_stop, change, NEWTON_ITERATIONS, watch)
            stored = stored_outputs(times, next_out, every, status, watch)
            break
        first = reached
    if kernel is not None:
        records_q, records_qd, records_qdd = problem.records
        y, dy = np.hstack([records_q, records_qd]), np.hstack([records_qd, records_qdd])
    return Integration(times[:stored], y[:stored], dy[:stored], "failed" if message else "success", message,
                       counter_dict(counts))


def _run_compiled_trapezoidal(model: Model, solver, chosen: Formulation, plan: tuple, inputs: Inputs,
                              q0: np.ndarray, qd0: np.ndarray, grid: np.ndarray, tolerance: float, started: float,
                              options: dict) -> Trajectory:
    """The trapezoidal rule of :func:`_run_reduced` on the compiled problem of
    :mod:`cmbs.integrate.compiled_reduced`, recorded as the Python run is (:func:`_record`)."""
    loop_started = time.perf_counter()
    result = _run_reduced(model, solver, inputs, q0, qd0, grid, options["every"], TRAPEZOIDAL, options["dt"],
                          tolerance, None, kernel=plan[0])
    loop_wall = time.perf_counter() - loop_started
    trajectory = _record(model, solver, inputs, result, chosen,
                         {**options, "compiled": True, "loop_wall_time": loop_wall})
    _note_rounding(trajectory.info, solver)
    trajectory.info["wall_time"] = time.perf_counter() - started
    return trajectory


def _python_reduced_problem(model: Model, solver, inputs: Inputs, full: tuple, last: tuple, y: np.ndarray,
                            dy: np.ndarray, bar: _Progress | None, branch: BranchWatch) -> Callable[[], object]:
    """The trapezoidal rule's problem for :func:`_run_reduced` as Python functions (the model or
    the inputs have Python callables): a :class:`~cmbs.integrate.implicit.CallbackProblem` whose
    residual expands an iterate into ``last`` (as
    :class:`~cmbs.integrate.compiled_reduced.ReducedProblem`'s kernel does), whose steps accept
    ``last`` into ``full`` and update the partition there (:meth:`MatrixRSolver.update_partition`),
    whose branch watch ``branch`` sees ``full``, and which records ``full`` into ``y``, ``dy``.
    Returns the maker of the problem for a run or its retry."""
    from cmbs.integrate.implicit import CallbackProblem

    terms = model.new_terms()

    def residual(t, z, zd, zdd, lam):
        independent = solver.partition.independent
        guess, qd, qdd = full[0].copy(), full[1].copy(), full[2].copy()
        guess[independent], qd[independent], qdd[independent] = z, zd, zdd
        q, qd = solver.recover(guess, qd, t, integrated_velocities=False)
        model.evaluate(q, qd, t, inputs(t, q, qd), out=terms)
        qdd = solver.dependent_accelerations(terms, qdd)
        for target, value in zip(last, (q, qd, qdd)):
            target[:] = value
        if not (np.all(np.isfinite(terms.Q)) and np.all(np.isfinite(terms.M))):
            raise CmbsError(f"model {model.name!r} at t={t:.6g}: non-finite forces or mass matrix")
        R = solver.velocity_matrix(terms)
        C, K = _force_derivatives(model, inputs, q, qd, t)
        return (R.T @ (terms.M @ qdd - terms.Q), np.zeros(0), R.T @ terms.M @ R, np.zeros((0, R.shape[1])),
                R.T @ C @ R, R.T @ K @ R)

    def adjust(t: float, state: tuple) -> None:
        for target, value in zip(full, last):
            target[:] = value
        solver.update_partition(model.jacobian(full[0], t), t)
        independent = solver.partition.independent
        z, zd, zdd, _, x = state
        z[:], zd[:], zdd[:], x[:] = full[0][independent], full[1][independent], full[2][independent], \
            full[2][independent]

    def keep(row: int, t: float, state: tuple) -> None:
        y[row] = np.concatenate([full[0], full[1]])
        dy[row] = np.concatenate([full[1], full[2]])

    return lambda: CallbackProblem(residual, bar, (CmbsError,), [""], adjust, keep,
                                   branch=lambda t, state: branch.left_at(t, *full))


def _record(model: Model, solver, inputs: Inputs, result: Integration, chosen: Formulation | None,
            options: dict) -> Trajectory:
    """Evaluate λ, forces, energy and constraint errors at the output times."""
    n, m = model.n, model.m
    k = result.t.size
    q, qd = result.y[:, :n], result.y[:, n:]
    qdd = np.zeros((k, n))
    lam, u = np.zeros((k, m)), np.zeros((k, model.n_u))
    position_error, velocity_error = np.zeros(k), np.zeros(k)
    terms = model.new_terms()
    unsolved = 0
    for i, t in enumerate(result.t):
        u[i] = inputs(t, q[i], qd[i])
        model.evaluate(q[i], qd[i], t, u[i], out=terms)
        accelerations = None
        if chosen is not None:
            try:
                accelerations = _solve(solver, model, terms, q[i], qd[i], t)
            except CmbsError:  # e.g. an output instant closer to a singular position than any step
                unsolved += 1
        if accelerations is None:  # the integrator's own accelerations; λ by least squares
            qdd[i] = result.dy[i, n:]
            lam[i] = np.linalg.lstsq(terms.A.T, terms.Q - terms.M @ qdd[i], rcond=None)[0] if m else lam[i]
        else:
            qdd[i], lam[i] = accelerations.qdd, accelerations.lam
        position_error[i] = np.max(np.abs(terms.phi), initial=0.0)
        velocity_error[i] = np.max(np.abs(terms.A @ qd[i] + terms.phi_t), initial=0.0)
    info = _info(model, chosen, options, result.status, result.message, result.counters)
    if unsolved:
        info["outputs_from_integrator"] = unsolved
    return _trajectory(model, result.t, q, qd, qdd, lam, u, position_error, velocity_error, info)


def _info(model: Model, chosen: Formulation | None, options: dict, status: str, message: str, counters: dict) -> dict:
    parameters = {key: value for key, value in vars(chosen).items() if not callable(value)} if chosen else {}
    return {"model": model.name, "formulation": chosen.name if chosen else "index-3 lagrange",
            "formulation_options": parameters, **options, "status": status, "message": message, **counters}


def _trajectory(model: Model, t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, lam: np.ndarray,
                u: np.ndarray, position_error: np.ndarray, velocity_error: np.ndarray, info: dict,
                force: np.ndarray | None = None) -> Trajectory:
    """The result, with the constraint forces -Aᵀλ (evaluated at each output unless given) and
    the energy."""
    if force is None:
        force = np.zeros_like(q)
        terms = model.new_terms()
        for i in range(t.size if model.m else 0):
            model.evaluate(q[i], qd[i], t[i], u[i], out=terms)
            force[i] = -terms.A.T @ lam[i]
    with np.errstate(over="ignore", invalid="ignore"):   # a diverged run: its status and notes say so
        kinetic, potential = model.energy_parts(q, qd)
    energy = kinetic + potential
    _note_energy_drift(model, kinetic, energy, u, info)
    _note_constraint_violation(model, t, q, position_error, info)
    return Trajectory(t, q, qd, qdd, model.coordinate_names,
                      {"lam": lam, "constraint_force": force, "u": u, "energy": energy,
                       "constraint_error": position_error, "velocity_constraint_error": velocity_error}, info)


def energy_drift(sources: tuple[str, ...] | None, kinetic: np.ndarray, energy: np.ndarray,
                 u: np.ndarray) -> float | None:
    """max |E - E0| / max T over a run's outputs (kinetic energies T, total energies E = T + V,
    inputs u (k, n_u)) when its exact motion conserves E: nothing does work but gravity and
    springs (``sources``, the model's :attr:`Model.work_sources`, is empty) and every input is
    zero; else None (and when the mechanism is at rest throughout, or an energy is not finite)."""
    if sources != () or np.any(u != 0) or not np.all(np.isfinite(energy)):
        return None
    scale = float(kinetic.max(initial=0.0))
    return float(np.abs(energy - energy[0]).max() / scale) if scale > 0 else None


def supplied_work(model: Model, trajectory: Trajectory) -> np.ndarray | None:
    """W(t), the work done on the mechanism since t = 0 by its moving drivers and its inputs, at
    each output of ``trajectory``, when these are all that does work besides gravity and springs
    (:attr:`Model.work_sources` names drivers only); else None.  The exact motion then keeps the
    energy balance E(t) - E(0) - W(t) = 0.

    The power is P = f_cᵀ q̇ + (Q(u) - Q(0))ᵀ q̇: the constraint forces f_c = -Aᵀλ (the drivers'
    share; workless constraints add f_cᵀ q̇ ≈ 0) and the forces B u of the inputs, integrated
    over the outputs as the not-a-knot cubic spline through P (error O(dt⁴) for a smooth power
    and outputs dt apart; the trapezoidal rule's O(dt²) showed as a balance of 4e-4 of the
    work on the driven four-bar at dt = 10 ms), by the trapezoidal rule below 4 outputs or when
    the power is not finite."""
    sources = model.work_sources
    if sources is None or not all(source.startswith("driver ") for source in sources):
        return None
    t, q, qd = trajectory.t, trajectory.q, trajectory.qd
    power = np.einsum("ij,ij->i", trajectory.extras["constraint_force"], qd)
    inputs = np.asarray(trajectory.extras["u"], dtype=float).reshape(t.size, -1)
    if np.any(inputs != 0):
        with_inputs, without = model.new_terms(), model.new_terms()
        zeros = np.zeros(model.n_u)
        for i in range(t.size):
            model.evaluate(q[i], qd[i], t[i], inputs[i], out=with_inputs)
            model.evaluate(q[i], qd[i], t[i], zeros, out=without)
            power[i] += (with_inputs.Q - without.Q) @ qd[i]
    if t.size < 4 or not np.all(np.isfinite(power)):     # a diverged run's NaN stays NaN, no spline error
        return np.concatenate([[0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * np.diff(t))])
    from scipy.interpolate import CubicSpline

    return CubicSpline(t, power).antiderivative()(t)


def dissipated_only(kinetic: np.ndarray, energy: np.ndarray) -> bool:
    """Whether a change of the energy E = T + V over a run's outputs is one that numerical damping
    can explain: damping only takes energy away, so E may nowhere rise above its lowest value
    before by more than :data:`ENERGY_NOTE` of the largest kinetic energy T (a rise is an error of
    the integration, as the pendulum's gain of 10.5 J at generalized-α's 7e-12 s step was)."""
    rise = energy - np.minimum.accumulate(energy)
    return bool(rise.max(initial=0.0) <= ENERGY_NOTE * kinetic.max(initial=0.0))


def _note_energy_drift(model: Model, kinetic: np.ndarray, energy: np.ndarray, u: np.ndarray, info: dict) -> None:
    """``info["energy_drift"]`` (:func:`energy_drift`) when the run is judged, and a note when it
    exceeds :data:`ENERGY_NOTE`: the motion is then not what the model says, to more than a
    little."""
    drift = energy_drift(model.work_sources, kinetic, energy, u)
    if drift is None:
        return
    info["energy_drift"] = drift
    if drift > ENERGY_NOTE:
        damped = info.get("integrator") in NUMERICALLY_DAMPED and dissipated_only(kinetic, energy)
        cause = (f"{info['integrator']} damps numerically by design" if damped
                 else "integration error: a smaller dt, or rtol for an adaptive integrator, reduces it")
        _add_note(info, f"the energy T + V of this conservative model changed by {100 * drift:.2g} % of its "
                        f"largest kinetic energy ({cause})")


def _note_constraint_violation(model: Model, t: np.ndarray, q: np.ndarray, position_error: np.ndarray,
                               info: dict) -> None:
    """A note when the constraints are violated by more than :data:`CONSTRAINT_NOTE` of the model's
    size (at the output with the largest |Φ| or the last one): the motion is then not the
    mechanism's."""
    if not t.size or not model.holonomic.any():
        return
    from cmbs.kinematics import position_errors

    for k in dict.fromkeys((int(np.nanargmax(position_error)) if np.any(np.isfinite(position_error)) else -1, -1)):
        violation = position_errors(model, q[k], float(t[k])).max() if np.all(np.isfinite(q[k])) else np.inf
        if not violation <= CONSTRAINT_NOTE:
            _add_note(info, f"the constraints are violated by up to {violation:.2g} times the mechanism's size (t = "
                            f"{t[k]:.6g}): the motion is not the mechanism's (a smaller dt or rtol, or project=True)")
            if not violation <= DIVERGED and info.get("status") == "success":
                info["status"] = "failed"
                info["message"] = (f"the motion diverged: at t = {t[k]:.6g} the constraints are violated by "
                                   f"{violation:.2g} times the mechanism's size")
            return


def _singular_message(model: Model, solver, q: np.ndarray, qd: np.ndarray, t: float, u: np.ndarray) -> str:
    """Why a compiled loop stopped as singular at (q, q̇, t, u): the Python solver's own error,
    which names the dependent constraints."""
    try:
        solver.accelerations(model.evaluate(q, qd, t, u), q, qd, t)
    except CmbsError as error:
        return str(error)
    except (np.linalg.LinAlgError, ArithmeticError, ValueError) as error:   # the diagnosis failed, not the run
        return f"singular system at t={t:.6g} ({type(error).__name__}: {error})"
    return f"singular system at t={t:.6g}"


def _run_compiled(model: Model, solver, chosen: Formulation, plan: tuple, inputs: Inputs, q0: np.ndarray,
                  qd0: np.ndarray, steps: int, dt: float, started: float, options: dict) -> Trajectory:
    """The whole RK4 loop in :func:`cmbs.integrate.compiled_rk4.rk4`, ``steps`` steps of dt;
    outputs at every ``options["every"]``-th step.  A computed-torque law runs compiled
    (:mod:`cmbs.control.compiled_torque`), recorded as :func:`_record` records a callable input."""
    from cmbs.dynamics.base import NON_FINITE, OK, SINGULAR
    from cmbs.integrate.compiled_rk4 import ConstantInputs, rk4

    model_part, formulation, law = plan
    u0 = np.array(inputs(0.0, q0, qd0), dtype=float) if isinstance(law, ConstantInputs) else np.zeros(model.n_u)
    loop_started = time.perf_counter()
    (T, Q, QD, QDD, LAM, U, PHI, PHID, FORCE, recorded, status, t_fail, done, q_fail, qd_fail, u_fail,
     message) = rk4(model_part, formulation, law, np.array(q0), np.array(qd0), dt, steps, options["every"], u0,
                    model.new_terms().buffer.size, model.m)
    loop_wall = time.perf_counter() - loop_started
    if status == SINGULAR:                      # (LEFT_BRANCH: the loop's message, the branch watch's)
        message = _singular_message(model, solver, q_fail, qd_fail, t_fail, u_fail)
    elif status == NON_FINITE:
        message = (f"non-finite state or accelerations at t={t_fail:.6g}: the motion diverged; try a smaller "
                   "step, drift projection (project=True) or another formulation")
    elif status not in (OK, LEFT_BRANCH):
        message = solver.loop_failure(status, t_fail)     # the formulation's hooks failed
    _note_loop_conditions(solver)
    counters = {"steps": done, "evaluations": 4 * done}
    info = _info(model, chosen, {**options, "compiled": True, "loop_wall_time": loop_wall}, "success" if status ==
                 OK else "failed", message, counters)
    k = recorded
    trajectory = _trajectory(model, T[:k], Q[:k], QD[:k], QDD[:k], LAM[:k], U[:k], PHI[:k], PHID[:k], info,
                             FORCE[:k])
    _note_rounding(info, solver)
    info["wall_time"] = time.perf_counter() - started
    return trajectory


def _note_loop_conditions(solver) -> None:
    """For matrix R: the largest κ₁ a compiled loop's recoveries met, to the solver (for
    :func:`_note_rounding`)."""
    if isinstance(solver, MatrixRSolver):
        solver.note_loop_conditions()


def _run_compiled_adaptive(model: Model, solver, chosen: Formulation, plan: tuple, inputs: Inputs, q0: np.ndarray,
                           qd0: np.ndarray, times: np.ndarray, started: float, options: dict) -> Trajectory:
    """The rk45/rk23/dop853 loop of :mod:`cmbs.integrate.compiled_adaptive`; outputs at ``times``."""
    from cmbs.dynamics.base import OK, SINGULAR
    from cmbs.integrate import compiled_adaptive

    model_part, formulation, _ = plan
    u = np.array(inputs(0.0, q0, qd0), dtype=float)
    loop_started = time.perf_counter()
    run = compiled_adaptive.adaptive(model_part, formulation, np.array(q0), np.array(qd0), times, options["rtol"],
                                     options["atol"], u, model.new_terms().buffer.size, model.m,
                                     explicit_method(options["integrator"]),
                                     solver.adjusts_state or options["project"])
    loop_wall = time.perf_counter() - loop_started
    status, t_stop, message = run.status, run.t_stop, run.message    # (the branch watch's, else "")
    if status == SINGULAR:
        message = _singular_message(model, solver, run.state[:model.n], run.state[model.n:], t_stop, u)
    elif status in compiled_adaptive.REASONS:
        message = f"{compiled_adaptive.REASONS[status]} at t={t_stop:.6g}"
    elif status not in (OK, LEFT_BRANCH):
        message = solver.loop_failure(status, t_stop)     # the formulation's hooks failed
    _note_loop_conditions(solver)
    counters = {"steps": run.steps, "rejected": run.rejected, "evaluations": run.evaluations}
    info = _info(model, chosen, {**options, "compiled": True, "loop_wall_time": loop_wall},
                 "success" if status == OK else "failed", message, counters)
    if run.unsolved:
        info["outputs_from_integrator"] = run.unsolved
    k = run.recorded
    T, Q, QD, QDD, LAM, PHI, PHID, FORCE = (array[:k] for array in run.records)
    trajectory = _trajectory(model, T, Q, QD, QDD, LAM, np.tile(u, (k, 1)), PHI, PHID, info, FORCE)
    _note_rounding(info, solver)
    info["wall_time"] = time.perf_counter() - started
    return trajectory
