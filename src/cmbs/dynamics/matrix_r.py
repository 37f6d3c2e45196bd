"""Velocity transformation (matrix R, coordinate partitioning; thesis §3.5.4, García de Jalón &
Bayo 1994 ch. 5).

The coordinates split into n - r independent z and r dependent d (r = rank A); with the
r independent constraint rows, A_d (r × r) regular::

    q̇ = R ż,   R = [-A_d⁻¹ A_z ; I]   (rows permuted back),   q̈ = R z̈ + S,   S = [A_d⁻¹ γ ; 0]
    Rᵀ M R z̈ = Rᵀ (Q - M S)

Every integrator stage evaluates the accelerations at the consistent state: the dependent
coordinates recovered from z by a position analysis (Newton on Φ = 0 with z held, started from
the integrated values) and their velocities from A_d ḋ = -A_z ż - Φ_t; the same recovery follows
every accepted step.  The motion is that of the ODE in z, whose right-hand side is smooth along
the assembly branch even where A_d is ill-conditioned (near a singular position); evaluating it
at unrecovered stage states there would amplify their constraint error by the partition's
condition κ = ‖A_r‖ ‖A_d⁻¹‖ (:func:`partition_condition`; A_r the partition's rows of A).  Its
evaluation in floating point is not smooth there: the recovery amplifies rounding about κ³
times (see ROUNDING_CONDITION), so close to a singular position the integrated velocities are
kept (``velocity_recovery_growth``), and runs report the worst stage.

The partition is given by the user (names of the independent coordinates) or chosen
automatically: constraint rows by QR with column pivoting of the row-scaled Aᵀ, dependent
coordinates by Gaussian elimination with partial pivoting of those rows' transpose (pivot
columns of A are dependent); and chosen again when κ grows by ``condition_growth`` from its
smallest value since the partition was chosen, so that the
method follows the mechanism through configurations where its first choice of independent
coordinates stops determining the others.  κ, not cond(A_d): a block can stay perfectly
conditioned while it shrinks against the rest of A (a pendulum's x as it swings under the
pivot).  The choice and the test are compiled
(:func:`cmbs.dynamics.matrix_r_kernels.update_partition`): the compiled loops re-partition inside
their after-step hook, and this module's solver calls the same routine.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Sequence

import numpy as np

from cmbs.dynamics import matrix_r_kernels as kernels
from cmbs.dynamics.base import NON_FINITE, SINGULAR, Accelerations, check_parameters
from cmbs.errors import CmbsError, ConvergenceError, SingularSystemError
from cmbs.jit import interpreted
from cmbs.model.compiled import model_kernel
from cmbs.model.model import Model, Terms

#: κ₁ (:func:`partition_condition`) at an evaluated stage above which :func:`rounding_note`
#: warns.  At a state δ from a singular position, κ ~ 1/δ; the positions a recovery reaches are then uncertain by
#: about ε/δ along A_d's near-null direction (ε the rounding of Φ), the velocities recovered from
#: them by ε/δ² and the accelerations by ε/δ³.  Recovering every velocity, the slider-crank
#: (gravity 9.81, RK4 for 1 s through its crossing at 0.83 s, against its branch ODE) ended
#: 5e-10 to 1e-5 rad off at h = 0.5 ms to 10 µs (worst stages 1.5e5 to 6.3e6), within its
#: truncation error at 10 to 1 ms (at most 2.8e4).  Keeping the integrated velocities where
#: κ₁ has grown 100-fold (``velocity_recovery_growth``) brings all of those within 1e-10;
#: the horizontal slider-crank over 10 s (seven crossings) still loses digits at small steps
#: (relative energy error 1e-6 at 0.1 ms, 3.3e-6 at 20 µs, worst stages 1e6 to 4e6; below 1e-7
#: at 2.5 to 0.25 ms except 2.4e-7 at 0.5 ms, worst stages below 7e4).  (On the slider-crank κ₁
#: equals cond₁(A_d), with which these were measured: A_d holds A_r's largest column.)
ROUNDING_CONDITION = 1e5


@dataclass(frozen=True)
class MatrixR:
    """Matrix-R velocity transformation.

    Parameters
    ----------
    independent
        Names of the independent coordinates (default: chosen automatically).
    condition_growth
        Re-partition when the partition's condition κ₂ = ‖A_r‖₂ ‖A_d⁻¹‖₂
        (:func:`partition_condition`) grows beyond this factor times its smallest value since
        the partition was chosen (automatic partition only; a partition chosen near a singular
        position, where κ₂ is large for every partition, is so chosen again once κ₂ has fallen
        and grown again).  The error constant of the ODE in z
        grows with κ (its derivatives hold A_d⁻¹), so re-partitioning early pays: RK4 at 1 ms,
        end error against Lagrange at 25 µs, factor 3 → 1.25 (both with cond₂(A_d) as the
        measure): closed 8-link chain (2 s) 1.1e-2 → 2.1e-4, 14-link (1 s) 4.2e-2 → 7.6e-4,
        50-link (1.6 s) 3.2e-4 → 2.8e-5, undriven four-bar (5 s) 1.0e-8 → 3.0e-10, with 1-3 times
        the re-partitions; the slider-crank through its singular positions is as accurate and
        9 % slower.  With κ₂ at 1.25: 2.0e-4, 4.5e-4, 2.8e-5 and 2.8e-10, and the pendulum and
        the particle on a circle, whose 1 × 1 A_d has condition 1 at every position, no longer
        fail where the pendulum passes under its pivot (5 s: 5.8e-10).  With the growth counted
        from κ₂'s smallest value (needed through A02's singular positions, docs/formulations.md):
        2.1e-4, 7.8e-4, 2.8e-5, 2.5e-10 and 4.9e-10; the 14-link figure moves with the instants
        of re-partition (factor 1.15 to 1.4: 1.5e-4 to 1.2e-3 now, 2.4e-4 to 2.2e-3 before).
    rank_tolerance
        Relative singular-value tolerance for the rank of A.
    position_tolerance, max_iterations
        Newton recovery of the dependent coordinates.
    velocity_recovery_growth
        Where κ₁ exceeds this factor times κ₁ at the start, the dependent velocities are not
        recovered, only the positions.  So close to a singular position, the positions' rounding
        error along A_d's near-null direction (about ε κ) would turn into velocity errors about
        κ times larger, and accelerations larger again (see
        ROUNDING_CONDITION): more than the integrated velocities' small inconsistency.  Those
        states keep the integrated velocities, as an index-1 method does; the first state
        outside that zone recovers them.
    """

    name: ClassVar[str] = "matrix-r"
    independent: tuple[str, ...] | None = None
    condition_growth: float = 1.25
    rank_tolerance: float = 1e-9
    position_tolerance: float = 1e-12
    max_iterations: int = 20
    velocity_recovery_growth: float = 100.0

    def __post_init__(self) -> None:
        check_parameters(self, condition_growth="above-one", rank_tolerance="positive",
                         position_tolerance="positive", max_iterations="count",
                         velocity_recovery_growth="above-one")

    def bind(self, model: Model) -> "MatrixRSolver":
        return MatrixRSolver(model, self)

    def compiled(self, solver: "MatrixRSolver", model: Model) -> kernels.MatrixRKernel | None:
        """The compiled loops' matrix R (:meth:`MatrixRSolver.kernel`), for holonomic models:
        with a nonholonomic row the stage states are not recovered (:meth:`MatrixRSolver.stage_state`),
        which the Python loop does."""
        return None if model.nonholonomic.any() else solver.kernel()


@dataclass(frozen=True)
class Partition:
    """Independent coordinates z, dependent coordinates d, and the constraint rows used."""

    independent: np.ndarray
    dependent: np.ndarray
    rows: np.ndarray


def choose_partition(A: np.ndarray, rank_tolerance: float, independent: np.ndarray | None = None,
                     rank: int | None = None) -> Partition:
    """Choose r independent constraint rows (QR with column pivoting of Aᵀ, rows scaled to unit
    norm) and r dependent coordinates: the pivot rows of Gaussian elimination with partial
    pivoting of those rows' transpose (or the complement of the user's ``independent``
    coordinates): :func:`~cmbs.dynamics.matrix_r_kernels.choose_partition`, the choice the
    compiled loops make when they re-partition.

    r is ``rank`` when given, else the numerical rank of A (singular values of the row-scaled A
    above ``rank_tolerance`` times the largest, :func:`~cmbs.dynamics.matrix_r_kernels.numerical_rank`)."""
    A = np.ascontiguousarray(A, dtype=float)
    n = A.shape[1]
    r = int(kernels.numerical_rank(A, float(rank_tolerance))) if rank is None else int(rank)
    if independent is None:
        dependent, free = np.empty(r, dtype=np.int64), np.empty(n - r, dtype=np.int64)
    else:
        dependent = np.setdiff1d(np.arange(n), independent).astype(np.int64)
        free = np.setdiff1d(np.arange(n), dependent).astype(np.int64)
    rows = np.empty(r, dtype=np.int64)
    kernels.choose_partition(A, independent is None, rows, dependent, free)
    return Partition(free, dependent, rows)


def partition_condition(A_rows: np.ndarray, dependent: np.ndarray, norm: int) -> float:
    """κ_p = ‖A_r‖_p ‖A_d⁻¹‖_p (p = 1 or 2; ‖A_d⁻¹‖₂ = 1/σ_min(A_d)), inf for a singular A_d: how
    much the recovery of the dependent coordinates amplifies a constraint residual, relative to
    the scale of the partition's rows A_r (all columns) of A, whose dependent columns are A_d.

    cond(A_d) alone does not see A_d becoming small against A_r: a pendulum in natural
    coordinates (x, z) with x dependent has A_d = [2x], of condition 1 at every x, while its
    velocity transformation ẋ = -(z/x) ż grows without bound as the pendulum swings under its
    pivot; κ = ‖[2x, 2z]‖ / |2x| = L/|x| does.  Since ‖A_r‖ ≥ ‖A_d‖, κ ≥ cond(A_d), and both grow
    alike where A_r itself loses rank (a singular position).  1 without dependent coordinates.
    (:func:`~cmbs.dynamics.matrix_r_kernels.condition_two` and
    :func:`~cmbs.dynamics.matrix_r_kernels.condition_one`.)"""
    A_rows = np.ascontiguousarray(A_rows, dtype=float)
    rows = np.arange(A_rows.shape[0], dtype=np.int64)
    dependent = np.ascontiguousarray(dependent, dtype=np.int64)
    if norm == 2:
        return float(kernels.condition_two(A_rows, rows, dependent))
    r = rows.size
    Ad, pivots = np.empty((r, r)), np.empty(r, dtype=np.int64)
    if not kernels.factor_dependent(A_rows, rows, dependent, Ad, pivots):
        return np.inf
    return float(kernels.condition_one(A_rows, rows, Ad, pivots, np.empty(r)))


class MatrixRSolver:
    """Matrix R for one run: the partition (chosen here, in :meth:`repartition`) and the work
    arrays of the kernels of :mod:`cmbs.dynamics.matrix_r_kernels`, which do every evaluation's
    numerical work (the compiled loops call the same kernels)."""

    adjusts_state = True

    def __init__(self, model: Model, parameters: MatrixR):
        self.model = model
        self.p = parameters
        self.user = None if parameters.independent is None else model.coordinate_indices(parameters.independent)
        A0 = np.ascontiguousarray(model.jacobian(model.q0, 0.0), dtype=float)
        partition = choose_partition(A0, parameters.rank_tolerance, self.user)
        if self.user is not None and len(partition.rows) != len(partition.dependent):
            raise CmbsError(
                f"matrix-r: {len(self.user)} independent coordinates given, but the model has "
                f"{model.n - len(partition.rows)} degrees of freedom")
        self.worst_condition = 0.0     # largest κ₁ met by a recovery, and its time
        self.worst_time = 0.0
        self.work = kernels.accelerations_work(model.n, partition.independent.size, partition.rows.size)
        #: κ₁ above which the velocities are not recovered (``velocity_recovery_growth``)
        self.recovery_limit = parameters.velocity_recovery_growth * partition_condition(
            A0[partition.rows], partition.dependent, 1)
        self._no_input = np.zeros(model.n_u)
        self._loop_worst = np.zeros(2)     # [κ₁, t] of the compiled loops' recoveries (:meth:`kernel`)
        self._kernel = kernels.MatrixRKernel(
            model.m, partition.rows, partition.dependent, partition.independent, float(parameters.position_tolerance),
            int(parameters.max_iterations), float(self.recovery_limit), self.user is None,
            float(parameters.condition_growth), np.zeros(2), np.zeros(1, dtype=np.int64), self._no_input,
            self._loop_worst, *self.work)
        kernels.set_reference(A0, self._kernel)
        self.update_partition(A0, 0.0)
        kernel = model_kernel(model)
        self._terms = model.new_terms()
        self._equations = kernel if kernel is not None else kernels.PythonEquations(model, self._terms)
        self._recover = kernels.recover if kernel is not None else interpreted(kernels.recover)
        self._worst = np.zeros(2)

    @property
    def partition(self) -> Partition:
        """The current partition (a copy: :meth:`update_partition` changes the kernel's in place)."""
        kernel = self._kernel
        return Partition(kernel.independent.copy(), kernel.dependent.copy(), kernel.rows.copy())

    @property
    def _indices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The kernel's rows, dependent and independent coordinates, as the kernels take them."""
        kernel = self._kernel
        return kernel.rows, kernel.dependent, kernel.independent

    @property
    def repartitions(self) -> int:
        """How many times the partition was chosen again (here or in the compiled loops)."""
        return int(self._kernel.repartitions[0])

    def update_partition(self, A: np.ndarray, t: float) -> None:
        """Choose the partition again when κ₂ has grown by ``condition_growth`` from its
        smallest value since the partition was chosen (automatic partition), or raise where the
        partition kept or chosen has a singular A_d:
        :func:`~cmbs.dynamics.matrix_r_kernels.update_partition`, as the compiled loops' hook."""
        status = kernels.update_partition(np.ascontiguousarray(A, dtype=float), self._kernel)
        if status == kernels.SINGULAR_PARTITION:
            raise SingularSystemError(self._singular_message(t))

    def repartition(self, A: np.ndarray) -> float:
        """Choose the partition again at the configuration of ``A``, with as many dependent
        coordinates as at the start (:func:`~cmbs.dynamics.matrix_r_kernels.repartition`); returns
        the new κ₂."""
        return float(kernels.repartition(np.ascontiguousarray(A, dtype=float), self._kernel))

    def _singular_message(self, t: float) -> str:
        """The message of a partition found singular at ``t`` (:func:`singular_partition_message`)."""
        return singular_partition_message(self.model.name, self.model.coordinate_names, self._kernel, t)

    def kernel(self) -> kernels.MatrixRKernel:
        """The :class:`~cmbs.dynamics.matrix_r_kernels.MatrixRKernel` of this solver: its partition,
        conditions and counts, which the compiled loops update in place, and its work arrays; the
        largest κ₁ its recoveries meet is noted by :meth:`note_loop_conditions`."""
        return self._kernel

    def note_loop_conditions(self) -> None:
        """Keep the largest κ₁ the compiled loops' recoveries met (:meth:`note_condition`)."""
        self.note_condition(float(self._loop_worst[0]), float(self._loop_worst[1]))

    def loop_failure(self, status: int, t: float) -> str:
        """The message of a compiled loop stopped by a recovery with ``status`` at ``t``
        (:data:`~cmbs.dynamics.matrix_r_kernels.NOT_CONVERGED`, ``UNRECOVERED`` or
        ``SINGULAR_PARTITION``), else ""."""
        if status == kernels.NOT_CONVERGED:
            return (f"model {self.model.name!r} at t={t:.6g}: matrix-r position recovery did not converge in "
                    f"{self.p.max_iterations} iterations")
        if status == kernels.UNRECOVERED:
            return (f"model {self.model.name!r} at t={t:.6g}: matrix-r position recovery met non-finite constraints "
                    "or a singular block A_d")
        if status == kernels.SINGULAR_PARTITION:
            return self._singular_message(t)
        return ""

    def velocity_matrix(self, terms: Terms) -> np.ndarray:
        """R (n, n - r) with q̇ = R ż for the current partition."""
        Ad, pivots, side = self.work[:3]
        R = np.empty((self.model.n, self.partition.independent.size))
        if not kernels.factored_velocity_matrix(terms.A, *self._indices, Ad, pivots, side, R):
            raise SingularSystemError(f"model {self.model.name!r}: matrix-r's dependent block A_d is singular")
        return R

    def dependent_accelerations(self, terms: Terms, qdd: np.ndarray) -> np.ndarray:
        """``qdd`` with its dependent accelerations from A_r q̈ = γ_r, the independent ones held
        (:func:`~cmbs.dynamics.matrix_r_kernels.dependent_accelerations`)."""
        Ad, pivots, side = self.work[:3]
        qdd = np.array(qdd, dtype=float)
        rows, dependent, _ = self._indices
        if not kernels.factored_dependent_accelerations(terms.A, terms.gamma, rows, dependent, Ad, pivots, side, qdd):
            raise SingularSystemError(f"model {self.model.name!r}: matrix-r's dependent block A_d is singular")
        return qdd

    def accelerations(self, terms: Terms, q: np.ndarray, qd: np.ndarray, t: float) -> Accelerations:
        """q̈, λ and f_c = -Aᵀλ by :func:`~cmbs.dynamics.matrix_r_kernels.accelerations`; raises
        :class:`~cmbs.errors.SingularSystemError` where A_d or Rᵀ M R is singular."""
        qdd, lam = np.empty(self.model.n), np.empty(self.model.m)
        status = kernels.factored_accelerations(terms.Q, terms.A, terms.gamma, terms.M, *self._indices, self.work,
                                                qdd, lam)
        if status == SINGULAR:
            raise SingularSystemError(f"model {self.model.name!r} at t={t:.6g}: matrix-r's dependent block A_d or "
                                      "reduced mass matrix Rᵀ M R is singular")
        return Accelerations(qdd, lam, -terms.A.T @ lam)

    def note_condition(self, condition: float, t: float) -> None:
        """Keep the largest κ₁ met by a recovery (at the state it was given) and its time."""
        if condition > self.worst_condition:
            self.worst_condition, self.worst_time = condition, t

    def stage_state(self, q: np.ndarray, qd: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The consistent state of the stage: dependent coordinates and velocities recovered.

        Holonomic models only.  With nonholonomic rows the positions are not all functions of
        z (a coordinate made dependent by a velocity-level row must be integrated), and a
        recovery at every stage would move that coordinate by the Newton correction of the
        holonomic rows: on the sleigh held on a circle (tests/test_nonholonomic.py) RK4 at
        h = 0.05 then errs 1.2e-7 instead of 1.3e-8.  Those stages use the integrated state."""
        if self.model.nonholonomic.any():
            return q, qd
        return self.recover(q, qd, t)

    def after_step(self, q: np.ndarray, qd: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Recover the dependent coordinates and velocities, then re-partition if needed (at the
        recovered q, whose A the recovery left in its terms) and recover again with a new
        partition, as the compiled loops' hook
        (:func:`~cmbs.dynamics.matrix_r_kernels._after_step`)."""
        q, qd = self.recover(q, qd, t)
        before = self.repartitions
        self.update_partition(self._terms.A, t)
        return (q, qd) if self.repartitions == before else self.recover(q, qd, t)

    def recover(self, q: np.ndarray, qd: np.ndarray, t: float,
                integrated_velocities: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Dependent coordinates by Newton on Φ = 0 and their velocities from A_d ḋ = -A_z ż - Φ_t,
        with the independent coordinates and velocities held
        (:func:`~cmbs.dynamics.matrix_r_kernels.recover`).  When ``qd`` holds integrated
        velocities, they are kept as given where κ₁ at the given q exceeds
        ``recovery_limit`` (``velocity_recovery_growth``); False (an integrator of z and ż alone,
        whose ḋ is only a guess) recovers them everywhere."""
        model = self.model
        q, qd = np.array(q, dtype=float), np.array(qd, dtype=float)
        Ad, pivots, side = self.work[:3]
        worst = self._worst
        worst[0] = 0.0
        status = self._recover(self._equations, q, qd, float(t), self._no_input, self._terms.buffer, model.n, model.m,
                               *self._indices, float(self.p.position_tolerance), int(self.p.max_iterations),
                               float(self.recovery_limit if integrated_velocities else np.inf), Ad, pivots, side,
                               worst)
        if worst[0] > 0.0:
            self.note_condition(worst[0], worst[1])
        if status == kernels.NOT_CONVERGED:
            residual = np.max(np.abs(self._terms.phi[self.partition.rows]))
            raise ConvergenceError(
                f"model {model.name!r} at t={t:.6g}: matrix-r position recovery did not converge in "
                f"{self.p.max_iterations} iterations (residual {residual:.3g})")
        if status == NON_FINITE:
            raise SingularSystemError(f"model {model.name!r} at t={t:.6g}: matrix-r position recovery met non-finite "
                                      "constraints or a singular block A_d")
        return q, qd


def singular_partition_message(model_name: str, coordinate_names: Sequence[str], kernel: kernels.MatrixRKernel,
                               t: float) -> str:
    """The message of a run stopped at ``t`` where the partition of ``kernel`` has a singular A_d
    (:data:`~cmbs.dynamics.matrix_r_kernels.SINGULAR_PARTITION`, κ₂ in its MET), naming its
    independent coordinates: a user's partition can be chosen otherwise, or automatically; an
    automatic one was just chosen again at that configuration, a singular position for every
    partition, which a step lands on only by chance."""
    names = ", ".join(coordinate_names[k] for k in kernel.independent)
    start = (f"model {model_name!r} at t={t:.6g}: the dependent block A_d is singular (condition ‖A_r‖‖A_d⁻¹‖ "
             f"{kernel.conditions[kernels.MET]:.3g}) with independent coordinates {names}")
    if kernel.automatic:
        return (f"{start}, chosen automatically at this very configuration: a singular position, which a step "
                "reaches only by chance; try another dt or rtol")
    return f"{start}; choose other independent coordinates or let matrix-r choose them automatically"


def rounding_note(worst_condition: float, worst_time: float) -> str:
    """A warning when a matrix-R run evaluated a stage with κ₁ above ROUNDING_CONDITION
    (close to a singular position, where rounding costs digits), else ""."""
    if not worst_condition > ROUNDING_CONDITION:
        return ""
    return (f"matrix-r evaluated a stage at condition ‖A_r‖‖A_d⁻¹‖ = {worst_condition:.2g} (t = {worst_time:.6g}, "
            "near a singular position), where rounding costs digits: the motion after it may be off by more than "
            "the integrator's error; check it with another dt or formulation (docs/formulations.md)")
