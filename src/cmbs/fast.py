"""Compiled fixed-step simulation: the whole RK4 loop, model kernel and formulation solve in one
numba function, for natural- and joint-coordinate models.

Used by :func:`cmbs.simulate` when the run allows it (integrator ``rk4``; formulation
``lagrange``, ``baumgarte`` or ``projection`` with the standard inertia; constant inputs or a
:class:`~cmbs.control.ComputedTorque` law, alone or in a :class:`~cmbs.control.ZeroOrderHold`
sampled every step; no drift projection; no Python-callable time functions); otherwise the
Python path runs, which gives the same results (tested to 1e-12, closed loops to 1e-10),
including where Lagrange and Baumgarte stop at a singular configuration (the rank of A is
checked at every evaluation, as in Python).  The formulations are those of
:mod:`cmbs.dynamics` (same equations, same singularity check for Lagrange/Baumgarte)::

    lagrange/baumgarte   [M Aᵀ; A 0][q̈; λ] = [Q; γ - 2ξωΦ̇ - ω²Φ]
    projection           (M̂ + PM - M̂P) q̈ = PQ + M̂A⁺γ,   f_c = (I - P)(Mq̈ - Q),   λ = -(Aᵀ)⁺f_c

The computed-torque law is evaluated on its own model (which may differ from the plant) as in
:func:`computed_torque`.
"""

from __future__ import annotations

import functools
import math
import weakref
from typing import TYPE_CHECKING

from cmbs.jit import interpreted, njit, njit_borrowing, prange
import numpy as np

from cmbs.banded import band_factor, band_plan, band_solve, gram_profile, inverse_trace, jacobian_pattern
from cmbs.dynamics import Baumgarte, Formulation, Lagrange, Projection
from cmbs.errors import CmbsError, SingularSystemError
from cmbs.integrate.grid import whole_steps
from cmbs.lazy import lazy_module
from cmbs.model.drivers import evaluate_piecewise
from cmbs.model.model import Model
from cmbs.model.natural import NaturalEquations, _evaluate as _natural_kernel

if TYPE_CHECKING:
    from cmbs.control.computed_torque import ComputedTorque

#: the joint-coordinate model module, executed at its first use: a run of a natural model never
#: needs it (numba reads ``joints._evaluate_kernel`` when it compiles :func:`_evaluate`)
joints = lazy_module("cmbs.model.joints")

KIND_NATURAL, KIND_JOINT = 0, 1
LAGRANGE, BAUMGARTE, PROJECTION = 0, 1, 2
METHODS = {"lagrange": LAGRANGE, "baumgarte": BAUMGARTE, "projection": PROJECTION}
# status codes of the loop
OK, SINGULAR, NON_FINITE = 0, 1, 2
# inputs of the loop: constant, a computed-torque law at every stage, or that law sampled and held
CONSTANT, LAW, HELD = 0, 1, 2


def supported(model: Model) -> int | None:
    """The kernel kind of ``model`` if the compiled path can run it, else None."""
    equations = model.equations
    if isinstance(equations, NaturalEquations) and not equations.time_functions.python:
        return KIND_NATURAL
    if isinstance(equations, joints.JointEquations) and not equations.python:
        return KIND_JOINT
    return None


def kernel(model: Model) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(kind, ints, reals, buffer, mass) of a supported model: its kernel's data, a zeroed
    :class:`~cmbs.model.model.Terms` buffer, and the constant M of a natural-coordinate model
    (zeros for a joint model, whose M is in the buffer)."""
    kind = supported(model)
    equations = model.equations
    terms = model.new_terms()
    if kind == KIND_NATURAL:
        return kind, equations.ints, equations.reals, terms.buffer, np.array(terms.M)
    return kind, equations.ip, equations.rp, terms.buffer, np.zeros((model.n, model.n))


def control(u: object, model: Model, dt: float) -> tuple[int, ComputedTorque | None] | None:
    """(input mode, law) when the loop can compute the inputs ``u`` of a run of ``model`` with
    step ``dt``, else None.

    Constant inputs (an array or None) give CONSTANT; a :class:`ComputedTorque` gives LAW; a
    :class:`ZeroOrderHold` of one with period ``dt`` exactly gives HELD.  The law's own model
    must be supported and have the plant's coordinates and inputs counts.  Anything else (a
    fault wrapper, another law, another period) is Python's."""
    if not callable(u):
        return CONSTANT, None
    from cmbs.control.base import ZeroOrderHold   # here: a run with constant inputs does not import
    from cmbs.control.computed_torque import ComputedTorque   # the control package

    mode, law = (HELD, u.law) if type(u) is ZeroOrderHold and u.period == dt else (LAW, u)
    if type(law) is not ComputedTorque or supported(law.model) is None or law.model.n != model.n \
            or law.model.n_u != model.n_u:
        return None
    return mode, law


def method_of(chosen: Formulation) -> tuple[int, np.ndarray] | None:
    """(method, parameters) of :func:`field` for the formulation ``chosen``, or None when the
    compiled field does not run it (penalty, matrix R, Udwadia-Kalaba, least-squares Lagrange,
    the symmetric and parameterised projection inertias).  The projection's regularisation
    entries are filled in by :func:`bound_parameters`."""
    if isinstance(chosen, (Lagrange, Baumgarte)) and not chosen.least_squares:
        xi, omega = (chosen.xi, chosen.omega) if isinstance(chosen, Baumgarte) else (0.0, 0.0)
        return (BAUMGARTE if isinstance(chosen, Baumgarte) else LAGRANGE,
                np.array([xi, omega, chosen.singular_tolerance, 0.0, 0.0]))
    if isinstance(chosen, Projection) and chosen.inertia == "standard":
        return PROJECTION, np.array([0.0, 0.0, chosen.threshold, 0.0, 0.0])
    return None


def compiled_plan(model: Model, chosen: Formulation, integrator: str, u: object, project: bool, t_end: float,
                  dt: float) -> tuple | None:
    """(kernel kind, method, parameters, input mode, law) when :func:`rk4` (integrator ``rk4``,
    t_end a multiple of dt) or :mod:`cmbs.fast_adaptive` (``rk45``/``rk23``/``dop853``, constant inputs)
    can run the simulation of ``model`` under ``chosen``, else None."""
    kind = supported(model)
    inputs = control(u, model, dt)
    if project or inputs is None or kind is None:
        return None
    if integrator in ("rk45", "rk23", "dop853"):
        if inputs[0] != CONSTANT:
            return None
    elif integrator != "rk4" or whole_steps(t_end, dt) is None:
        return None
    method = method_of(chosen)
    return None if method is None else (kind, *method, *inputs)


def workspace(model: Model) -> tuple:
    """(kind, ints, reals, buffer, mass, schur) of a supported model: :func:`kernel` and the
    :func:`schur_workspace` built with its Jacobian's structure (:func:`jacobian_pattern`).

    Built once per model object (about 0.8 ms for a 14-link chain, a fifth of a second's
    compiled motion) and kept while the model lives; ``buffer`` is new at each call.  The
    ``schur`` tuple is shared: the loops write into private copies of its scratch arrays
    (:func:`_private_copy`), :class:`CompiledDynamics` into its packed copy."""
    cached = _WORKSPACES.get(id(model))
    if cached is None:
        kind, ints, reals, buffer, mass = kernel(model)
        cached = (kind, ints, reals, buffer.size, mass, schur_workspace(kind, mass, model.m, jacobian_pattern(model)))
        _WORKSPACES[id(model)] = cached
        weakref.finalize(model, _WORKSPACES.pop, id(model), None)
    kind, ints, reals, size, mass, schur = cached
    return kind, ints, reals, np.zeros(size), mass, schur


#: :func:`workspace`'s parts by the id of a live model (an entry leaves with its model).
_WORKSPACES: dict[int, tuple] = {}


def bound_parameters(method: int, parameters: np.ndarray, solver: object) -> np.ndarray:
    """``parameters`` with the mass-regularisation scale and semi-definite flag of the bound
    projection ``solver`` (unchanged for the other methods)."""
    parameters = np.array(parameters, dtype=float)
    if method == PROJECTION:
        parameters[3] = solver.scale
        parameters[4] = 1.0 if solver.semi_definite else 0.0
    return parameters


