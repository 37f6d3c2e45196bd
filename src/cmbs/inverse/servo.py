"""Inverse dynamics of underactuated systems with servo constraints (Quasem, Uhlar & Betsch,
PAMM 9 (2009) 119-120, §1 and §3; Blajer & Kołodziejczyk, Multibody Syst. Dyn. 11 (2004);
THEORY §5).

A part of the motion is prescribed: m̃ outputs ``Ψ(q)`` follow ``y_ref(t)``, driven by as many
inputs ``u``, fewer than the degrees of freedom.  In the library's convention (THEORY §1) the
unknowns ``q(t), λ(t), u(t)`` satisfy::

    M(q) q̈ + Aᵀλ = Q(q, q̇, t, u),     Q = Q₀ + Bᵀu     (u enters linearly, through the actuators)
    Φ(q, t) = 0                         (m holonomic constraints, A = Φ_q)
    c(q, t) = Ψ(q) - y_ref(t) = 0       (m̃ servo constraints, C = Ψ_q)

(the paper writes ``M v̇ + ∇V + Gᵀλ + Bᵀu = 0``, ``g(q) = 0`` and ``c = Φ(q) - γ(t)``: its G is
our A, its Φ our Ψ, its γ our y_ref, and its actuation has the opposite sign).

Backward Euler (paper eq. (8)), step h from t_n to t_{n+1}, unknowns a, λ, u at n+1::

    v_{n+1} = v_n + h a,   q_{n+1} = q_n + h v_{n+1}

``method="full"`` imposes, at (q_{n+1}, v_{n+1}, t_{n+1}),

    M a + Aᵀλ - Q = 0   (n),    Φ = 0   (m),    c = 0   (m̃).

``method="projected"`` is the paper's eq. (7)-(8) (after Blajer & Kołodziejczyk): with D (n × (n-m̃))
spanning the null space of C(q_{n+1}) (C D = 0), the dynamics is split into

    Dᵀ (M a + Aᵀλ - Q) = 0                         (n - m̃)
    C M⁺ (Q - Aᵀλ) + ξ = 0,   ξ = Ċ q̇ - ÿ_ref     (m̃: the servo constraint at acceleration
                                                     level, c̈ = C q̈ + ξ = 0)
    Φ = 0,   c = 0.

M⁺ is M⁻¹ when M is regular.  In natural coordinates the angle coordinates carry no mass and M
is singular; C q̈ = C M⁺ M q̈ = C M⁺ (Q - Aᵀλ) still holds when the outputs depend on coordinates
with mass only (C M⁺ M = C, checked at the start; the paper's COM output is such).

The two are *different* discretisations of the same DAE.  ``[Dᵀ; C M⁺]`` is regular, so were the
second block ``C M⁺(M a + Aᵀλ - Q) = 0`` the projected system would be the full one; the paper
puts the exact acceleration-level condition at t_{n+1} there instead of the backward-Euler
acceleration a = (v_{n+1} - v_n)/h.  The solutions therefore agree to O(h), not to round-off
(tests/test_servo.py measures the difference and its halving with h).  As h → 0 both converge to
the DAE solution.  THEORY §5 writes the second block ``C M⁻¹(Q + Bᵀu - Aᵀλ) = ξ``; with the sign
of c̈ = C q̈ + ξ it is ``= -ξ`` (as here).

Newton's method solves each step.  The residual rows of Φ and c are divided by h² (their
derivative with respect to a is h² A, h² C), as in :mod:`cmbs.integrate.implicit`.  Jacobian:
the columns of a are *forward differences* of the dynamics rows (they include ∂Q/∂q, ∂Q/∂q̇ and
the Hessian-type terms ∂(M a + Aᵀλ)/∂q and, projected, ∂(C M⁺(Q - Aᵀλ) + Ċq̇)/∂q); the
columns of λ are analytic (Aᵀ, -C M⁺Aᵀ), those of u exact (Bᵀ = Q(u + e_i) - Q(u), Q is linear
in u); the constraint rows are analytic (A, C).  The projected rows use the smooth null-space
basis D(q) = (I - Cᵀ(CCᵀ)⁻¹C) E, E an orthonormal basis of null(C) at the step's first iterate,
and drop ∂D/∂q (its term, h² ∂D/∂q applied to r = M a + Aᵀλ - Q, is small: r is the O(h)
mismatch between the two schemes' servo-direction forces).  The iteration matrix is computed
at the first iterate of a step and kept while every iteration reduces the residual tenfold
(recomputed otherwise).  Newton stops when
max|Φ| ≤ tol and max|c| ≤ tol (model units) and the dynamics rows are below tol relative to the
size of their terms (1 + the largest of |M a|, |Q|, |Aᵀλ|; projected, s relative to 1 + the
largest of |C M⁺(Q - Aᵀλ)|, |Ċq̇|, |ÿ_ref|).

The start (t₀) needs a consistent state: Φ = 0, c = 0, A q̇ + Φ_t = 0, C q̇ = ẏ_ref.  Its
(a, λ, u) solve the continuous equations ``M a + Aᵀλ - Bᵀu = Q₀, A a = γ, C a = ÿ_ref - Ċq̇``.
With v₀ exact, the first backward-Euler acceleration is ((q₁ - q₀)/h - v₀)/h ≈ q̈₀/2: an O(1)
start layer unless the motion starts with zero acceleration (as rest-to-rest paths do).

The paper's case (examples/passive_manipulator_servo.py; its path was lost in the extraction,
this one is chosen): the library passive manipulator (links 5 m, 10 kg, horizontal plane) starts
at θ = (90°, -90°, 0°) at rest with the link-3 COM at (7.5, 5); the COM moves on the straight line
to (5.5, 3) with s(τ) = 10τ³ - 15τ⁴ + 6τ⁵, τ = t/3 (:class:`LinePath`), h = 0.01.  The passive
link swings through ~200°.  Its internal dynamics, I_G φ̈ = (r_J3 - r_G) × m r̈_G, is unstable
while the COM decelerates, which amplifies the O(h) differences between the discretisations
(RED vs GEN, full vs projected: 0.02-0.19 rad at h = 0.01, halving with h).

Outputs Ψ(q) (:class:`ServoOutput`): a point of a segment or link (:func:`segment_point`, e.g. a
centre of mass, exact Jacobian and Ċq̇ for natural- and joint-coordinate models), coordinates
(:func:`coordinate_output`) or any callable (:func:`callable_output`, derivatives by central
differences).  When a step has no solution (the path leaves the workspace, or the servo
constraint cannot be steered by the inputs at a singular configuration) a
:class:`ServoConvergenceError` says when, which residual and why.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from cmbs.errors import CmbsError, ConvergenceError
from cmbs.model.model import Model
from cmbs.trajectory import Trajectory

METHODS = ("full", "projected")
Reference = Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]]
_SINGULAR_CONDITION = 1e12                     # iteration matrices worse than this count as singular


class ServoConvergenceError(ConvergenceError):
    """No solution of a servo step: ``t`` the time, ``residual`` the name of the worst residual,
    ``value`` its size, ``condition`` the condition number of the iteration matrix."""

    def __init__(self, message: str, *, t: float, residual: str, value: float, condition: float):
        super().__init__(message)
        self.t = t
        self.residual = residual
        self.value = value
        self.condition = condition


# ------------------------------------------------------------------------------ outputs Ψ(q)
@dataclass(frozen=True)
class ServoOutput:
    """The prescribed outputs Ψ(q) (m̃,): ``value(q)``, ``jacobian(q)`` = C = Ψ_q (m̃, n) and
    ``bias(q, q̇)`` = Ċ q̇ (the output acceleration when q̈ = 0, the ξ of the paper without
    ÿ_ref)."""

    names: tuple[str, ...]
    value: Callable[[np.ndarray], np.ndarray]
    jacobian: Callable[[np.ndarray], np.ndarray]
    bias: Callable[[np.ndarray, np.ndarray], np.ndarray]

    @property
    def size(self) -> int:
        return len(self.names)


def segment_point(model: Model, segment: str, local: Sequence[float] | None = None) -> ServoOutput:
    """Position (x, z) of a point of ``segment`` (a segment of a natural-coordinate model or a link
    of a joint-coordinate model), at ``local`` = (along, across) in its frame; default its centre
    of mass.  Exact Jacobian and Ċq̇:

    - natural coordinates (thesis eq. 3.32): r = C_P (r_i, r_j), linear in q, so Ċq̇ = 0;
    - joint coordinates (:mod:`cmbs.model.joints`): r = O_k + R(θ_k) c, columns S(r - O_j)
      (revolute) or e_j (prismatic) along the path to the ground, Ċq̇ from the recursion of the
      frame origins' bias accelerations.
    """
    from cmbs.model.joints import JointEquations
    from cmbs.model.natural import NaturalEquations

    equations = getattr(model.equations, "inner", model.equations)  # a model without its drivers
    if isinstance(equations, NaturalEquations):
        return _natural_point(model, equations, segment, local)
    if isinstance(equations, JointEquations):
        return _joint_point(model, equations, segment, local)
    raise CmbsError(f"model {model.name!r}: segment_point needs a natural- or joint-coordinate model; "
                    "give the output as a callable Ψ(q) instead (callable_output)")


def _point_names(segment: str, local: Sequence[float] | None) -> tuple[str, str]:
    label = f"{segment}.com" if local is None else f"{segment}({local[0]:g},{local[1]:g})"
    return f"{label}.x", f"{label}.z"


def _local(local: Sequence[float] | None, default: Sequence[float], segment: str) -> tuple[float, float]:
    point = default if local is None else local
    values = np.asarray(point, dtype=float)
    if values.shape != (2,) or not np.all(np.isfinite(values)):
        raise CmbsError(f"segment_point {segment!r}: local must be two finite numbers (along, across), got {local!r}")
    return float(values[0]), float(values[1])


def _natural_point(model: Model, equations, segment: str, local: Sequence[float] | None) -> ServoOutput:
    from cmbs.model.natural import point_map

    segments = {data.name: data for data in equations.segments}
    if segment not in segments:
        raise CmbsError(f"model {model.name!r} has no segment {segment!r}; segments: {', '.join(segments)}")
    data = segments[segment]
    mapping = point_map(data.length, _local(local, data.com, segment))
    n = model.n
    C = np.zeros((2, n))
    offset = np.zeros(2)
    for column, index in enumerate(data.indices):
        if index < n:
            C[:, index] += mapping[:, column]
        else:  # a fixed point: a constant of the extended coordinates
            offset += mapping[:, column] * equations.constants[index - n]
    C.setflags(write=False)
    zero = np.zeros(2)
    return ServoOutput(_point_names(segment, local), lambda q: C @ q + offset, lambda q: C, lambda q, qd: zero)


def _joint_point(model: Model, equations, segment: str, local: Sequence[float] | None) -> ServoOutput:
    links = [name for name, _ in model.segment_masses]
    if segment not in links:
        raise CmbsError(f"model {model.name!r} has no link {segment!r}; links: {', '.join(links)}")
    k = links.index(segment)
    point = _local(local, equations.layout().com[k], segment)
    at_rest = np.zeros(model.n)

    def value(q: np.ndarray) -> np.ndarray:
        return equations.point_kinematics(k, point, q, at_rest)[0]

    def jacobian(q: np.ndarray) -> np.ndarray:
        return equations.point_kinematics(k, point, q, at_rest)[1]

    def bias(q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return equations.point_kinematics(k, point, q, qd)[2]

    return ServoOutput(_point_names(segment, local), value, jacobian, bias)


def coordinate_output(model: Model, names: Sequence[str]) -> ServoOutput:
    """Coordinates of the model as outputs: Ψ(q) = (q_c for c in names), C rows of the identity."""
    columns = model.coordinate_indices(list(names))
    C = np.eye(model.n)[columns]
    C.setflags(write=False)
    zero = np.zeros(columns.size)
    return ServoOutput(tuple(model.coordinate_names[c] for c in columns), lambda q: q[columns], lambda q: C,
                       lambda q, qd: zero)


def callable_output(function: Callable[[np.ndarray], np.ndarray], names: Sequence[str]) -> ServoOutput:
    """Any Ψ(q) -> (m̃,), one entry per name in ``names``.

    Jacobian by the 4-point central difference, step h = 1e-3·max(1, |q_k|) (truncation h⁴/30
    times the fifth derivative, round-off ~1e-13·|Ψ|/h); Ċq̇ = d²Ψ(q + σq̇)/dσ² at σ = 0 by the
    5-point central formula with a q-space step of 1e-2 (truncation ~1e-10 for trigonometric Ψ of
    unit scale).  The steps are fixed, so the derivatives are smooth in q and Newton's method
    converges; their truncation error perturbs the projected method only (it uses Ċq̇ and C in
    its residual; the full method uses C in its iteration matrix only)."""

    def value(q: np.ndarray) -> np.ndarray:
        return np.atleast_1d(np.asarray(function(q), dtype=float))

    def jacobian(q: np.ndarray) -> np.ndarray:
        columns = []
        for k in range(q.size):
            step = 1e-3 * max(1.0, abs(q[k]))
            shifted = [q.copy() for _ in range(4)]
            for shift, factor in zip(shifted, (-2.0, -1.0, 1.0, 2.0)):
                shift[k] += factor * step
            f = [value(s) for s in shifted]
            columns.append((f[0] - 8.0 * f[1] + 8.0 * f[2] - f[3]) / (12.0 * step))
        return np.array(columns).T

    def bias(q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        speed = float(np.max(np.abs(qd), initial=0.0))
        if speed == 0.0:
            return np.zeros_like(value(q))
        step = 1e-2 / speed
        f = [value(q + k * step * qd) for k in (-2, -1, 0, 1, 2)]
        return (-f[0] + 16.0 * f[1] - 30.0 * f[2] + 16.0 * f[3] - f[4]) / (12.0 * step * step)

    return ServoOutput(tuple(names), value, jacobian, bias)


# ------------------------------------------------------------------------------ reference path
@dataclass(frozen=True)
class LinePath:
    """Rest-to-rest straight line from ``start`` to ``end`` in ``duration`` seconds:
    y = start + s(τ)(end - start), s(τ) = 10τ³ - 15τ⁴ + 6τ⁵, τ = t/duration clipped to [0, 1]
    (zero velocity and acceleration at both ends).  Called with t it returns (y, ẏ, ÿ)."""

    start: np.ndarray
    end: np.ndarray
    duration: float

    def __post_init__(self) -> None:
        start, end = (np.asarray(p, dtype=float).ravel() for p in (self.start, self.end))
        if start.shape != end.shape or not (np.all(np.isfinite(start)) and np.all(np.isfinite(end))):
            raise CmbsError(f"line path: start {self.start!r} and end {self.end!r} must be finite and of one size")
        if not self.duration > 0:
            raise CmbsError(f"line path: duration must be > 0, got {self.duration!r}")
        object.__setattr__(self, "start", start)
        object.__setattr__(self, "end", end)

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        tau = min(max(t / self.duration, 0.0), 1.0)
        s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)
        ds = 30.0 * tau**2 * (1.0 - tau) ** 2 / self.duration
        dds = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau) / self.duration**2
        span = self.end - self.start
        return self.start + s * span, ds * span, dds * span


# ------------------------------------------------------------------------------ result
@dataclass(frozen=True)
class ServoResult:
    """The servo inverse dynamics of one run.

    ``trajectory``: t, q, q̇ (= v), q̈ (= a) and the extras ``u`` (k, n_u) named by
    ``actuator_names`` (actuators that are not inputs stay 0, so ``SampledInput(t, u)`` replays the
    run), ``lam`` (k, m), ``y`` = Ψ(q) and ``y_ref`` (k, m̃), ``newton_iterations`` (k,),
    ``constraint_residual`` = max|Φ| and ``servo_residual`` = max|c| (k,).  The first sample is
    the initial state, with (a, λ, u) of the continuous equations at t₀.
    """

    trajectory: Trajectory
    method: str
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    actuator_names: tuple[str, ...]

    @property
    def t(self) -> np.ndarray:
        return self.trajectory.t

    @property
    def u(self) -> np.ndarray:
        """(k, n_u) actuator inputs, columns named by :attr:`actuator_names`."""
        return self.trajectory.extras["u"]

    @property
    def lam(self) -> np.ndarray:
        return self.trajectory.extras["lam"]

    @property
    def iterations(self) -> np.ndarray:
        return self.trajectory.extras["newton_iterations"]

    @property
    def constraint_residual(self) -> np.ndarray:
        return self.trajectory.extras["constraint_residual"]

    @property
    def servo_residual(self) -> np.ndarray:
        return self.trajectory.extras["servo_residual"]

    def input(self, name: str) -> np.ndarray:
        """The history of actuator input ``name``."""
        if name not in self.actuator_names:
            raise CmbsError(f"no actuator {name!r}; actuators: {', '.join(self.actuator_names)}")
        return self.u[:, self.actuator_names.index(name)]


# ------------------------------------------------------------------------------ solver
def servo_inverse_dynamics(model: Model, outputs: ServoOutput | Callable[[np.ndarray], np.ndarray],
                           y_ref: Reference, times: Sequence[float] | np.ndarray, *,
                           inputs: Sequence[str] | None = None, method: str = "full", tol: float = 1e-10,
                           max_iterations: int = 20, q0: np.ndarray | None = None,
                           qd0: np.ndarray | None = None) -> ServoResult:
    """Inputs u(t) that make the outputs Ψ(q) follow ``y_ref(t)`` (module docstring).

    Parameters
    ----------
    outputs
        A :class:`ServoOutput` (:func:`segment_point`, :func:`coordinate_output`, ...) or a
        callable Ψ(q) -> (m̃,) (wrapped by :func:`callable_output`).
    y_ref
        Callable t -> (y, ẏ, ÿ), each (m̃,): e.g. :class:`LinePath` or
        :class:`cmbs.control.base.Reference`.  ẏ is used to check the start, ÿ by the
        projected method and the initial accelerations.
    times
        Strictly increasing instants; the steps are their differences, the start state is at
        ``times[0]``.
    inputs
        The m̃ actuators that act (default: all actuators of the model); the others stay at 0.
    method
        ``"full"`` or ``"projected"`` (Blajer & Kołodziejczyk's split, paper eq. (8)).
    tol, max_iterations
        Newton: max|Φ|, max|c| ≤ tol and dynamics rows ≤ tol relative to their terms.
    q0, qd0
        Start state (default the model's); it must satisfy Φ = 0, c = 0 and their velocity level.

    Raises
    ------
    CmbsError
        Bad arguments, or an inconsistent start.
    ServoConvergenceError
        A step without solution (time, residual, reason in the message).
    """
    if method not in METHODS:
        raise CmbsError(f"unknown servo method {method!r}; choose one of {', '.join(METHODS)}")
    if not (isinstance(tol, (int, float)) and tol > 0):
        raise CmbsError(f"tol must be a number > 0, got {tol!r}")
    if not (isinstance(max_iterations, int) and max_iterations >= 1):
        raise CmbsError(f"max_iterations must be an integer >= 1, got {max_iterations!r}")
    if model.nonholonomic.any():
        raise CmbsError(f"model {model.name!r} has nonholonomic constraints; servo inverse dynamics needs "
                        "holonomic constraints only")
    times = _checked_times(times)
    q = _state(model, model.q0 if q0 is None else q0, "q0")
    v = _state(model, model.qd0 if qd0 is None else qd0, "qd0")
    output = outputs if isinstance(outputs, ServoOutput) else _wrap_callable(outputs, q)
    actuators = _input_columns(model, inputs, output)
    system = _ServoSystem(model, output, y_ref, actuators, method == "projected")

    count, n, k = times.size, model.n, output.size
    history = {label: np.zeros((count, width)) for label, width in
               (("q", n), ("v", n), ("a", n), ("lam", model.m), ("u", k), ("y", k), ("y_ref", k))}
    iterations = np.zeros(count, dtype=np.int64)
    residuals = np.zeros((count, 2))
    a, lam, u = system.start(q, v, float(times[0]))
    for i in range(count):
        if i > 0:
            a, lam, u, q, v, iterations[i] = system.step(float(times[i]), float(times[i] - times[i - 1]), q, v, a,
                                                         lam, u, tol, max_iterations, i)
        y_now = system.reference(float(times[i]))[0]
        for label, value in (("q", q), ("v", v), ("a", a), ("lam", lam), ("u", u), ("y", output.value(q)),
                             ("y_ref", y_now)):
            history[label][i] = value
        residuals[i] = system.position_residuals(q, float(times[i]))
    u_full = np.zeros((count, model.n_u))
    u_full[:, actuators] = history["u"]
    names = tuple(model.actuator_names[j] for j in actuators)
    trajectory = Trajectory(
        times, history["q"], history["v"], history["a"], model.coordinate_names,
        {"u": u_full, "lam": history["lam"], "y": history["y"], "y_ref": history["y_ref"],
         "newton_iterations": iterations, "constraint_residual": residuals[:, 0], "servo_residual": residuals[:, 1]},
        {"analysis": "servo inverse dynamics", "method": method, "scheme": "backward-euler", "inputs": list(names),
         "outputs": list(output.names), "tolerance": tol, "model": model.name})
    return ServoResult(trajectory, method, names, output.names, model.actuator_names)


def _checked_times(times: Sequence[float] | np.ndarray) -> np.ndarray:
    array = np.asarray(times, dtype=float).ravel()
    if array.size < 2 or not np.all(np.isfinite(array)) or np.any(np.diff(array) <= 0):
        raise CmbsError("times must be at least 2 finite, strictly increasing instants")
    return array


def _state(model: Model, value: np.ndarray, label: str) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.shape != (model.n,) or not np.all(np.isfinite(array)):
        raise CmbsError(f"{label} must be {model.n} finite numbers for model {model.name!r}, got shape {array.shape}")
    return array.copy()


def _wrap_callable(function: Callable[[np.ndarray], np.ndarray], q: np.ndarray) -> ServoOutput:
    if not callable(function):
        raise CmbsError(f"outputs must be a ServoOutput or a callable Ψ(q), got {type(function).__name__}")
    size = np.atleast_1d(np.asarray(function(q.copy()), dtype=float)).size
    return callable_output(function, [f"y[{j}]" for j in range(size)])


def _input_columns(model: Model, inputs: Sequence[str] | None, output: ServoOutput) -> np.ndarray:
    names = list(model.actuator_names if inputs is None else inputs)
    unknown = [name for name in names if name not in model.actuator_names]
    if unknown:
        raise CmbsError(f"model {model.name!r} has no actuator(s) {', '.join(map(repr, unknown))}; "
                        f"actuators: {', '.join(model.actuator_names) or 'none'}")
    if len(set(names)) != len(names) or len(names) != output.size:
        raise CmbsError(f"servo inverse dynamics needs as many distinct inputs as outputs: {output.size} outputs "
                        f"({', '.join(output.names)}) but inputs {', '.join(names) or 'none'}; choose them with "
                        "inputs=[...]")
    return np.array([model.actuator_names.index(name) for name in names], dtype=np.int64)


@dataclass
class _Rows:
    """The dynamics rows at one iterate: r = M a + Aᵀλ - Q and, projected, s = C M⁺(Q - Aᵀλ) + Ċq̇ - ÿ,
    with the scales their tolerance is relative to."""

    r: np.ndarray
    s: np.ndarray | None
    force_scale: float
    acceleration_scale: float


@dataclass
class _ServoSystem:
    """The backward-Euler step equations of one problem (module docstring)."""

    model: Model
    output: ServoOutput
    y_ref: Reference
    actuators: np.ndarray
    projected: bool
    terms: object = field(init=False)
    probe: object = field(init=False)
    u_full: np.ndarray = field(init=False)
    mass_pinv: np.ndarray | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        self.terms = self.model.new_terms()
        self.probe = self.model.new_terms()
        self.u_full = np.zeros(self.model.n_u)
        if self.projected and self.model.constant_mass:
            self.mass_pinv = np.linalg.pinv(self.model.mass_matrix(self.model.q0), hermitian=True)

    # ---------------------------------------------------------------- pieces
    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        try:
            values = tuple(np.asarray(part, dtype=float).reshape(-1) for part in self.y_ref(t))
        except (TypeError, ValueError) as error:
            raise CmbsError(f"y_ref(t) must return (y, ẏ, ÿ), got an error at t = {t:g}: {error}") from None
        k = self.output.size
        if len(values) != 3 or any(part.shape != (k,) for part in values):
            raise CmbsError(f"y_ref(t) must return (y, ẏ, ÿ) of {k} values each (outputs "
                            f"{', '.join(self.output.names)}), got shapes {[part.shape for part in values]}")
        return values

    def _evaluate(self, q: np.ndarray, v: np.ndarray, t: float, u: np.ndarray, terms) -> None:
        self.u_full[self.actuators] = u
        self.model.evaluate(q, v, t, self.u_full, out=terms)

    def _input_matrix(self, q: np.ndarray, v: np.ndarray, t: float, u: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """Bᵀ (n, m̃): Q(u + e_i) - Q(u), exact because Q is linear in u."""
        columns = np.empty((self.model.n, u.size))
        for i in range(u.size):
            shifted = u.copy()
            shifted[i] += 1.0
            self._evaluate(q, v, t, shifted, self.probe)
            columns[:, i] = self.probe.Q - Q
        return columns

    def _rows(self, q: np.ndarray, v: np.ndarray, t: float, a: np.ndarray, lam: np.ndarray, u: np.ndarray,
              ydd: np.ndarray, terms, scales: bool = False) -> _Rows:
        """The dynamics rows at an iterate (with the scales of their terms when ``scales``)."""
        self._evaluate(q, v, t, u, terms)
        Ma, At_lam = terms.M @ a, terms.A.T @ lam
        r = Ma + At_lam - terms.Q
        force_scale = 1.0 + max(np.abs(Ma).max(), np.abs(terms.Q).max(), np.abs(At_lam).max(initial=0.0)) \
            if scales else 1.0
        if not self.projected:
            return _Rows(r, None, force_scale, 1.0)
        produced = self._c_minv(self.output.jacobian(q), terms.M) @ (terms.Q - At_lam)
        bias = self.output.bias(q, v)
        s = produced + bias - ydd
        scale = 1.0 + max(np.abs(produced).max(), np.abs(bias).max(), np.abs(ydd).max()) if scales else 1.0
        return _Rows(r, s, force_scale, scale)

    def _c_minv(self, C: np.ndarray, M: np.ndarray) -> np.ndarray:
        """C M⁺ (M symmetric): M⁻¹ for a regular M, the pseudo-inverse (cached) for the constant,
        singular M of natural coordinates with massless angle coordinates."""
        if self.mass_pinv is not None:
            return C @ self.mass_pinv
        try:
            return np.linalg.solve(M, C.T).T
        except np.linalg.LinAlgError:
            raise CmbsError(f"model {self.model.name!r}: the mass matrix is singular here; the projected method "
                            "needs a regular M (or a constant one); use method='full'") from None

    def position_residuals(self, q: np.ndarray, t: float) -> tuple[float, float]:
        """max|Φ(q, t)|, max|Ψ(q) - y_ref(t)|."""
        self._evaluate(q, np.zeros(self.model.n), t, np.zeros(self.output.size), self.probe)
        phi = float(np.abs(self.probe.phi).max(initial=0.0))
        return phi, float(np.abs(self.output.value(q) - self.reference(t)[0]).max())

    # ---------------------------------------------------------------- start
    def start(self, q: np.ndarray, v: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Check the start state and return (a, λ, u) of the continuous equations at t₀:
        M a + Aᵀλ - Bᵀu = Q₀, A a = γ, C a = ÿ_ref - Ċq̇."""
        model, output, n, m, k = self.model, self.output, self.model.n, self.model.m, self.output.size
        y, yd, ydd = self.reference(t)
        zero = np.zeros(k)
        self._evaluate(q, v, t, zero, self.terms)
        terms = self.terms
        C = output.jacobian(q)
        position = max(1.0, float(np.abs(q).max()))
        speed = max(1.0, float(np.abs(v).max()))
        checks = [(f"Φ ({_worst(terms.phi, model.constraint_names)})", terms.phi, position),
                  (f"Ψ(q0) - y_ref(t0) ({_worst(output.value(q) - y, output.names)})", output.value(q) - y, position),
                  (f"A q̇0 + Φ_t ({_worst(terms.A @ v + terms.phi_t, model.constraint_names)})",
                   terms.A @ v + terms.phi_t, speed),
                  (f"C q̇0 - ẏ_ref(t0) ({_worst(C @ v - yd, output.names)})", C @ v - yd, speed)]
        for label, values, scale in checks:
            if values.size and np.abs(values).max() > 1e-8 * scale:
                raise CmbsError(f"servo inverse dynamics of model {model.name!r}: the start state at t = {t:g} is "
                                f"inconsistent: {label} = {np.abs(values).max():.3g}; start the reference at the "
                                "outputs of the start state (and its rate at their rate), or assemble q0 on it")
        if self.projected:
            self._check_massive_outputs(C, terms.M)
        Q0 = terms.Q.copy()
        matrix = np.zeros((n + m + k, n + m + k))
        matrix[:n, :n] = terms.M
        matrix[:n, n:n + m] = terms.A.T
        matrix[:n, n + m:] = -self._input_matrix(q, v, t, zero, Q0)
        matrix[n:n + m, :n] = terms.A
        matrix[n + m:, :n] = C
        rhs = np.concatenate([Q0, terms.gamma, ydd - output.bias(q, v)])
        condition = np.linalg.cond(matrix)
        if not condition < _SINGULAR_CONDITION:
            raise ServoConvergenceError(
                f"servo inverse dynamics of model {model.name!r}: at the start t = {t:g} the system "
                f"[M Aᵀ -Bᵀ; A 0 0; C 0 0] is singular (condition number {condition:.3g}): the inputs "
                f"{', '.join(model.actuator_names[j] for j in self.actuators)} cannot steer the outputs "
                f"{', '.join(output.names)} here, or the constraints are redundant",
                t=t, residual="start", value=float("nan"), condition=condition)
        x = np.linalg.solve(matrix, rhs)
        return x[:n], x[n:n + m], x[n + m:]

    def _check_massive_outputs(self, C: np.ndarray, M: np.ndarray) -> None:
        """C q̈ = C M⁺ M q̈ needs range(Cᵀ) ⊆ range(M): outputs of coordinates that carry mass."""
        leak = np.abs(self._c_minv(C, M) @ M - C).max()
        if leak > 1e-9 * max(1.0, float(np.abs(C).max())):
            raise CmbsError(f"model {self.model.name!r}: the projected method needs outputs "
                            f"({', '.join(self.output.names)}) that depend on coordinates with mass only "
                            f"(C M⁺M = C fails by {leak:.3g}; angle coordinates of natural models carry no mass); "
                            "use method='full'")

    # ---------------------------------------------------------------- one step
    def step(self, t: float, h: float, q_old: np.ndarray, v_old: np.ndarray, a: np.ndarray, lam: np.ndarray,
             u: np.ndarray, tol: float, max_iterations: int, index: int):
        """Newton's method on the step equations; returns (a, λ, u, q, v, iterations).

        The iteration matrix is computed at the first iterate and kept while each iteration reduces
        the residual at least tenfold (recomputed otherwise)."""
        n, m = self.model.n, self.model.m
        y, _, ydd = self.reference(t)
        x = np.concatenate([a, lam, u])
        matrix, basis, reason, previous = None, None, "not converged", np.inf
        for iteration in range(max_iterations + 1):
            a, lam, u = x[:n], x[n:n + m], x[n + m:]
            v = v_old + h * a
            q = q_old + h * v
            rows = self._rows(q, v, t, a, lam, u, ydd, self.terms, scales=True)
            phi, c = self.terms.phi.copy(), self.output.value(q) - y
            C = self.output.jacobian(q)
            if self.projected and basis is None:
                basis = self._null_space(C, t)
            D = None if basis is None else self._projected_basis(C, basis)
            dynamics = rows.r if D is None else D.T @ rows.r
            sizes = self._sizes(phi, c, dynamics, rows)
            measure = max(sizes)
            if measure <= tol:
                return a.copy(), lam.copy(), u.copy(), q, v, iteration
            if iteration == max_iterations:
                break
            if matrix is None or measure > 0.1 * previous:
                matrix = self._iteration_matrix(t, h, q_old, v_old, q, v, a, lam, u, ydd, rows, C, D)
            previous = measure
            F = np.concatenate([dynamics] + ([rows.s] if D is not None else []) + [phi / (h * h), c / (h * h)])
            try:
                delta = np.linalg.solve(matrix, -F)
            except np.linalg.LinAlgError:
                reason = "singular"
                break
            if not np.all(np.isfinite(delta)):
                reason = "diverged"
                break
            x = x + delta
        condition = float(np.linalg.cond(matrix)) if matrix is not None else float("nan")
        if reason == "not converged" and not condition < _SINGULAR_CONDITION:
            reason = "singular"
        label, value = self._worst_residual(phi, c, dynamics, rows, sizes)
        raise self._failure(t, h, index, label, value, condition, reason, max_iterations)

    def _null_space(self, C: np.ndarray, t: float) -> np.ndarray:
        """An orthonormal basis (n, n - m̃) of null(C), from the SVD of C."""
        _, singular, vt = np.linalg.svd(C)
        if singular.size and singular.min() <= 1e-12 * max(singular.max(), 1.0):
            raise CmbsError(f"the output Jacobian C = Ψ_q has dependent rows at t = {t:g} "
                            f"(outputs {', '.join(self.output.names)}): the outputs are not independent")
        return vt[C.shape[0]:].T

    @staticmethod
    def _projected_basis(C: np.ndarray, basis: np.ndarray) -> np.ndarray:
        """D = (I - Cᵀ(CCᵀ)⁻¹C) E: a basis of null(C) that varies smoothly with q (E = the basis at
        the step's first iterate), so that the iteration matrix can be kept between iterations."""
        return basis - C.T @ np.linalg.solve(C @ C.T, C @ basis)

    def _sizes(self, phi: np.ndarray, c: np.ndarray, dynamics: np.ndarray, rows: _Rows) -> list[float]:
        """max|Φ|, max|c|, the dynamics rows relative to their terms and, projected, s relative."""
        sizes = [float(np.abs(phi).max(initial=0.0)), float(np.abs(c).max()),
                 float(np.abs(dynamics).max(initial=0.0)) / rows.force_scale]
        if rows.s is not None:
            sizes.append(float(np.abs(rows.s).max()) / rows.acceleration_scale)
        return sizes

    def _worst_residual(self, phi: np.ndarray, c: np.ndarray, dynamics: np.ndarray, rows: _Rows,
                        sizes: list[float]) -> tuple[str, float]:
        """Name and size of the largest of :meth:`_sizes`."""
        model, names = self.model, self.output.names
        labels = [f"constraint {_worst(phi, model.constraint_names)!r}: max|Φ|",
                  f"servo constraint {_worst(c, names)!r}: max|c|",
                  "projected dynamics Dᵀ(M a + Aᵀλ - Q), relative" if self.projected else
                  f"dynamics of {_worst(dynamics, model.coordinate_names)!r}: M a + Aᵀλ - Q, relative"]
        if rows.s is not None:
            labels.append(f"acceleration-level servo constraint {_worst(rows.s, names)!r}, relative")
        worst = int(np.argmax(sizes))
        return labels[worst], sizes[worst]

    def _iteration_matrix(self, t: float, h: float, q_old: np.ndarray, v_old: np.ndarray, q: np.ndarray,
                          v: np.ndarray, a: np.ndarray, lam: np.ndarray, u: np.ndarray, ydd: np.ndarray,
                          rows: _Rows, C: np.ndarray, D: np.ndarray | None) -> np.ndarray:
        n, m, k = self.model.n, self.model.m, self.output.size
        terms = self.terms
        M, A = terms.M.copy(), terms.A.copy()
        Bt = self._input_matrix(q, v, t, u, terms.Q.copy())
        size = n + m + k
        Jr = np.empty((n, size))
        Js = np.empty((k, size)) if D is not None else None
        for j in range(n):  # forward differences in a: q moves by δ, v by δ/h
            step = 1.5e-8 * max(1.0, abs(q[j])) / (h * h)
            shifted = a.copy()
            shifted[j] += step
            v_j = v_old + h * shifted
            probe = self._rows(q_old + h * v_j, v_j, t, shifted, lam, u, ydd, self.probe)
            Jr[:, j] = (probe.r - rows.r) / step
            if Js is not None:
                Js[:, j] = (probe.s - rows.s) / step
        Jr[:, n:n + m] = A.T
        Jr[:, n + m:] = -Bt
        matrix = np.zeros((size, size))
        if D is None:
            matrix[:n] = Jr
        else:
            CMinv = self._c_minv(C, M)
            Js[:, n:n + m] = -CMinv @ A.T
            Js[:, n + m:] = CMinv @ Bt
            matrix[:n - k] = D.T @ Jr
            matrix[n - k:n] = Js
        matrix[n:n + m, :n] = A
        matrix[n + m:, :n] = C
        return matrix

    def _failure(self, t: float, h: float, index: int, label: str, value: float, condition: float, reason: str,
                 max_iterations: int) -> ServoConvergenceError:
        if reason == "singular":
            why = (f"the iteration matrix is singular (condition number {condition:.3g}): at this configuration the "
                   f"inputs cannot steer the outputs (the servo constraint is not controllable, e.g. a stretched or "
                   f"folded arm at the workspace boundary) or the constraints are redundant")
        elif reason == "diverged":
            why = "Newton's method diverged (non-finite correction)"
        else:
            why = (f"Newton's method did not converge in {max_iterations} iterations (condition number "
                   f"{condition:.3g}): the prescribed path is not realisable here (it leaves the workspace) or "
                   "changes too fast for the step; try a smaller step")
        method = "projected" if self.projected else "full"
        return ServoConvergenceError(
            f"servo inverse dynamics ({method}) of model {self.model.name!r}: no solution at t = {t:.6g} s "
            f"(step {index}, h = {h:g}); worst residual: {label} = {value:.3g}; {why}",
            t=t, residual=label, value=value, condition=condition)


def _worst(values: np.ndarray, names: Sequence[str]) -> str:
    """The name of the entry of largest magnitude."""
    return names[int(np.argmax(np.abs(values)))] if len(values) else "-"
