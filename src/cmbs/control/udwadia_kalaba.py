"""Udwadia-Kalaba tracking control: the task written as constraints, the force of those
constraints applied by the actuators (Nicoara 2016 §5, eq. 23-32, after Udwadia 2003;
THEORY §3 item 6 and §5 "Udwadia-Kalaba control").

Task.  Outputs y = Ψ(q) (k,) — a point of a segment or link, selected coordinates, any function —
must follow y_d(t).  Differentiating Ψ twice and stabilising like Baumgarte gives the task
constraint at acceleration level

    Ψ_q q̈ = ÿ_d + K_d (ẏ_d - ẏ) + K_p (y_d - y) - Ψ̇_q q̇  =: b_task,      ẏ = Ψ_q q̇,

so that wherever it holds the task error e = y_d - y obeys ë + K_d ė + K_p e = 0.

Stacking with the plant's constraints.  The plant enforces its own constraints A q̈ = γ with its
own reaction -Aᵀλ: whatever force f the actuators add, it moves with Gauss's acceleration for
(M, Q + f, A, γ).  The task rows are therefore stacked with the plant's rows,

    A_s = [A; Ψ_q],   b_s = [γ; b_task],   a = M⁻¹Q,
    q̈* = a + M^{-1/2} (A_s M^{-1/2})⁺ (b_s - A_s a),                 (Nicoara eq. 11)
    Q_c = M q̈* - Q = M^{1/2} (A_s M^{-1/2})⁺ (b_s - A_s a),           (Nicoara eq. 19)

the force of least constraint (Gauss) that makes the plant satisfy both.  The task rows alone
would give a force blind to A q̈ = γ, to which the plant would add a reaction that changes the
task acceleration (in natural coordinates the "free" system M q̈ = Q is a cloud of unconnected
points and massless angles, with a singular M).  Q_c includes the plant's reaction; since any f
in Q_c + range(Aᵀ) gives the plant exactly q̈* (its reaction absorbs the difference), the
actuators need to realise Q_c only modulo range(Aᵀ).

Actuation.  With G = ∂Q/∂u (n, n_u) (the Bᵀ of ``M q̈ + Aᵀλ = Q + Bᵀu``), an extra force f changes
the plant's acceleration by δq̈ = M^{-1/2} N M^{-1/2} f, with N = I - B⁺B, B = A M^{-1/2} (f in
range(Aᵀ) does nothing).  The inputs minimise Gauss's measure of the acceleration error,

    ‖N M^{-1/2} (G u - Q_c)‖² = δq̈ᵀ M δq̈,    u = (N M^{-1/2} G)⁺ N M^{-1/2} Q_c,

the minimum-norm u when the actuators are redundant; with no plant constraints (N = I) this is
G u = Q_c in the M⁻¹-weighted least-squares sense.  The residual is zero when the actuators can
realise Q_c; whether they can for *every* task demand is the inclusion
range(N (A_s M^{-1/2})⁺) ⊆ range(N M^{-1/2} G), measured by the unrealisable fraction

    ρ = ‖(I - Π_G) N B̃⁺‖₂ / ‖N B̃⁺‖₂,   B̃ = A_s M^{-1/2} with unit rows, Π_G the projector onto
                                        range(N M^{-1/2} G),

0 for a realisable task, up to 1.  ρ > ``tolerance`` raises :class:`~cmbs.errors.CmbsError` (the
task is not realisable with these actuators, e.g. more task outputs than actuators, or a
passive joint that the force of least constraint would need).

Numerics.  Any factor M = L Lᵀ can stand for M^{1/2} (Gauss's measure is the same), so the
Cholesky factor is used, and q̈* is computed by the Udwadia-Kalaba formulation's own solve,
:func:`cmbs.dynamics.udwadia_kalaba.udwadia_kalaba_solve`, on that factor with the stacked rows
A_s, b_s as its constraints (the controller adds the actuation and ρ above).  When the model has
constraints, M is replaced by M̂ = M + s ÃᵀÃ and Q by Q̂ = Q + s Ãᵀγ̃ (Ã, γ̃ the plant's rows
scaled to unit norm, s = trace(M(q0))/n; Udwadia & Phohomsiri 2006): on A q̈ = γ this adds the
constant s|γ̃|² to Gauss's function and changes neither q̈* nor Q_c nor δq̈, and it makes M̂
definite for natural coordinates with massless angle coordinates.  The pseudo-inverses of B̃
(A_s L⁻ᵀ with unit rows) and of its plant rows discard singular values ≤ ``threshold``, that
of N L⁻¹ G those below ``threshold``·σ_max, so a task row that becomes dependent (an arm at
full stretch) is dropped instead of blowing up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Protocol, Sequence

import numpy as np

from cmbs.control.base import actuator_map, gain_vector
from cmbs.dynamics.projection import pseudo_inverse
from cmbs.dynamics.udwadia_kalaba import udwadia_kalaba_solve
from cmbs.errors import CmbsError
from cmbs.lazy import on_first_use
from cmbs.model import joints
from cmbs.model.model import Model
from cmbs.model.natural import NaturalEquations, point_map

linalg = on_first_use("scipy.linalg")

Desired = Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]]
#: The non-ideal vector c of :func:`udwadia_kalaba_solve`: none (the task force is ideal).
NO_NONIDEAL = np.zeros(0)


# ------------------------------------------------------------------ outputs y = Ψ(q)
class Output(Protocol):
    """A task output map: ``names`` (k,), Ψ(q) (k,), Ψ_q (k, n) and Ψ̇_q q̇ (k,)."""

    names: tuple[str, ...]

    def value(self, q: np.ndarray) -> np.ndarray:
        """Ψ(q)."""

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """Ψ_q(q)."""

    def bias(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Ψ̇_q q̇, the acceleration of y when q̈ = 0."""