class CompiledDynamics:
    """Forward dynamics of one model under one formulation at single states, in one compiled call
    (model terms and solve: :func:`field`, the function the compiled RK4 loop runs at each stage).

    For callers that evaluate q̈ at states of their own (an integrator of their own, a shooting
    method, a benchmark).  Same results as ``formulation.bind(model).accelerations`` after
    ``model.evaluate`` (tested to 1e-10); Lagrange and Baumgarte check the rank of A and raise
    :class:`~cmbs.errors.SingularSystemError` naming the constraints, as the Python solver does.

    Parameters
    ----------
    model
        A natural- or joint-coordinate model without Python-callable time functions.
    formulation
        A name or a :class:`~cmbs.dynamics.Formulation`: ``lagrange``, ``baumgarte`` or
        ``projection`` (standard inertia).
    """

    def __init__(self, model: Model, formulation: str | Formulation = "lagrange"):
        from cmbs.dynamics import formulation as make_formulation

        chosen = make_formulation(formulation) if isinstance(formulation, str) else formulation
        kind = supported(model)
        plan = method_of(chosen)
        if kind is None or plan is None:
            raise CmbsError(f"the compiled field cannot run model {model.name!r} with formulation {chosen.name!r}: "
                            "it takes natural- or joint-coordinate models without Python time functions, with "
                            "lagrange, baumgarte or projection (standard inertia)")
        self.model, self.formulation = model, chosen
        self.solver = chosen.bind(model)
        self.method = plan[0]
        self.parameters = bound_parameters(plan[0], plan[1], self.solver)
        kind, ints, reals, buffer, mass, schur = workspace(model)
        n, m = model.n, model.m
        row_scale = np.ascontiguousarray(self.solver.row_scale, dtype=float)
        # bound once: a call then passes (and numba unboxes) only the state and the outputs
        self._field = functools.partial(_field_at, *pack_workspace(schur), kind, self.method, self.parameters, ints,
                                        reals, buffer, mass, row_scale, np.empty((n + m, n + m)), np.empty(n + m))
        self._no_input = np.zeros(model.n_u)

    def into(self, q: np.ndarray, qd: np.ndarray, t: float, u: np.ndarray | None, qdd: np.ndarray,
             lam: np.ndarray) -> int:
        """q̈ (n,) and λ (m,) at (q, q̇, t, u) into ``qdd`` and ``lam``; returns the status code
        (OK, SINGULAR or NON_FINITE).  Float64 contiguous arrays of the model's sizes; no
        checks and no allocation (the fast path)."""
        return self._field(q, qd, t, self._no_input if u is None else u, qdd, lam)

    def accelerations(self, q: np.ndarray, qd: np.ndarray, t: float = 0.0,
                      u: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(q̈, λ) at (q, q̇, t, u) as new arrays.

        Raises
        ------
        CmbsError
            Arrays of the wrong size; :class:`~cmbs.errors.SingularSystemError` at a singular
            configuration (Lagrange, Baumgarte: the constraints are named); non-finite terms or
            accelerations.
        """
        model = self.model
        q, qd = np.ascontiguousarray(q, dtype=float), np.ascontiguousarray(qd, dtype=float)
        u = self._no_input if u is None else np.ascontiguousarray(u, dtype=float)
        for name, value, size in (("q", q, model.n), ("qd", qd, model.n), ("u", u, model.n_u)):
            if value.shape != (size,):
                raise CmbsError(f"model {model.name!r}: {name} must have shape ({size},), got {value.shape}")
        qdd, lam = np.empty(model.n), np.empty(model.m)
        status = self.into(q, qd, float(t), u, qdd, lam)
        if status == SINGULAR:
            terms = model.evaluate(q, qd, t, u)
            self.solver.accelerations(terms, q, qd, t)   # raises, naming the dependent constraints
            raise SingularSystemError(f"model {model.name!r} at t={t:.6g}: singular system")
        if status != OK:
            raise CmbsError(f"model {model.name!r} at t={t:.6g}: non-finite terms or accelerations")
        return qdd, lam


def pack_workspace(schur: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The :func:`schur_workspace` tuple as three arrays (floats, ints, layout), which a call from
    Python unboxes in a fraction of the time its 27 entries take (about 1.6 µs, more than the
    four-bar's whole evaluation).  ``layout[k]`` = (0: float array, 1: int array, 2: scalar;
    offset or scalar value; rows; columns), a 1-D array having one column."""
    floats, integers, layout = [], [], []
    sizes = [0, 0]
    for entry in schur:
        if isinstance(entry, (int, np.integer)):
            layout.append((2, int(entry), 0, 0))
            continue
        array = np.ascontiguousarray(entry)
        group = 0 if array.dtype == np.float64 else 1
        rows, columns = (array.shape[0], 1) if array.ndim == 1 else array.shape
        layout.append((group, sizes[group], rows, columns))
        (floats if group == 0 else integers).append(array.ravel().astype(np.float64 if group == 0 else np.int64))
        sizes[group] += array.size
    return (np.concatenate(floats) if floats else np.zeros(0), np.concatenate(integers) if integers else
            np.zeros(0, dtype=np.int64), np.array(layout, dtype=np.int64))


@njit_borrowing(cache=True, inline="always")
def _matrix(values, layout, k):
    return values[layout[k, 1]:layout[k, 1] + layout[k, 2] * layout[k, 3]].reshape((layout[k, 2], layout[k, 3]))


@njit_borrowing(cache=True, inline="always")
def _vector(values, layout, k):
    return values[layout[k, 1]:layout[k, 1] + layout[k, 2]]


@njit_borrowing(cache=True, inline="always")
def unpack_workspace(floats, integers, layout):
    """The :func:`schur_workspace` tuple again from :func:`pack_workspace`'s arrays (views)."""
    return (_matrix(floats, layout, 0), layout[1, 1], _matrix(floats, layout, 2), _matrix(floats, layout, 3),
            _vector(floats, layout, 4), _matrix(integers, layout, 5), _vector(integers, layout, 6),
            _matrix(floats, layout, 7), _matrix(floats, layout, 8), _vector(integers, layout, 9),
            _vector(integers, layout, 10), _vector(floats, layout, 11), _vector(integers, layout, 12),
            _matrix(integers, layout, 13), _vector(integers, layout, 14), _matrix(floats, layout, 15), layout[16, 1],
            layout[17, 1], _matrix(floats, layout, 18), _vector(integers, layout, 19), _vector(floats, layout, 20),
            _vector(integers, layout, 21), _vector(integers, layout, 22), _vector(integers, layout, 23),
            _vector(floats, layout, 24), _vector(integers, layout, 25), _vector(integers, layout, 26),
            _vector(floats, layout, 27), _matrix(floats, layout, 28))


@njit_borrowing(cache=True)
def _field_at(floats, integers, layout, kind, method, parameters, ints, reals, buffer, mass, row_scale, K, rhs, q,
              qd, t, u, qdd, lam):
    """:func:`field` with the workspace packed by :func:`pack_workspace` (the call of
    :meth:`CompiledDynamics.into`)."""
    return field(kind, method, parameters, q, qd, t, u, ints, reals, buffer, mass, row_scale, qdd, lam, K, rhs, True,
                 unpack_workspace(floats, integers, layout))


def law_arrays(law: ComputedTorque | None, model: Model) -> tuple:
    """The tuple :func:`computed_torque` reads for ``law`` (its model's kernel, workspace and
    zero inputs; its coordinates, constraint rows and gains; the reference spline's breaks and
    coefficients, one row per coordinate in the flattened layout of
    :func:`~cmbs.model.drivers.evaluate_piecewise`; the inverse actuator gains; the dependent
    coordinates of the partition).  For no law
    (constant inputs) the same types, empty, on ``model``'s kernel: numba needs them typed."""
    if law is None:
        kind, ints, reals, buffer, mass = kernel(model)
        empty = np.zeros(0)
        return (kind, ints, reals, buffer, mass, model.m, np.zeros(model.n_u), np.zeros(0, dtype=np.int64),
                np.zeros(0, dtype=np.int64), empty, empty, empty, np.zeros((0, 0)), np.zeros((model.n_u, 0)),
                np.zeros(0, dtype=np.int64))
    kind, ints, reals, buffer, mass = kernel(law.model)
    spline = law.reference._spline
    coefficients = np.transpose(spline.c, (2, 1, 0)).reshape(law.columns.size, -1)  # [j, 4i + r] = c[r, i, j]
    return (kind, ints, reals, buffer, mass, law.model.m, np.zeros(law.model.n_u), law.columns.astype(np.int64),
            law.solver.partition.rows.astype(np.int64), np.array(law.kp, dtype=float),
            np.array(law.kd, dtype=float), np.ascontiguousarray(spline.x, dtype=float),
            np.ascontiguousarray(coefficients, dtype=float), np.ascontiguousarray(law.inverse_gains, dtype=float),
            law.solver.partition.dependent.astype(np.int64))


@njit_borrowing(cache=True, inline="always")
def _evaluate(kind, q, qd, t, u, ints, reals, buffer):
    if kind == KIND_NATURAL:
        _natural_kernel(q, qd, t, u, ints, reals, buffer)
    else:
        joints._evaluate_kernel(ints, reals, q, qd, t, u, buffer)


@njit_borrowing(cache=True)
def _gram_extremes(G):
    """Smallest and largest eigenvalue of the small symmetric matrix ``G`` (overwritten) by
    cyclic Jacobi rotations (Golub & Van Loan §8.5): for a few rows this avoids LAPACK's call
    and workspace overhead, which is larger than the arithmetic."""
    m = G.shape[0]
    for sweep in range(60):
        off = 0.0
        scale = 0.0
        for i in range(m):
            scale += G[i, i] * G[i, i]
            for j in range(i + 1, m):
                off += G[i, j] * G[i, j]
        if off <= 1e-32 * scale:
            break
        for p in range(m - 1):
            for r in range(p + 1, m):
                if G[p, r] == 0.0:
                    continue
                theta = (G[r, r] - G[p, p]) / (2.0 * G[p, r])
                t = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                for k in range(m):      # columns p, r
                    gkp, gkr = G[k, p], G[k, r]
                    G[k, p] = c * gkp - s * gkr
                    G[k, r] = s * gkp + c * gkr
                for k in range(m):      # rows p, r
                    gpk, grk = G[p, k], G[r, k]
                    G[p, k] = c * gpk - s * grk
                    G[r, k] = s * gpk + c * grk
    smallest, largest = G[0, 0], G[0, 0]
    for i in range(1, m):
        smallest = min(smallest, G[i, i])
        largest = max(largest, G[i, i])
    return smallest, largest


@njit_borrowing(cache=True)
def _cholesky_in_place(L, start):
    """Lower Cholesky factor L Lᵀ = K of the symmetric positive definite K given in ``L``'s lower
    triangle, in place (the upper triangle is not read).  ``start[i]`` is the first column of
    row i that may be non-zero (the profile of K, which the factor keeps: George & Liu 1981
    §4.2); zeros for a dense K.  Returns False when K is not numerically positive definite."""
    size = L.shape[0]
    for j in range(size):
        pivot = L[j, j]
        for k in range(start[j], j):
            pivot -= L[j, k] * L[j, k]
        if not pivot > 0.0:
            return False
        pivot = math.sqrt(pivot)
        L[j, j] = pivot
        for i in range(j + 1, size):
            if start[i] > j:
                continue
            total = L[i, j]
            for k in range(max(start[i], start[j]), j):
                total -= L[i, k] * L[j, k]
            L[i, j] = total / pivot
    return True


@njit_borrowing(cache=True)
def _forward(L, start, b):
    """Solve L x = b in place for the lower triangular L with row profile ``start``."""
    for i in range(L.shape[0]):
        total = b[i]
        for k in range(start[i], i):
            total -= L[i, k] * b[k]
        b[i] = total / L[i, i]


@njit_borrowing(cache=True)
def _backward(L, start, b):
    """Solve Lᵀ x = b in place for the lower triangular L with row profile ``start``."""
    for i in range(L.shape[0] - 1, -1, -1):
        b[i] /= L[i, i]
        for k in range(start[i], i):
            b[k] -= L[i, k] * b[i]


@njit_borrowing(cache=True)
def _gram(X, scale, gram, rows_of, start):
    """G = (SX)(SX)ᵀ into ``gram`` (S = diag(scale)), column by column over the rows each column
    touches, so a sparse X costs Σ_k nnz(column k)² instead of rows² x columns.

    ``rows_of`` (columns, rows + 1): row k holds column k's structural rows after their count
    (:func:`column_rows`, from the Jacobian's pattern; G then has the profile ``start`` and only
    that profile is cleared, filled and mirrored: O(m b) for a band), or a count of -1 when there
    is no pattern: the column is then scanned (O(mn)) and G cleared whole.  Entries of G outside
    the profile stay zero from the workspace's creation (callers that overwrite G restore them)."""
    m, n = X.shape
    structured = _structured(rows_of, n)
    for i in range(m):
        for j in range(start[i] if structured else 0, i + 1 if structured else m):
            gram[i, j] = 0.0
    for k in range(n):
        count = rows_of[k, 0]
        if count < 0:
            count = 0
            for i in range(m):
                if X[i, k] != 0.0:
                    rows_of[k, 1 + count] = i
                    count += 1
            rows_of[k, 0] = -1
        for a in range(count):
            i = rows_of[k, 1 + a]
            xi = X[i, k] * scale[i]
            if xi == 0.0:
                continue
            for b in range(a + 1):
                j = rows_of[k, 1 + b]
                gram[i, j] += xi * X[j, k] * scale[j]
    for i in range(m):
        for j in range(start[i] if structured else 0, i):
            gram[j, i] = gram[i, j]


@njit_borrowing(cache=True, inline="always")
def _structured(rows_of, n):
    """True when ``rows_of`` (:func:`column_rows`) lists A's structural rows, False when its
    counts are -1 (no pattern: the columns are scanned)."""
    return n > 0 and rows_of[0, 0] >= 0


def column_rows(pattern: np.ndarray | None, m: int, n: int) -> np.ndarray:
    """The ``rows_of`` workspace of :func:`_gram`: for each column of A's structural ``pattern``
    (m, n), its row count and rows; without a pattern, counts of -1 (scan each call)."""
    rows_of = np.zeros((max(n, 1), m + 1), dtype=np.int64)
    if pattern is None:
        rows_of[:, 0] = -1
        return rows_of
    for k in range(n):
        rows = np.flatnonzero(pattern[:, k])
        rows_of[k, 0] = rows.size
        rows_of[k, 1:1 + rows.size] = rows
    return rows_of


@njit_borrowing(cache=True)
def _gram_bounds(A, row_scale, gram, factor, rows_of, start, Z):
    """Bounds (λ_low, λ_high) on the extreme eigenvalues of the Gram matrix G = (SA)(SA)ᵀ
    (S = diag(row_scale)), left in ``gram``, with λ_low <= λ_min(G) and λ_max(G) <= λ_high:
    λ_high = trace G and λ_low = 1 / trace G⁻¹, because the trace of a positive definite matrix
    lies between its largest eigenvalue and m times it.  trace G⁻¹ comes from the Cholesky
    factor L of G (in ``factor``, keeping G's profile ``start``) by the Takahashi recurrence
    (:func:`cmbs.banded.inverse_trace`, workspace ``Z``): O(m b²) for a profile of half-width b.
    λ_low = 0 when G is not numerically positive definite."""
    m = A.shape[0]
    _gram(A, row_scale, gram, rows_of, start)
    trace = 0.0
    for i in range(m):
        trace += gram[i, i]
        for j in range(start[i], i + 1):
            factor[i, j] = gram[i, j]
    if not _cholesky_in_place(factor, start):
        return 0.0, trace
    if Z.shape[1] < m:                      # a narrow profile: O(m b²)
        return 1.0 / inverse_trace(factor, start, Z), trace
    total = 0.0                             # dense: ‖L⁻¹‖_F² column by column, the entries below
    for j in range(m):                      # the diagonal in factor's upper triangle (scratch)
        diagonal = 1.0 / factor[j, j]
        total += diagonal * diagonal
        for i in range(j + 1, m):
            value = -factor[i, j] * diagonal
            for k in range(j + 1, i):
                value -= factor[i, k] * factor[j, k]
            value /= factor[i, i]
            factor[j, i] = value
            total += value * value
    return 1.0 / total, trace


#: Largest m·n for which :func:`_bounds` keeps a reference A without A's structure (its test then
#: costs m·n operations; with the structure, one per structural non-zero).
BOUNDS_REUSE_SIZE = 1024


@njit_borrowing(cache=True, inline="always")
def _bounds(A, row_scale, reference, A0, gram, factor, rows_of, start, Z):
    """(λ_low, λ_high, reused): bounds on the extreme eigenvalues of G = (SA)(SA)ᵀ as
    :func:`_gram_bounds` gives them, from a reference A₀ bounded earlier when A is close to it.

    By Weyl's inequality for singular values (Golub & Van Loan, Cor. 8.6.2), with
    δ = ‖S(A - A₀)‖_F ≥ ‖S(A - A₀)‖₂: σ_min(SA) ≥ σ_min(SA₀) - δ and σ_max(SA) ≤ σ_max(SA₀) + δ,
    so (√λ₀_low - δ)² and (√λ₀_high + δ)² are bounds again.  Reused while δ ≤ √λ₀_low / 10 (the
    lower bound loses at most 19 %); otherwise, or without a valid reference, the Gram bounds
    are computed afresh (which leaves G in ``gram``: ``reused`` False) and A becomes the
    reference (``reference`` = (valid, √λ_low, √λ_high), ``A0``) when they prove full rank.
    A step moves A little, so most stages of a run skip the Gram matrix, its Cholesky factor and
    trace G⁻¹.  With A's structure (``rows_of`` of :func:`column_rows`), δ and the copy into A₀
    run over the structural non-zeros only: the entries outside are zero in A and A₀ alike."""
    m, n = A.shape
    structured = _structured(rows_of, n)
    if reference[0] == 1.0:
        total = 0.0
        for j in range(n):
            for a in range(rows_of[j, 0] if structured else m):
                i = rows_of[j, 1 + a] if structured else a
                difference = (A[i, j] - A0[i, j]) * row_scale[i]
                total += difference * difference
        delta = math.sqrt(total)
        if delta <= 0.1 * reference[1]:
            return (reference[1] - delta) ** 2, (reference[2] + delta) ** 2, True
    low, high = _gram_bounds(A, row_scale, gram, factor, rows_of, start, Z)
    reference[0] = 0.0
    if low > 0.0 and A0.shape[0] == m:
        for j in range(n):
            for a in range(rows_of[j, 0] if structured else m):
                i = rows_of[j, 1 + a] if structured else a
                A0[i, j] = A[i, j]
        reference[0], reference[1], reference[2] = 1.0, math.sqrt(low), math.sqrt(high)
    return low, high, False


@njit_borrowing(cache=True, inline="always")
def _bounds_meeting(A, row_scale, ratio, floor, reference, A0, gram, factor, rows_of, start, Z):
    """(λ_low, λ_high) of :func:`_bounds`, computed afresh (G then in ``gram``) when reused ones
    fail the caller's test λ_low >= ratio²·max(λ_high, 1) and λ_low > floor²: a test lost only
    to the reuse's slack is decided on the fresh bounds."""
    low, high, reused = _bounds(A, row_scale, reference, A0, gram, factor, rows_of, start, Z)
    if reused and (low < ratio * ratio * max(high, 1.0) or low <= floor * floor):
        reference[0] = 0.0
        low, high, reused = _bounds(A, row_scale, reference, A0, gram, factor, rows_of, start, Z)
    return low, high


@njit_borrowing(cache=True, inline="always")
def _certify(A, row_scale, tolerance, reference, A0, gram, factor, rows_of, start, Z):
    """(singular, certified, decided) for the constraint Jacobian A: ``singular`` when σ_min/σ_max
    of the row-scaled SA is below ``tolerance`` (as KKTSolver's SVD test, with σ_max replaced by
    1 when smaller); ``certified`` when cheap bounds already prove it is not (:func:`_bounds`).
    Only uncertified cases pay for the eigenvalues: Jacobi rotations for up to 12 rows
    (:func:`_gram_extremes`); beyond, ``decided`` is False, G is left in ``gram`` (the bounds
    that failed were fresh) and the caller decides by :func:`_gram_singular` (LAPACK, which
    creates arrays: not in a borrowing kernel)."""
    m, n = A.shape
    if m == 0:
        return False, True, True
    if m > n:
        return True, False, True
    low, high = _bounds_meeting(A, row_scale, tolerance, 0.0, reference, A0, gram, factor, rows_of, start, Z)
    if low >= tolerance * tolerance * max(high, 1.0):
        return False, True, True
    if m > 12:
        return False, False, False
    low, high = _gram_extremes(gram)        # fresh bounds failed: G is in gram
    gram[:, :] = 0.0                        # the rotations filled it: zero outside the profile again
    smallest, largest = math.sqrt(max(low, 0.0)), math.sqrt(max(high, 0.0))
    return smallest < tolerance * max(largest, 1.0), False, True


@njit(cache=True)
def _gram_singular(gram, tolerance):
    """The singularity test of :func:`_certify` on the Gram matrix ``gram`` = (SA)(SA)ᵀ, by
    LAPACK's symmetric eigenvalues (σ² of SA)."""
    eigenvalues = np.linalg.eigvalsh(gram)
    smallest = math.sqrt(max(eigenvalues[0], 0.0))
    largest = math.sqrt(max(eigenvalues[eigenvalues.shape[0] - 1], 0.0))
    return smallest < tolerance * max(largest, 1.0)


@njit_borrowing(cache=True, inline="always")
def _schur_solve(M, Q, A, c, schur, qdd, lam):
    """q̈, λ of [M Aᵀ; A 0][q̈; λ] = [Q; c] by block elimination of the coordinates p that carry
    mass (the range-space method, Golub & Van Loan §4.2; Nocedal & Wright §16.2).  Split
    q = (p, a) with a the massless coordinates (zero rows of M, e.g. a natural model's angle
    coordinates), X = M_pp⁻¹A_pᵀ, y = M_pp⁻¹Q_p::

        [A_p X  -A_a] [λ  ]   [A_p y - c]
        [A_aᵀ    0  ] [q̈_a] = [Q_a      ],      q̈_p = y - Xλ

    solved by Cholesky when a is empty (A_p X is then positive definite for a full-rank A),
    else by Gaussian elimination with partial pivoting: m + n_a unknowns instead of n + m.  The
    products with A use its non-zeros only (a natural model's rows have a few).

    ``schur`` is the tuple of :func:`schur_workspace`.  Its flag 1: the first matrix is the
    constant M_pp⁻¹ (natural coordinates: inverted once); 0: M is factored here by Cholesky
    (joint coordinates); -1: M_pp is not positive definite (returns False: the caller solves
    the full system).  Returns False when a factorisation meets a non-positive pivot or the
    reduced system is singular."""
    matrix, flag, X, K, y, columns, counts, massive, massless, z, dense = (
        schur[0], schur[1], schur[2], schur[3], schur[4], schur[5], schur[6], schur[9], schur[10], schur[11],
        schur[12])
    n_p = massive.shape[0]
    n_a = massless.shape[0]
    m = c.shape[0]
    if flag < 0:
        return False
    if flag == 0:
        for i in range(n_p):
            for j in range(i + 1):
                matrix[i, j] = M[massive[i], massive[j]]
        if not _cholesky_in_place(matrix, dense):
            return False
    for r in range(m):                      # non-zeros of A_p's rows; X's rows
        count = 0
        for i in range(n_p):
            if A[r, massive[i]] != 0.0:
                columns[r, count] = i
                count += 1
        counts[r] = count
        if flag == 1:
            for i in range(n_p):
                total = 0.0
                for t in range(count):
                    total += matrix[i, columns[r, t]] * A[r, massive[columns[r, t]]]
                X[r, i] = total
        else:
            for i in range(n_p):
                X[r, i] = A[r, massive[i]]
            _forward(matrix, dense, X[r])
            _backward(matrix, dense, X[r])
    if flag == 1:
        for i in range(n_p):
            total = 0.0
            for j in range(n_p):
                total += matrix[i, j] * Q[massive[j]]
            y[i] = total
    else:
        for i in range(n_p):
            y[i] = Q[massive[i]]
        _forward(matrix, dense, y)
        _backward(matrix, dense, y)
    reduced = K                             # (m + n_a)², as schur_workspace sizes it
    for a in range(m):
        total = -c[a]
        for t in range(counts[a]):
            total += A[a, massive[columns[a, t]]] * y[columns[a, t]]
        z[a] = total
        for b in range(a + 1):
            value = 0.0
            for t in range(counts[a]):
                value += A[a, massive[columns[a, t]]] * X[b, columns[a, t]]
            reduced[a, b] = reduced[b, a] = value
        for j in range(n_a):
            reduced[a, m + j] = -A[a, massless[j]]
            reduced[m + j, a] = A[a, massless[j]]
    for j in range(n_a):
        z[m + j] = Q[massless[j]]
        for i in range(n_a):
            reduced[m + j, m + i] = 0.0
    if n_a == 0:
        if not _cholesky_in_place(reduced, dense):
            return False
        _forward(reduced, dense, z)
        _backward(reduced, dense, z)
    elif not _solve_in_place(reduced, z):
        return False
    for a in range(m):
        lam[a] = z[a]
    for j in range(n_a):
        qdd[massless[j]] = z[m + j]
    for i in range(n_p):
        total = y[i]
        for a in range(m):
            total -= X[a, i] * lam[a]
        qdd[massive[i]] = total
    return True


def schur_workspace(kind: int, mass: np.ndarray, m: int, pattern: np.ndarray | None = None) -> tuple:
    """The ``schur`` tuple of :func:`_schur_solve` and :func:`field` for a kernel of ``kind``
    with ``m`` constraints and constant mass matrix ``mass`` (natural) or its shape (joint);
    ``pattern``, the structural non-zeros of A (:func:`cmbs.banded.jacobian_pattern`), lets
    the Gram matrix keep its profile and large natural models solve by band LU.

    Natural coordinates: the coordinates with a zero row in M are massless (a), the others (p)
    have the constant M_pp, inverted once here (flag 1; -1 when M_pp is not positive definite);
    joint coordinates: all carry mass and M is factored at each call (flag 0).  Then
    workspaces: X (m, n_p), the reduced matrix (m + n_a)², y (n_p,), A's row non-zeros (m, n)
    and their counts (m,), two Gram matrices (m, m), the index arrays of p and a, a vector
    (m + n_a,), the dense profile (zeros) of a matrix of max(n, m) rows, the Gram's column
    lists (:func:`column_rows`), the Gram's profile (m,) and the Takahashi band (m, b + 1); then the band KKT
    plan (:func:`_band_kkt`): its flag (1: used), half-width b, storage (3b + 1, n + m),
    pivots, right-hand side, the position of each unknown, M's non-zeros (row, column, value)
    and A's structural non-zeros (row, column); last the reference of :func:`_bounds`: (valid,
    √λ_low, √λ_high) and its A (m, n), empty without ``pattern`` when m·n > BOUNDS_REUSE_SIZE."""
    n = mass.shape[0]
    flag = 0
    massive = np.arange(n)
    matrix = np.zeros((n, n))
    if kind == KIND_NATURAL:
        massive = np.flatnonzero(np.any(mass != 0.0, axis=1))
        block = mass[np.ix_(massive, massive)]
        try:
            np.linalg.cholesky(block)       # positive definite: the inverse is safe
            matrix = np.linalg.inv(block)
            flag = 1
        except np.linalg.LinAlgError:
            flag = -1
    massless = np.setdiff1d(np.arange(n), massive)
    size = m + massless.size
    start = np.zeros(m, dtype=np.int64) if pattern is None else gram_profile(pattern)
    width = int(np.max(np.arange(m) - start, initial=0))
    band = _band_workspace(kind, flag, mass, pattern, m, massive.size)
    return (matrix, flag, np.zeros((m, massive.size)), np.zeros((size, size)), np.zeros(massive.size),
            np.zeros((m, max(n, 1)), dtype=np.int64), np.zeros(m, dtype=np.int64), np.zeros((m, m)),
            np.zeros((m, m)), massive.astype(np.int64), massless.astype(np.int64), np.zeros(size),
            np.zeros(max(n, m), dtype=np.int64), column_rows(pattern, m, n),
            start, np.zeros((max(m, 1), width + 1)), *band, np.zeros(3),
            np.zeros((m, n)) if m * n <= BOUNDS_REUSE_SIZE or pattern is not None else np.zeros((0, 0)))


#: Band KKT solves are used from this many unknowns (n + m) on, when cheaper than the Schur path
#: (measured: the band LU wins from about 22 unknowns, a pinned 8-link chain; the cost estimate
#: of :func:`_band_workspace` chooses between the two).
BAND_MINIMUM_SIZE = 20


def _band_workspace(kind: int, flag: int, mass: np.ndarray, pattern: np.ndarray | None, m: int,
                    n_p: int) -> tuple:
    """The band part of :func:`schur_workspace`: used (flag 1) for natural models of at least
    BAND_MINIMUM_SIZE unknowns whose band LU, ~(n + m)·3b² operations, is cheaper than the
    Schur path's ~m³/3 + m²·n_p."""
    n = mass.shape[0]
    use = 0
    width = 0
    order = np.arange(n + m, dtype=np.int64)
    if kind == KIND_NATURAL and flag == 1 and pattern is not None and n + m >= BAND_MINIMUM_SIZE:
        order, width = band_plan(mass, pattern)
        use = 1 if (n + m) * 3.0 * width * width < m ** 3 / 3.0 + m * m * n_p else 0
    position = np.empty(n + m, dtype=np.int64)
    position[order] = np.arange(n + m)
    mass_rows, mass_columns = np.nonzero(mass)
    a_rows, a_columns = np.nonzero(pattern) if pattern is not None else (np.zeros(0, int), np.zeros(0, int))
    return (use, width, np.zeros((n + m, 3 * width + 1)), np.zeros(n + m, dtype=np.int64), np.zeros(n + m),
            position, mass_rows.astype(np.int64), mass_columns.astype(np.int64),
            np.ascontiguousarray(mass[mass_rows, mass_columns], dtype=float), a_rows.astype(np.int64),
            a_columns.astype(np.int64))


@njit_borrowing(cache=True)
def _band_kkt(Q, A, c, schur, qdd, lam):
    """q̈, λ of [M Aᵀ; A 0][q̈; λ] = [Q; c] by band LU in the reverse Cuthill-McKee order of
    :func:`cmbs.banded.band_plan` (M's non-zeros are constant and listed in the workspace, A's
    read at its structural non-zeros).  Returns False for an exactly singular matrix."""
    width, AB, pivots, rhs, position = schur[17], schur[18], schur[19], schur[20], schur[21]
    mass_rows, mass_columns, mass_values, a_rows, a_columns = schur[22], schur[23], schur[24], schur[25], schur[26]
    n = Q.shape[0]
    m = c.shape[0]
    diagonal = 2 * width
    AB[:, :] = 0.0
    for k in range(mass_rows.shape[0]):
        i, j = position[mass_rows[k]], position[mass_columns[k]]
        AB[j, diagonal + i - j] = mass_values[k]
    for k in range(a_rows.shape[0]):
        value = A[a_rows[k], a_columns[k]]
        i, j = position[n + a_rows[k]], position[a_columns[k]]
        AB[j, diagonal + i - j] = value
        AB[i, diagonal + j - i] = value
    for i in range(n):
        rhs[position[i]] = Q[i]
    for r in range(m):
        rhs[position[n + r]] = c[r]
    if not band_factor(AB, width, pivots):
        return False
    band_solve(AB, width, pivots, rhs)
    for i in range(n):
        qdd[i] = rhs[position[i]]
    for r in range(m):
        lam[r] = rhs[position[n + r]]
    return True


@njit_borrowing(cache=True)
def _solve_in_place(K, rhs):
    """Gaussian elimination with partial pivoting on a small dense system; the solution
    overwrites ``rhs`` and K is destroyed (its diagonal ends holding the pivots' reciprocals:
    one division per column).  Returns False for an exactly singular matrix.  (The pivot search
    is that of :func:`_lu_in_place`; eliminating into the right-hand side directly avoids the
    pivot array, whose allocation costs 13 % of a four-bar stage.)"""
    size = rhs.shape[0]
    for column in range(size):
        pivot = column
        largest = abs(K[column, column])
        for row in range(column + 1, size):
            if abs(K[row, column]) > largest:
                largest = abs(K[row, column])
                pivot = row
        if largest == 0.0:
            return False
        if pivot != column:                 # columns left of ``column`` are no longer read
            for k in range(column, size):
                K[column, k], K[pivot, k] = K[pivot, k], K[column, k]
            rhs[column], rhs[pivot] = rhs[pivot], rhs[column]
        inverse = 1.0 / K[column, column]
        K[column, column] = inverse
        for row in range(column + 1, size):
            factor = K[row, column] * inverse
            if factor != 0.0:
                for k in range(column + 1, size):
                    K[row, k] -= factor * K[column, k]
                rhs[row] -= factor * rhs[column]
    for row in range(size - 1, -1, -1):
        total = rhs[row]
        for k in range(row + 1, size):
            total -= K[row, k] * rhs[k]
        rhs[row] = total * K[row, row]
    return True


#: The projection formulation takes the Schur-complement path when the row-scaled A is certified
#: to have σ_min >= this (times max(σ_max, 1)) and above the formulation's SVD threshold.
PROJECTION_REGULAR = 1e-4


@njit_borrowing(cache=True, inline="always")
def _projection_by_schur(band, M, Q, A, gamma, row_scale, threshold, schur, qdd, lam):
    """Aghili's standard projection solution at a regular configuration, by the augmented system.

    When A has full row rank and no singular value of the row-scaled DA falls below the SVD
    ``threshold``, the pseudo-inverse discards nothing, A⁺ = Aᵀ(AAᵀ)⁻¹ and P = I - A⁺A, and
    (M̂ + PM - M̂P) q̈ = PQ + M̂A⁺γ holds exactly when P(Mq̈ - Q) = 0 and Aq̈ = γ (Aghili 2005,
    §IV: the two projections of the equation), i.e. when Mq̈ + Aᵀλ = Q, Aq̈ = γ for some λ: the
    Lagrange solution, unique here, with the same multipliers (λ = -(Aᵀ)⁺f_c and f_c = -Aᵀλ).
    Taken only when the Gram-matrix bounds of :func:`_bounds` certify σ_min(DA) >=
    PROJECTION_REGULAR·max(σ_max, 1) and σ_min > ``threshold``; returns False otherwise (near
    singular positions, redundant constraints), and the caller takes the SVD path.  Solved by
    band LU when ``band`` and the workspace chose it (schur[16] == 1), else by the Schur
    complement."""
    m = A.shape[0]
    if m == 0 or m > A.shape[1]:
        return False
    low, high = _bounds_meeting(A, row_scale, PROJECTION_REGULAR, threshold, schur[27], schur[28], schur[7], schur[8],
                                schur[13], schur[14], schur[15])
    if low < PROJECTION_REGULAR * PROJECTION_REGULAR * max(high, 1.0) or low <= threshold * threshold:
        return False
    if band and schur[16] == 1:
        return _band_kkt(Q, A, gamma, schur, qdd, lam)
    return _schur_solve(M, Q, A, gamma, schur, qdd, lam)


#: Status of :func:`_field_borrowed` when the state needs :func:`_field_fallback`.
FALLBACK = -1


@njit_borrowing(cache=True, inline="always")
def field(kind, method, parameters, q, qd, t, u, ints, reals, buffer, mass, row_scale, qdd, lam, K, rhs,
          check_rank, schur):
    """q̈ and λ at (q, q̇, t, u) into ``qdd``, ``lam``; returns a status code.

    ``parameters`` = (ξ, ω, singularity tolerance or SVD threshold, mass-regularisation scale s,
    semi-definite flag); ``mass`` is the constant M (natural) or unused (joint: M from buffer);
    ``K`` (n+m, n+m) and ``rhs`` (n+m,) are workspace, ``schur`` that of :func:`schur_workspace`.
    Lagrange/Baumgarte check the rank of A when ``check_rank`` (:func:`_certify`); when A
    is certified well away from singular and M is positive definite they solve by the Schur
    complement (:func:`_schur_solve`: O(nm²) with M's constant factor, against O((n+m)³) for the
    full system), else the full system by Gaussian elimination with partial pivoting.
    Projection takes the same Schur path where A is certified regular (the solutions coincide
    there: :func:`_projection_by_schur`), else the SVD (:func:`_projection_by_svd`).  A state
    whose terms are not finite returns NON_FINITE before any factorisation.

    The common case runs without reference counting (:func:`_field_borrowed`); the SVD and the
    eigenvalues of a Gram matrix over 12 rows, which create arrays, run in
    :func:`_field_fallback`.
    """
    status = _field_borrowed(kind, method, parameters, q, qd, t, u, ints, reals, buffer, mass, row_scale, qdd, lam,
                             K, rhs, check_rank, schur)
    if status == FALLBACK:
        status = _field_fallback(kind, method, parameters, qd, buffer, mass, row_scale, qdd, lam, K, rhs,
                                 check_rank, schur)
    return status


@njit_borrowing(cache=True, inline="always")
def _terms(kind, n, m, buffer, mass):
    """Views (Q, Φ, A, γ, Φ_t, M) of the terms a kernel wrote into ``buffer``."""
    Q = buffer[:n]
    phi = buffer[n:n + m]
    A = buffer[n + m:n + m + m * n].reshape((m, n))
    gamma = buffer[n + m + m * n:n + 2 * m + m * n]
    phi_t = buffer[n + 2 * m + m * n:n + 3 * m + m * n]
    M = mass if kind == KIND_NATURAL else buffer[n + 3 * m + m * n:n + 3 * m + m * n + n * n].reshape((n, n))
    return Q, phi, A, gamma, phi_t, M


@njit_borrowing(cache=True)
def _field_borrowed(kind, method, parameters, q, qd, t, u, ints, reals, buffer, mass, row_scale, qdd, lam, K, rhs,
                    check_rank, schur):
    """:func:`field` up to the paths that create arrays: returns FALLBACK there, with the terms
    evaluated in ``buffer`` (and, for Lagrange and Baumgarte, the Gram matrix G = (SA)(SA)ᵀ of
    the fresh bounds in schur[7])."""
    return _field_stage(kind, True, method, parameters, q, qd, t, u, ints, reals, buffer, mass, row_scale, qdd, lam,
                        K, rhs, check_rank, schur)


@njit_borrowing(cache=True)
def _field_small_natural(method, parameters, q, qd, t, u, ints, reals, buffer, mass, row_scale, qdd, lam, K, rhs,
                         check_rank, schur):
    """:func:`_field_borrowed` for a natural-coordinate model that is not solved by band LU
    (schur[16] != 1): the same operations, compiled without the joint kernel and the band
    solve, so the loop that calls it (:func:`_rk4_steps_small_natural`) is about 30 %
    smaller to load (419 KB of bitcode instead of 580 KB)."""
    return _field_stage(KIND_NATURAL, False, method, parameters, q, qd, t, u, ints, reals, buffer, mass, row_scale,
                        qdd, lam, K, rhs, check_rank, schur)


@njit_borrowing(cache=True, inline="always")
def _field_stage(kind, band, method, parameters, q, qd, t, u, ints, reals, buffer, mass, row_scale, qdd, lam, K, rhs,
                 check_rank, schur):
    """The body of :func:`_field_borrowed`; ``band`` False leaves out the band solve (the caller
    knows schur[16] != 1)."""
    n = q.shape[0]
    m = lam.shape[0]
    _evaluate(kind, q, qd, t, u, ints, reals, buffer)
    Q, phi, A, gamma, phi_t, M = _terms(kind, n, m, buffer, mass)
    for k in range(n + 3 * m + m * n if kind == KIND_NATURAL else n + 3 * m + m * n + n * n):
        if not math.isfinite(buffer[k]):    # a state that has blown up: no factorisation sees it
            return NON_FINITE
    if method == PROJECTION:
        if not _projection_by_schur(band, M, Q, A, gamma, row_scale, parameters[2], schur, qdd, lam):
            return FALLBACK
    else:
        singular, certified, decided = _certify(A, row_scale, parameters[2], schur[27], schur[28], schur[7],
                                                schur[8], schur[13], schur[14], schur[15])
        if not decided:
            return FALLBACK
        if check_rank and singular:
            return SINGULAR
        if not _constrained_solve(band, method, parameters, qd, Q, phi, A, gamma, phi_t, M, K, rhs, certified, schur,
                                  qdd, lam):
            return SINGULAR
    return _finite(qdd)


@njit(cache=True)
def _field_fallback(kind, method, parameters, qd, buffer, mass, row_scale, qdd, lam, K, rhs, check_rank, schur):
    """The rest of :func:`field` where :func:`_field_borrowed` returned FALLBACK: the projection's
    SVD, or (Lagrange and Baumgarte, more than 12 constraints, fresh bounds inconclusive) the rank
    test of A by the eigenvalues of the Gram matrix those bounds left in schur[7], then the band
    or full system."""
    n = qd.shape[0]
    m = lam.shape[0]
    Q, phi, A, gamma, phi_t, M = _terms(kind, n, m, buffer, mass)
    if method == PROJECTION:
        if not _projection_by_svd(M, Q, A, gamma, row_scale, parameters, qdd, lam):
            return SINGULAR
        return _finite(qdd)
    if check_rank and _gram_singular(schur[7], parameters[2]):
        return SINGULAR
    if not _constrained_solve(True, method, parameters, qd, Q, phi, A, gamma, phi_t, M, K, rhs, False, schur, qdd,
                              lam):
        return SINGULAR
    return _finite(qdd)


@njit_borrowing(cache=True, inline="always")
def _finite(qdd):
    """OK when every q̈ is finite, else NON_FINITE."""
    for k in range(qdd.shape[0]):
        if not math.isfinite(qdd[k]):
            return NON_FINITE
    return OK


@njit_borrowing(cache=True, inline="always")
def _constrained_solve(band, method, parameters, qd, Q, phi, A, gamma, phi_t, M, K, rhs, certified, schur, qdd, lam):
    """q̈, λ of Lagrange's or Baumgarte's [M Aᵀ; A 0][q̈; λ] = [Q; c], c = γ (Lagrange) or
    γ - 2ξωΦ̇ - ω²Φ with Φ̇ = Aq̇ + Φ_t (Baumgarte): band LU for large natural models (when
    ``band``), the Schur complement when A is ``certified`` regular, else the full system.
    False when singular."""
    n = Q.shape[0]
    m = gamma.shape[0]
    for r in range(m):
        value = gamma[r]
        if method == BAUMGARTE:
            rate = phi_t[r]
            for j in range(n):
                rate += A[r, j] * qd[j]
            value -= 2.0 * parameters[0] * parameters[1] * rate + parameters[1] * parameters[1] * phi[r]
        rhs[n + r] = value
    if band and schur[16] == 1:             # large natural model: band LU of the KKT matrix
        return _band_kkt(Q, A, rhs[n:n + m], schur, qdd, lam)
    if certified and _schur_solve(M, Q, A, rhs[n:n + m], schur, qdd, lam):
        return True
    return _full_system(M, Q, A, K, rhs, qdd, lam)


@njit_borrowing(cache=True)
def _full_system(M, Q, A, K, rhs, qdd, lam):
    """q̈, λ of the augmented system [M Aᵀ; A 0][q̈; λ] = [Q; c] (c given in ``rhs[n:]``) by
    Gaussian elimination with partial pivoting (:func:`_solve_in_place`): the path of
    :func:`field` when the Schur complement cannot be used.  Returns False when singular."""
    n, m = qdd.shape[0], lam.shape[0]
    for i in range(n):
        for j in range(n):
            K[i, j] = M[i, j]
        rhs[i] = Q[i]
    for r in range(m):
        for j in range(n):
            K[n + r, j] = A[r, j]
            K[j, n + r] = A[r, j]
        for j in range(m):
            K[n + r, n + j] = 0.0
    if not _solve_in_place(K, rhs):
        return False
    for i in range(n):
        qdd[i] = rhs[i]
    for r in range(m):
        lam[r] = rhs[n + r]
    return True


@njit(cache=True)
def _projection_by_svd(M, Q, A, gamma, row_scale, parameters, qdd, lam):
    """Aghili's standard projection solution with the SVD pseudo-inverse of the row-scaled A,
    singular values up to the threshold ``parameters[2]`` discarded (any rank of A); M̂ = M + s(I - P)
    when ``parameters[4]`` flags a semi-definite M (s = ``parameters[3]``).  Returns False when
    the constraint inertia matrix is exactly singular."""
    n = M.shape[0]
    m = A.shape[0]
    pinv = np.zeros((n, m))
    P = np.eye(n)
    if m > 0:
        scaled = A * row_scale.reshape((m, 1))
        U, sigma, Vt = np.linalg.svd(scaled, full_matrices=False)
        for k in range(sigma.shape[0]):
            if sigma[k] > parameters[2]:
                v = Vt[k]
                P -= np.outer(v, v)
                pinv += np.outer(v / sigma[k], U[:, k] * row_scale)
    I_P = np.eye(n) - P
    M_hat = M + parameters[3] * I_P if parameters[4] > 0.0 else M.copy()
    matrix = M_hat + P @ M - M_hat @ P
    solution = P @ Q + M_hat @ (pinv @ gamma)
    if not _solve_in_place(matrix, solution):
        return False
    qdd[:] = solution
    force = I_P @ (M @ qdd - Q)
    lam[:] = -(pinv.T @ force)
    return True


@njit_borrowing(cache=True)
def _lu_in_place(K, pivots):
    """LU factorisation with partial pivoting of the square ``K`` in place (unit lower factor
    below the diagonal); row swaps in ``pivots``.  Returns False for an exactly singular matrix."""
    size = K.shape[0]
    for column in range(size):
        pivot = column
        largest = abs(K[column, column])
        for row in range(column + 1, size):
            if abs(K[row, column]) > largest:
                largest = abs(K[row, column])
                pivot = row
        pivots[column] = pivot
        if largest == 0.0:
            return False
        if pivot != column:
            for k in range(size):
                K[column, k], K[pivot, k] = K[pivot, k], K[column, k]
        for row in range(column + 1, size):
            factor = K[row, column] / K[column, column]
            K[row, column] = factor
            if factor != 0.0:
                for k in range(column + 1, size):
                    K[row, k] -= factor * K[column, k]
    return True


@njit_borrowing(cache=True)
def _lu_solve(K, pivots, b):
    """Solve K x = b in place with the factors of :func:`_lu_in_place`."""
    size = K.shape[0]
    for i in range(size):
        if pivots[i] != i:
            b[i], b[pivots[i]] = b[pivots[i]], b[i]
    for i in range(size):
        for k in range(i):
            b[i] -= K[i, k] * b[k]
    for i in range(size - 1, -1, -1):
        for k in range(i + 1, size):
            b[i] -= K[i, k] * b[k]
        b[i] /= K[i, i]


@njit_borrowing(cache=True)
def _lu_solve_transposed(K, pivots, b):
    """Solve Kᵀ x = b in place with the factors of :func:`_lu_in_place` (K = Pᵀ L U)."""
    size = K.shape[0]
    for i in range(size):                   # Uᵀ y = b
        for k in range(i):
            b[i] -= K[k, i] * b[k]
        b[i] /= K[i, i]
    for i in range(size - 1, -1, -1):       # Lᵀ w = y
        for k in range(i + 1, size):
            b[i] -= K[k, i] * b[k]
    for i in range(size - 1, -1, -1):       # x = Pᵀ w
        if pivots[i] != i:
            b[i], b[pivots[i]] = b[pivots[i]], b[i]


@njit_borrowing(cache=True)
def computed_torque(law, q, qd, t, K, rhs, pivots, u):
    """The inputs of :class:`~cmbs.control.ComputedTorque` at (q, q̇, t) into ``u``; NaN when its
    linear system is singular (the Python law raises there).

    The law (thesis ch. 6) is τ_z = Rᵀ(M(R z̈_c + S) - Q₀), u = G τ_z, with M, Q₀ (Q at u = 0),
    A, γ of the law's model, G its inverse actuator gains, and::

        z̈_c = z̈_ref + K_d (ż_ref - ż) + K_p (z_ref - z)

    where z_ref, ż_ref, z̈_ref come from the reference's cubic spline at t clamped to the spline's
    span (as :meth:`~cmbs.control.Reference.__call__`).  With the partition's r constraint rows
    A_r = [A_d A_z] split into its dependent (d) and independent (z) columns (r = n - k, A_d
    invertible), R = [-A_d⁻¹A_z; I] and S = [A_d⁻¹γ_r; 0] (THEORY §5), so one LU factorisation
    of A_d gives everything::

        q̈_z = z̈_c,   q̈_d = A_d⁻¹(γ_r - A_z z̈_c),   f = M q̈ - Q₀,
        τ_z = f_z + R_dᵀ f_d = f_z - A_zᵀ A_d⁻ᵀ f_d

    ``law`` is the tuple of :func:`law_arrays`; ``K`` (at least r x r), ``rhs`` (at least
    n + r) and ``pivots`` (at least r integers) are workspace.
    """
    kind, ints, reals, buffer, mass, m, no_input, columns, rows, kp, kd, breaks, coefficients, gains, dependent = law
    n = q.shape[0]
    r = rows.shape[0]
    k = columns.shape[0]
    _evaluate(kind, q, qd, t, no_input, ints, reals, buffer)
    A = buffer[n + m:n + m + m * n].reshape((m, n))
    gamma = buffer[n + m + m * n:n + 2 * m + m * n]
    M = mass if kind == KIND_NATURAL else buffer[n + 3 * m + m * n:n + 3 * m + m * n + n * n].reshape((n, n))
    qdd = rhs[:n]
    side = rhs[n:n + r]
    clamped = min(max(t, breaks[0]), breaks[breaks.shape[0] - 1])
    for b in range(k):
        reference = evaluate_piecewise(breaks, coefficients[b], clamped)
        c = columns[b]
        qdd[c] = reference[2] + kd[b] * (reference[1] - qd[c]) + kp[b] * (reference[0] - q[c])
    Ad = K[:r, :r]
    for a in range(r):
        row = rows[a]
        total = gamma[row]
        for b in range(k):
            total -= A[row, columns[b]] * qdd[columns[b]]
        side[a] = total
        for j in range(r):
            Ad[a, j] = A[row, dependent[j]]
    if not _lu_in_place(Ad, pivots):
        u[:] = np.nan
        return
    _lu_solve(Ad, pivots, side)
    for j in range(r):
        qdd[dependent[j]] = side[j]
    for j in range(r):                      # f_d into side
        c = dependent[j]
        total = -buffer[c]
        for i in range(n):
            total += M[c, i] * qdd[i]
        side[j] = total
    _lu_solve_transposed(Ad, pivots, side)  # A_d⁻ᵀ f_d
    for i in range(u.shape[0]):
        u[i] = 0.0
    for b in range(k):
        c = columns[b]
        force = -buffer[c]
        for i in range(n):
            force += M[c, i] * qdd[i]
        for a in range(r):
            force -= A[rows[a], c] * side[a]
        for i in range(u.shape[0]):
            u[i] += gains[i, b] * force


@njit_borrowing(cache=True)
def record_constraints(buffer, n, m, qd, lam, PHI, PHID, FORCE, k):
    """Row ``k`` of a loop's records from the terms in ``buffer`` (at the state with velocities
    ``qd``) and the multipliers ``lam``: max |Φ|, max |A q̇ + Φ_t| and f_c = -Aᵀλ."""
    A = buffer[n + m:n + m + m * n].reshape((m, n))
    largest, rate_largest = 0.0, 0.0
    for a in range(m):
        largest = max(largest, abs(buffer[n + a]))
        rate = buffer[n + 2 * m + m * n + a]
        for j in range(n):
            rate += A[a, j] * qd[j]
        rate_largest = max(rate_largest, abs(rate))
    PHI[k], PHID[k] = largest, rate_largest
    for j in range(n):
        total = 0.0
        for a in range(m):
            total -= A[a, j] * lam[a]
        FORCE[k, j] = total


@njit(cache=True)
def _private_copy(schur):
    """The :func:`schur_workspace` tuple with fresh copies of its scratch arrays (the constant
    M_pp⁻¹, its flag and the index arrays are shared), so that loops running at the same time
    (:func:`rk4_batch`) do not write into each other's workspace."""
    return (schur[0].copy() if schur[1] == 0 else schur[0], schur[1], schur[2].copy(), schur[3].copy(),
            schur[4].copy(), schur[5].copy(), schur[6].copy(), schur[7].copy(), schur[8].copy(), schur[9],
            schur[10], schur[11].copy(), schur[12], schur[13].copy(), schur[14], schur[15].copy(), schur[16],
            schur[17], schur[18].copy(), schur[19].copy(), schur[20].copy(), schur[21], schur[22], schur[23],
            schur[24], schur[25], schur[26], schur[27].copy(), schur[28].copy())


@njit(cache=True, parallel=True)
def rk4_batch(kind, method, parameters, Q0, QD0, U0, h, steps, every, ints, reals, buffer_size, mass, row_scale, m,
              law, schur, Qs, QDs, PHIs, statuses, recorded):
    """:func:`rk4` with constant inputs for N variants of the initial state and the inputs (rows
    of Q0, QD0, U0), in parallel over the variants (numba threads).  Writes each variant's
    recorded q, q̇ and |Φ|max into Qs (N, records, n), QDs and PHIs (N, records), its status
    and the number of records it reached."""
    for v in prange(Q0.shape[0]):
        state, records, work = _rk4_arrays(Q0[v], QD0[v], U0[v], m, steps // every + 1, buffer_size,
                                           law[8].shape[0])
        q, qd, u, sq, sv = state
        count, status, _, _, _ = _rk4_steps(kind, method, parameters, h, steps, every, ints, reals, mass, row_scale,
                                            CONSTANT, law, _private_copy(schur), q, qd, u, sq, sv, work, records, 0, 0,
                                            0)
        Qs[v, :count] = records[1][:count]
        QDs[v, :count] = records[2][:count]
        PHIs[v, :count] = records[6][:count]
        statuses[v] = status
        recorded[v] = count


@njit_borrowing(cache=True, inline="always")
def _stage_state(q, qd, a, kq, kv, sq, sv):
    """The RK stage state (sq, sv) = (q + a k_q, q̇ + a k_v)."""
    for i in range(q.shape[0]):
        sq[i] = q[i] + a * kq[i]
        sv[i] = qd[i] + a * kv[i]


@njit(cache=True)
def _rk4_arrays(q0, qd0, u0, m, records, buffer_size, r):
    """The arrays of an RK4 run from (q0, q̇0) with inputs u0: its state (q, q̇, u, copies; the
    stage state), its records (t, q, q̇, q̈, λ, u, |Φ|max, |Φ̇|max, f_c) and its workspace (terms
    buffer, the stages' slopes of q and q̇, λ at the step and at a stage, the KKT system, the
    computed-torque law's system of ``r`` constraint rows and its pivots).  Plain numpy: the
    Python driver :func:`rk4` calls it interpreted, which loads no compiled code; :func:`rk4_batch`
    compiled, once per variant."""
    n, n_u = q0.shape[0], u0.shape[0]
    state = (q0.copy(), qd0.copy(), u0.copy(), np.empty(n), np.empty(n))
    records = (np.zeros(records), np.zeros((records, n)), np.zeros((records, n)), np.zeros((records, n)),
               np.zeros((records, m)), np.zeros((records, n_u)), np.zeros(records), np.zeros(records),
               np.zeros((records, n)))
    work = (np.zeros(buffer_size), np.empty((4, n)), np.empty((4, n)), np.empty(m), np.empty(m),
            np.empty((n + m, n + m)), np.empty(n + m), np.empty((r, r)), np.empty(n + r), np.empty(r, dtype=np.int64))
    return state, records, work


def rk4(kind: int, method: int, parameters: np.ndarray, q0: np.ndarray, qd0: np.ndarray, h: float, steps: int,
        every: int, u0: np.ndarray, ints: np.ndarray, reals: np.ndarray, buffer_size: int, mass: np.ndarray,
        row_scale: np.ndarray, m: int, mode: int, law: tuple, schur: tuple) -> tuple:
    """Fixed-step RK4 for ``steps`` steps of size ``h`` from t = 0; records (t, q, q̇, q̈, λ, u,
    |Φ|max, |Φ̇|max, f_c = -Aᵀλ) every ``every`` steps (only those are stored).  Returns the records, the
    number recorded and a status code with the time, the steps completed, the state and inputs
    it refers to (for a failed run: where the formulation could not go on).

    The inputs (``mode``): CONSTANT keeps ``u0``; LAW evaluates :func:`computed_torque` (``law``
    from :func:`law_arrays`) at every stage; HELD reproduces :class:`~cmbs.control.ZeroOrderHold`
    with period h on the Python loop: the law is sampled at t = 0 and at every step's last stage
    (at t_n + h, which is the next sample instant, with that stage's state y_n + h k₃: the hold
    cannot tell that stage from the next step's start), and the value is held through the next
    step's first three stages.  The recorded u at t_n is the input applied from t_n on (the
    held value, as the hold returns it when :func:`cmbs.simulate` records the run), with q̈, λ
    evaluated with it.

    The loop runs first without the paths that create arrays (:func:`_rk4_steps_borrowed`, whose
    compiled code is about half the size, so a process loads it in half the time; for a natural
    model with constant inputs and no band solve, :func:`_rk4_steps_small_natural`, smaller
    still); at the first stage that needs the SVD or the eigenvalue rank test it goes on from
    that stage in :func:`_rk4_steps`, which has them: the same stages, the same results.
    """
    state, records, work = interpreted(_rk4_arrays)(q0, qd0, u0, m, steps // every + 1, buffer_size,
                                                    law[8].shape[0])
    q, qd, u, sq, sv = state
    arguments = (kind, method, parameters, h, steps, every, ints, reals, mass, row_scale, mode, law,
                 interpreted(_private_copy)(schur), q, qd, u, sq, sv, work, records)
    small_natural = kind == KIND_NATURAL and mode == CONSTANT and schur[16] != 1
    first = _rk4_steps_small_natural if small_natural else _rk4_steps_borrowed
    recorded, status, st, step, stage = first(*arguments, 0, 0, 0)
    if status == FALLBACK:
        recorded, status, st, step, _ = _rk4_steps(*arguments, step, stage, recorded)
    if status != OK:
        return *records, recorded, status, st, step, sq, sv, u
    return *records, recorded, OK, steps * h, steps, q, qd, u


@njit_borrowing(cache=True)
def _rk4_steps_borrowed(kind, method, parameters, h, steps, every, ints, reals, mass, row_scale, mode, law, schur, q,
                        qd, u, sq, sv, work, records, start_step, start_stage, recorded):
    """:func:`_rk4_loop` with :func:`_field_borrowed`: stops with FALLBACK at the first stage that
    needs :func:`_field_fallback`."""
    return _rk4_loop(BORROWED, kind, method, parameters, h, steps, every, ints, reals, mass, row_scale, mode, law,
                     schur, q, qd, u, sq, sv, work, records, start_step, start_stage, recorded)


@njit_borrowing(cache=True)
def _rk4_steps_small_natural(kind, method, parameters, h, steps, every, ints, reals, mass, row_scale, mode, law, schur,
                             q, qd, u, sq, sv, work, records, start_step, start_stage, recorded):
    """:func:`_rk4_steps_borrowed` for a natural model with constant inputs that is not solved by
    band LU (:func:`_field_small_natural`; ``kind`` and ``mode`` are not read)."""
    return _rk4_loop(SMALL_NATURAL, kind, method, parameters, h, steps, every, ints, reals, mass, row_scale, mode, law,
                     schur, q, qd, u, sq, sv, work, records, start_step, start_stage, recorded)


@njit_borrowing(cache=True)
def _rk4_steps(kind, method, parameters, h, steps, every, ints, reals, mass, row_scale, mode, law, schur, q, qd, u,
               sq, sv, work, records, start_step, start_stage, recorded):
    """:func:`_rk4_loop` with the whole :func:`field`."""
    return _rk4_loop(WHOLE, kind, method, parameters, h, steps, every, ints, reals, mass, row_scale, mode, law, schur,
                     q, qd, u, sq, sv, work, records, start_step, start_stage, recorded)


#: The field a compiled RK4 loop calls (:func:`_rk4_loop`).
WHOLE, BORROWED, SMALL_NATURAL = 0, 1, 2


@njit_borrowing(cache=True, inline="always")
def _rk4_loop(variant, kind, method, parameters, h, steps, every, ints, reals, mass, row_scale, mode, law,
              schur, q, qd, u, sq, sv, work, records, start_step, start_stage, recorded):
    """The loop of :func:`rk4` on the arrays :func:`_rk4_arrays` allocated (state q, q̇, u
    updated in place; stage state sq, sv; ``work``), from stage ``start_stage`` of step
    ``start_step`` with ``recorded`` records written (the earlier stages of that step left their
    slopes and λ in ``work``).  The stages call :func:`field` (``variant`` WHOLE),
    :func:`_field_borrowed` (BORROWED) or :func:`_field_small_natural` (SMALL_NATURAL, which
    also leaves out the input law); the callers pass a constant, so the compiled loop keeps only
    that call.  Returns (records written, status, time, step and stage of the failed stage).
    Borrowing: no reference counting in the loop."""
    n = q.shape[0]
    buffer, kq, kv, lam, stage_lam, K, rhs, law_K, law_rhs, law_pivots = work
    T, Qs, QDs, QDDs, LAMs, Us, PHI, PHID, FORCE = records
    for step in range(start_step, steps + 1):
        t = step * h
        st = t
        for stage in range(start_stage if step == start_step else 0, 4):  # one call site of the field
            if stage == 0:
                for i in range(n):
                    sq[i] = q[i]
                    sv[i] = qd[i]
            else:
                a = h if stage == 3 else 0.5 * h
                _stage_state(q, qd, a, kq[stage - 1], kv[stage - 1], sq, sv)
                st = t + a
            for i in range(n):
                kq[stage, i] = sv[i]
            sampled = mode == LAW or (mode == HELD and (step == 0 if stage == 0 else stage == 3))
            if variant != SMALL_NATURAL and sampled:
                computed_torque(law, sq, sv, st, law_K, law_rhs, law_pivots, u)
            if variant == WHOLE:
                status = field(kind, method, parameters, sq, sv, st, u, ints, reals, buffer, mass, row_scale,
                               kv[stage], lam if stage == 0 else stage_lam, K, rhs, True, schur)
            elif variant == SMALL_NATURAL:
                status = _field_small_natural(method, parameters, sq, sv, st, u, ints, reals, buffer, mass, row_scale,
                                              kv[stage], lam if stage == 0 else stage_lam, K, rhs, True, schur)
            else:
                status = _field_borrowed(kind, method, parameters, sq, sv, st, u, ints, reals, buffer, mass,
                                         row_scale, kv[stage], lam if stage == 0 else stage_lam, K, rhs, True, schur)
            if status != OK:
                return recorded, status, st, step, stage
            if stage == 0:
                if step % every == 0:
                    T[recorded] = t
                    for i in range(n):
                        Qs[recorded, i] = q[i]
                        QDs[recorded, i] = qd[i]
                        QDDs[recorded, i] = kv[0, i]
                    for i in range(lam.shape[0]):
                        LAMs[recorded, i] = lam[i]
                    for i in range(u.shape[0]):
                        Us[recorded, i] = u[i]
                    record_constraints(buffer, n, lam.shape[0], qd, lam, PHI, PHID, FORCE, recorded)
                    recorded += 1
                if step == steps:
                    break
        if step == steps:
            break
        for i in range(n):                  # in place: the loop allocates nothing per step
            q[i] += (h / 6.0) * (kq[0, i] + 2.0 * kq[1, i] + 2.0 * kq[2, i] + kq[3, i])
            qd[i] += (h / 6.0) * (kv[0, i] + 2.0 * kv[1, i] + 2.0 * kv[2, i] + kv[3, i])
    return recorded, OK, steps * h, steps, 0