class CoordinateOutput:
    """Selected model coordinates: Ψ = q[names] (Ψ_q a selection matrix, Ψ̇_q q̇ = 0)."""

    def __init__(self, model: Model, names: Sequence[str]):
        self.names = tuple(names)
        if not self.names:
            raise CmbsError("coordinate output: give at least one coordinate name")
        self.columns = model.coordinate_indices(self.names)
        self.selection = np.eye(model.n)[self.columns]

    def value(self, q: np.ndarray) -> np.ndarray:
        return q[self.columns]

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        return self.selection

    def bias(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return np.zeros(self.columns.size)


class LinearOutput:
    """Ψ = C q + d, constant C (k, n): points of natural-coordinate models (Ψ̇_q q̇ = 0)."""

    def __init__(self, names: Sequence[str], matrix: np.ndarray, offset: np.ndarray):
        self.names = tuple(names)
        self.matrix = np.asarray(matrix, dtype=float)
        self.offset = np.asarray(offset, dtype=float)

    def value(self, q: np.ndarray) -> np.ndarray:
        return self.matrix @ q + self.offset

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        return self.matrix

    def bias(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return np.zeros(self.offset.size)


class JointPointOutput:
    """A point fixed on link ``link`` (index) at local ``(ξ, η)`` of a joint-coordinate model:
    position, Jacobian and bias acceleration J̇ q̇ from
    :meth:`~cmbs.model.joints.JointEquations.point_kinematics`, the kinematics of the model's
    own loop closures."""

    def __init__(self, names: Sequence[str], equations: joints.JointEquations, link: int,
                 local: tuple[float, float]):
        self.names = tuple(names)
        self.equations = equations
        self.link = link
        self.local = (float(local[0]), float(local[1]))
        self.at_rest = np.zeros(equations.n)

    def value(self, q: np.ndarray) -> np.ndarray:
        return self.equations.point_kinematics(self.link, self.local, q, self.at_rest)[0]

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        return self.equations.point_kinematics(self.link, self.local, q, self.at_rest)[1]

    def bias(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return self.equations.point_kinematics(self.link, self.local, q, qd)[2]


class FunctionOutput:
    """Ψ given as a function of q, with optional analytic ``jacobian(q)`` and ``bias(q, q̇)``.

    Missing derivatives are taken by central differences: Ψ_q column by column with step
    ``step``·max(1, |q_i|) (error O(h²)); Ψ̇_q q̇ along v = q̇ as
    ``(Ψ_q(q + εv) - Ψ_q(q - εv)) v / 2ε`` when the Jacobian is analytic, else as the second
    directional difference ``(Ψ(q + εv) - 2Ψ(q) + Ψ(q - εv)) / ε²`` (both equal d²Ψ(q + sv)/ds²
    at s = 0, which is J̇ q̇ for Ψ independent of t), with ‖εv‖ = 1e-5 resp. 1e-4 (relative
    errors about 1e-10 resp. 1e-8 for smooth Ψ of unit scale).
    """

    def __init__(self, function: Callable[[np.ndarray], np.ndarray], names: Sequence[str], *,
                 jacobian: Callable[[np.ndarray], np.ndarray] | None = None,
                 bias: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None, step: float = 1e-6):
        self.names = tuple(names)
        if not step > 0:
            raise CmbsError(f"function output: step must be > 0, got {step}")
        self.function = function
        self.analytic_jacobian = jacobian
        self.analytic_bias = bias
        self.step = step

    def value(self, q: np.ndarray) -> np.ndarray:
        y = np.asarray(self.function(q), dtype=float)
        if y.shape != (len(self.names),):
            raise CmbsError(f"function output: Ψ(q) has shape {y.shape}, expected ({len(self.names)},) "
                            f"for outputs {', '.join(self.names)}")
        return y

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        if self.analytic_jacobian is not None:
            return np.asarray(self.analytic_jacobian(q), dtype=float)
        columns = []
        for i in range(q.size):
            h = self.step * max(1.0, abs(q[i]))
            shift = np.zeros(q.size)
            shift[i] = h
            columns.append((self.value(q + shift) - self.value(q - shift)) / (2 * h))
        return np.array(columns).T

    def bias(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        if self.analytic_bias is not None:
            return np.asarray(self.analytic_bias(q, qd), dtype=float)
        speed = float(np.linalg.norm(qd))
        if speed == 0.0:
            return np.zeros(len(self.names))
        if self.analytic_jacobian is not None:
            eps = 1e-5 / speed
            return (self.jacobian(q + eps * qd) - self.jacobian(q - eps * qd)) @ qd / (2 * eps)
        eps = 1e-4 / speed
        return (self.value(q + eps * qd) - 2 * self.value(q) + self.value(q - eps * qd)) / eps**2


def _innermost(equations: object) -> object:
    """The model's own evaluator under wrappers that keep its geometry (driver removal, faults)."""
    while hasattr(equations, "inner"):
        equations = equations.inner
    return equations


def point_output(model: Model, point: str | None = None, *, segment: str | None = None,
                 local: Sequence[float] | None = None) -> LinearOutput | JointPointOutput:
    """The position (x, z) of a point as a task output.

    Give either ``point`` (a named point of the model, see ``model.point_names``) or ``segment``
    and ``local`` = (along, across) in that segment's frame (natural coordinates: origin at its
    first point, x̄ towards the second; joint coordinates: a link name, its frame).  Natural
    coordinates: r = C q + d exactly (thesis eq. 3.32, :func:`cmbs.model.natural.point_map`);
    joint coordinates: :class:`JointPointOutput`.
    """
    if (point is None) == (segment is None):
        raise CmbsError("point output: give either a point name or a segment and a local position")
    if segment is not None and (local is None or len(local) != 2):
        raise CmbsError(f"point output: segment {segment!r} needs local = (along, across), got {local!r}")
    label = point if point is not None else f"{segment}{tuple(float(v) for v in local)}"
    names = (f"{label}.x", f"{label}.z")
    equations = _innermost(model.equations)
    if point is not None and point not in model.point_names:
        raise CmbsError(f"model {model.name!r} has no point {point!r}; points: {', '.join(model.point_names)}")
    if isinstance(equations, NaturalEquations):
        n = model.n
        if point is not None:
            indices, C = equations.point_xz[model.point_names.index(point)], np.eye(2)
        else:
            segments = {data.name: data for data in equations.segments}
            if segment not in segments:
                raise CmbsError(f"model {model.name!r} has no segment {segment!r}; "
                                f"segments: {', '.join(segments)}")
            data = segments[segment]
            indices, C = data.indices, point_map(data.length, (float(local[0]), float(local[1])))
        extended = np.zeros((2, n + equations.constants.size))
        np.add.at(extended.T, indices, C.T)
        matrix = extended[:, :n]
        if not matrix.any():
            raise CmbsError(f"point output {label!r} of model {model.name!r} is fixed to the ground: "
                            "it cannot follow a path")
        return LinearOutput(names, matrix, extended[:, n:] @ equations.constants)
    if isinstance(equations, joints.JointEquations):
        if point is not None:
            k = model.point_names.index(point)
            layout = equations.layout()
            link, position = int(layout.point_link[k]), tuple(float(v) for v in layout.point_local[k])
        else:
            if f"{segment}.origin" not in model.point_names:
                links = [name[:-len(".origin")] for name in model.point_names if name.endswith(".origin")]
                raise CmbsError(f"model {model.name!r} has no link {segment!r}; links: {', '.join(links)}")
            link = model.point_names.index(f"{segment}.origin") // 2  # links' origin/end come first, in order
            position = (float(local[0]), float(local[1]))
        return JointPointOutput(names, equations, link, position)
    raise CmbsError(f"point output: model {model.name!r} is neither a natural- nor a joint-coordinate model; "
                    "give the output as a FunctionOutput")


# ------------------------------------------------------------------ desired motion
@dataclass(frozen=True)
class CirclePath:
    """A point moving on a circle: y_d = c + r (cos φ, sin φ), φ = phase + 2π t / period
    (clockwise for a negative period), with exact ẏ_d, ÿ_d."""

    center: tuple[float, float]
    radius: float
    period: float
    phase: float = 0.0

    def __post_init__(self) -> None:
        if not self.radius > 0 or not math.isfinite(self.radius):
            raise CmbsError(f"circle path: radius must be > 0, got {self.radius}")
        if self.period == 0 or not math.isfinite(self.period):
            raise CmbsError(f"circle path: period must be a nonzero number, got {self.period}")

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rate = 2 * math.pi / self.period
        angle = self.phase + rate * t
        radial = np.array([math.cos(angle), math.sin(angle)])
        tangent = np.array([-math.sin(angle), math.cos(angle)])
        return (np.asarray(self.center, dtype=float) + self.radius * radial, self.radius * rate * tangent,
                -self.radius * rate**2 * radial)


@dataclass(frozen=True)
class TrackingTask:
    """Outputs ``output`` to follow ``desired(t) -> (y_d, ẏ_d, ÿ_d)`` (e.g. a :class:`CirclePath`
    or a :class:`cmbs.control.Reference` for coordinate outputs)."""

    output: Output
    desired: Desired

    @property
    def names(self) -> tuple[str, ...]:
        return self.output.names


# ------------------------------------------------------------------ the controller
def _unit_row_scale(matrix: np.ndarray) -> np.ndarray:
    """1 / (norm of each row), 1 for zero rows."""
    norms = np.linalg.norm(matrix, axis=1)
    return 1.0 / np.where(norms > 0, norms, 1.0)


@dataclass(frozen=True)
class UdwadiaKalabaStep:
    """The controller's quantities at one state (module docstring).

    ``qdd``: q̈*; ``constraint_force``: Q_c = M q̈* - Q (plant reaction included);
    ``actuator_force``: G u; ``u`` (n_u,); ``error``: e = y_d - y; ``residual``:
    ‖N M^{-1/2}(G u - Q_c)‖ = √(δq̈ᵀ M δq̈), 0 when Q_c is realised; ``unrealisable``: ρ.
    """

    qdd: np.ndarray
    constraint_force: np.ndarray
    actuator_force: np.ndarray
    u: np.ndarray
    error: np.ndarray
    residual: float
    unrealisable: float


class UdwadiaKalabaTracking:
    """Control through constraints: u(t, q, q̇) realising the Udwadia-Kalaba force of the task.

    Parameters
    ----------
    model
        The plant model (the controller's model of it).
    task
        A :class:`TrackingTask`.
    kp, kd
        Stabilisation gains (s⁻², s⁻¹), scalars or one per output; kd = 2√kp is critically damped.
    actuators
        Names of the inputs the controller may use (default: all); the others stay 0.
    tolerance
        Largest unrealisable fraction ρ accepted; above it a :class:`CmbsError` is raised.
        None: never raise, apply the least-squares inputs (see ``step(...).residual``).
    threshold
        Singular-value cut-off of the pseudo-inverses (of A_s M^{-1/2} with unit rows; relative to
        the largest for the actuators' N M^{-1/2} G).
    """

    def __init__(self, model: Model, task: TrackingTask, *, kp: float | Sequence[float],
                 kd: float | Sequence[float], actuators: Sequence[str] | None = None,
                 tolerance: float | None = 1e-6, threshold: float = 1e-9):
        self.model = model
        self.task = task
        k = len(task.names)
        self.kp = gain_vector(kp, k, "kp")
        self.kd = gain_vector(kd, k, "kd")
        if tolerance is not None and not tolerance >= 0:
            raise CmbsError(f"Udwadia-Kalaba control: tolerance must be >= 0 or None, got {tolerance}")
        if not threshold >= 0:
            raise CmbsError(f"Udwadia-Kalaba control: threshold must be >= 0, got {threshold}")
        self.tolerance = tolerance
        self.threshold = float(threshold)      # the compiled solve's argument type
        chosen = model.actuator_names if actuators is None else tuple(actuators)
        unknown = [name for name in chosen if name not in model.actuator_names]
        if unknown:
            raise CmbsError(f"model {model.name!r} has no actuator(s) {', '.join(unknown)}; "
                            f"actuators: {', '.join(model.actuator_names) or 'none'}")
        if not chosen:
            raise CmbsError(f"Udwadia-Kalaba control: model {model.name!r} has no actuators to apply the task force")
        if k > len(chosen):
            raise CmbsError(f"task {', '.join(task.names)} has {k} outputs but only {len(chosen)} actuator(s) "
                            f"({', '.join(chosen)}) act: the task is not realisable with these actuators")
        self.selected = np.array([model.actuator_names.index(name) for name in chosen], dtype=np.int64)
        self.gains = actuator_map(model, model.coordinate_names).T[:, self.selected]  # G: (n, selected)
        y_d, yd_d, ydd_d = (np.asarray(v, dtype=float) for v in task.desired(0.0))
        if not y_d.shape == yd_d.shape == ydd_d.shape == (k,):
            raise CmbsError(f"task desired(t) must return three ({k},) arrays for outputs {', '.join(task.names)}, "
                            f"got shapes {y_d.shape}, {yd_d.shape}, {ydd_d.shape}")
        self.mass_scale = float(np.trace(model.mass_matrix(model.q0))) / model.n
        n, rows = model.n, model.m + k
        self.solve_work = (np.zeros((rows, n)), np.zeros((3, n)), np.zeros((2, rows)), np.zeros(rows), np.zeros(n))
        self.terms = model.new_terms()
        self.no_input = np.zeros(model.n_u)

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return self.step(t, q, qd).u

    def step(self, t: float, q: np.ndarray, qd: np.ndarray) -> UdwadiaKalabaStep:
        """Everything the law computes at (t, q, q̇); raises :class:`CmbsError` when ρ > tolerance."""
        q, qd = np.asarray(q, dtype=float), np.asarray(qd, dtype=float)
        terms = self.model.evaluate(q, qd, t, self.no_input, out=self.terms)
        M, Q, A, gamma = terms.M, terms.Q, terms.A, terms.gamma
        output = self.task.output
        y_d, yd_d, ydd_d = (np.asarray(v, dtype=float) for v in self.task.desired(t))
        J = output.jacobian(q)
        error = y_d - output.value(q)
        b_task = ydd_d + self.kd * (yd_d - J @ qd) + self.kp * error - output.bias(q, qd)
        A_s = np.vstack([A, J])
        b_s = np.concatenate([gamma, b_task])
        M_hat, Q_hat = self._augmented(M, Q, A, gamma)
        try:
            L = np.linalg.cholesky(M_hat)
        except np.linalg.LinAlgError:
            raise CmbsError(f"Udwadia-Kalaba control at t={t:.6g}: the mass matrix of model {self.model.name!r} "
                            "is not positive definite on its constraint manifold") from None
        B = linalg.solve_triangular(L, A_s.T, lower=True, check_finite=False).T  # A_s L⁻ᵀ
        row_scale = _unit_row_scale(B)
        qdd = self._gauss_accelerations(M_hat, Q_hat, A_s, b_s, L, row_scale)
        force = M @ qdd - Q
        u_selected, residual, unrealisable = self._inputs(L, B * row_scale[:, None], A.shape[0], force)
        if self.tolerance is not None and unrealisable > self.tolerance:
            used = ", ".join(self.model.actuator_names[i] for i in self.selected)
            raise CmbsError(f"Udwadia-Kalaba control at t={t:.6g}: the task {', '.join(self.task.names)} needs "
                            f"generalized forces that the actuators ({used}) of model {self.model.name!r} cannot "
                            f"produce (unrealisable fraction {unrealisable:.3g} > tolerance {self.tolerance:g}); "
                            "the task is not realisable with these actuators: use fewer task outputs or more "
                            "actuators (tolerance=None applies the least-squares inputs anyway)")
        u = np.zeros(self.model.n_u)
        u[self.selected] = u_selected
        return UdwadiaKalabaStep(qdd=qdd, constraint_force=force, actuator_force=self.gains @ u_selected, u=u,
                                 error=error, residual=residual, unrealisable=unrealisable)

    def _augmented(self, M: np.ndarray, Q: np.ndarray, A: np.ndarray, gamma: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
        """M̂ = M + s ÃᵀÃ and Q̂ = Q + s Ãᵀγ̃, Ã and γ̃ the plant's rows scaled to unit norm
        (module docstring; M and Q themselves without plant constraints)."""
        scale = _unit_row_scale(A)
        A_unit = A * scale[:, None]
        return M + self.mass_scale * (A_unit.T @ A_unit), Q + self.mass_scale * (A_unit.T @ (gamma * scale))

    def _gauss_accelerations(self, M_hat: np.ndarray, Q_hat: np.ndarray, A_s: np.ndarray, b_s: np.ndarray,
                             L: np.ndarray, row_scale: np.ndarray) -> np.ndarray:
        """q̈* = a + L⁻ᵀ (A_s L⁻ᵀ)⁺ (b_s - A_s a), a = M̂⁻¹Q̂ (module docstring), by the Udwadia-Kalaba
        formulation's solve (:func:`~cmbs.dynamics.udwadia_kalaba.udwadia_kalaba_solve`) on the factor
        L of M̂ with the rows of A_s L⁻ᵀ scaled by ``row_scale``; NaN where a term is not finite (the
        plant's integrator then reports the state)."""
        qdd = np.empty(M_hat.shape[0])
        work_matrix, vectors_n, vectors_m, lam, force = self.solve_work
        udwadia_kalaba_solve(M_hat, Q_hat, A_s, b_s, NO_NONIDEAL, 0.0, True, self.threshold, row_scale, 1.0, L,
                             work_matrix, vectors_n, vectors_m, qdd, lam, force)
        return qdd

    def _inputs(self, L: np.ndarray, B_unit: np.ndarray, m: int, force: np.ndarray
                ) -> tuple[np.ndarray, float, float]:
        """The selected inputs u = (N L⁻¹ G)⁺ N L⁻¹ Q_c, the residual ‖N L⁻¹(G u - Q_c)‖ and the
        unrealisable fraction ρ (module docstring), from the factor L of M̂ and B̃ = A_s L⁻ᵀ with
        unit rows (its first ``m`` rows the plant's)."""
        unit = np.ones(B_unit.shape[0])
        B_unit_pinv, _ = pseudo_inverse(B_unit, self.threshold, unit)
        _, N = pseudo_inverse(B_unit[:m], self.threshold, unit[:m])  # projector onto null(A L⁻ᵀ)
        H = N @ linalg.solve_triangular(L, self.gains, lower=True, check_finite=False)  # N L⁻¹ G
        H_pinv, _ = pseudo_inverse(H, self.threshold)
        target = N @ linalg.solve_triangular(L, force, lower=True, check_finite=False)
        u_selected = H_pinv @ target
        residual = float(np.linalg.norm(H @ u_selected - target))
        demanded = N @ B_unit_pinv
        size = np.linalg.norm(demanded, 2) if demanded.size else 0.0
        unrealisable = float(np.linalg.norm(demanded - H @ (H_pinv @ demanded), 2) / size) if size > 0 else 0.0
        return u_selected, residual, unrealisable
