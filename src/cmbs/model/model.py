"""The one mathematical model interface every formulation, integrator and controller sees.

For coordinates ``q`` (size n), constraints (size m) and actuator inputs ``u`` (size n_u), a
:class:`Model` evaluates (THEORY §1, García de Jalón & Bayo's convention)::

    M(q) q̈ + Aᵀ λ = Q(q, q̇, t, u),     Φ(q, t) = 0,     A = Φ_q,
    A q̇ = -Φ_t,                        A q̈ = γ = -(Ȧ q̇) - 2 Φ_qt q̇ - Φ_tt.

Nonholonomic (velocity-level) constraint rows ``B_k(q, t) q̇ + b_k(q, t) = 0`` (THEORY §1, §3.6;
:attr:`Model.nonholonomic` marks them) use the same arrays with ``A[k] = B_k``, ``Φ[k] = 0``
(there is no position-level constraint), ``Φ_t[k] = b_k`` and ``γ[k] = -(dB_k/dt) q̇ - ḃ_k``, so
that ``A q̇ + Φ_t = 0`` and ``A q̈ = γ`` hold for every row; every formulation works on those
unchanged, while position-level operations (assembly, coordinate projection, the configuration
DOF) use the holonomic rows only.

Pinocchio's split between a constant model and per-evaluation data is kept: the frozen
:class:`Model` holds names, sizes and the compiled evaluator; :class:`Terms` is a caller-owned
workspace that :meth:`Model.evaluate` fills in place (the fast path, no allocation).  The
convenience methods (:meth:`Model.mass_matrix`, :meth:`Model.jacobian`, ...) return fresh
arrays.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Protocol, Sequence

import numpy as np

from cmbs.errors import ModelError, did_you_mean
from cmbs.model.read_only import make_read_only, read_only_paths


class Terms:
    """Workspace with the terms of the equations of motion at one state.

    Attributes (views into one buffer, overwritten by every :meth:`Model.evaluate`):
    ``M`` (n, n), ``Q`` (n,), ``phi`` (m,), ``A`` (m, n), ``gamma`` (m,), ``phi_t`` (m,).
    For models with a constant mass matrix ``M`` is the model's read-only matrix itself.

    A nonholonomic row k (``B_k q̇ + b_k = 0``, see :attr:`Model.nonholonomic`) holds
    ``A[k] = B_k``, ``phi[k] = 0``, ``phi_t[k] = b_k`` and ``gamma[k] = -(dB_k/dt) q̇ - ḃ_k``:
    the velocity constraint is ``A q̇ + Φ_t = 0`` and the acceleration constraint ``A q̈ = γ``
    for holonomic and nonholonomic rows alike.
    """

    __slots__ = ("buffer", "M", "Q", "phi", "A", "gamma", "phi_t", "scratch")

    def __init__(self, n: int, m: int, *, constant_mass: np.ndarray | None = None, scratch: int = 0):
        size = n + m * (n + 3) + (0 if constant_mass is not None else n * n) + scratch
        self.buffer = np.zeros(size)
        offset = 0

        def take(count: int) -> np.ndarray:
            nonlocal offset
            view = self.buffer[offset:offset + count]
            offset += count
            return view

        self.Q = take(n)
        self.phi = take(m)
        self.A = take(m * n).reshape(m, n)
        self.gamma = take(m)
        self.phi_t = take(m)
        self.M = constant_mass if constant_mass is not None else take(n * n).reshape(n, n)
        self.scratch = take(scratch)


def assign_terms(target: "Terms", source: "Terms", rows: np.ndarray | slice = slice(None)) -> None:
    """Copy Q, M and the constraint rows ``rows`` of ``source`` into ``target``."""
    target.Q[:] = source.Q
    target.phi[:] = source.phi[rows]
    target.A[:] = source.A[rows]
    target.gamma[:] = source.gamma[rows]
    target.phi_t[:] = source.phi_t[rows]
    if target.M is not source.M:
        target.M[:] = source.M


def base_equations(model: "Model") -> tuple[object, np.ndarray]:
    """The equations a model's wrappers (drivers removed or prescribed, faults) are built on,
    and for each model row its row there (-1: a row the base equations do not have).  A wrapper
    has ``inner`` and, when it changes the rows, ``row_origin`` (its row k is inner row
    ``row_origin[k]``, -1 for a row of its own)."""
    equations = model.equations
    rows = np.arange(model.m)
    while hasattr(equations, "inner"):
        origin = getattr(equations, "row_origin", None)
        if origin is not None:
            mapped, kept = np.full(rows.shape, -1), rows >= 0
            mapped[kept] = np.asarray(origin)[rows[kept]]
            rows = mapped
        equations = equations.inner
    return equations, rows


def base_multipliers(lam: np.ndarray, rows: np.ndarray, size: int) -> np.ndarray:
    """Multipliers of the base equations' ``size`` rows from a model's ``lam`` and its
    :func:`base_equations` rows (zero for base rows the model does not have)."""
    base = np.zeros(size)
    base[rows[rows >= 0]] = lam[rows >= 0]
    return base


class ModelEquations(Protocol):
    """What a model builder provides (natural coordinates, joint coordinates, user equations)."""

    def new_terms(self) -> Terms:
        """A workspace sized for this model."""

    def evaluate(self, q: np.ndarray, qd: np.ndarray, t: float, u: np.ndarray, terms: Terms) -> None:
        """Fill ``terms`` with M, Q, Φ, A, γ, Φ_t at the state."""

    def kinetic_energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        """T = ½ q̇ᵀ M(q) q̇."""

    def potential_energy(self, q: np.ndarray) -> float:
        """V(q) of gravity and springs (the conservative part of Q)."""

    def point_positions(self, q: np.ndarray) -> np.ndarray:
        """(n_points, 2) positions (x, z) of the model's named points."""

    # Optional: ``work_sources``, a tuple naming the elements other than gravity, springs,
    # constraints and actuators whose forces do work (dampers, applied forces and torques): ()
    # when there are none, so that T + V is conserved without drivers and inputs.  Equations
    # without it (from_callables, wrappers that change the forces) are not known to conserve it.
    # Optional too: ``steady_drivers``, the names of the driver rows with Φ_t = 0 (a constant),
    # which do no work.


@dataclass(frozen=True)
class Model:
    """A constrained multibody model: names, sizes and the evaluators of its equations.

    Parameters
    ----------
    name, description, source
        Identification; ``source`` cites where the mechanism and its parameters come from.
    coordinate_names
        Names of the n coordinates, e.g. ``("B.x", "B.z", "C.x", "C.z", "alpha")``.
    coordinate_kinds
        One of ``"x"``, ``"y"``, ``"z"``, ``"angle"``, ``"distance"``, ``"direction"`` (a component
        of a spatial unit vector), ``"joint"``, ``"generic"`` each.
    constraint_names
        Names of the m constraints (rows of Φ, or of A q̇ + Φ_t = 0 for nonholonomic rows).
    drivers
        Boolean mask (m,) of rheonomic driver constraints.
    nonholonomic
        Boolean mask (m,) of nonholonomic (velocity-level) constraint rows
        ``B_k(q, t) q̇ + b_k(q, t) = 0``; None (default) means all False.  Such a row has
        ``A[k] = B_k``, ``Φ[k] = 0``, ``Φ_t[k] = b_k``, ``γ[k] = -(dB_k/dt) q̇ - ḃ_k`` (see
        :class:`Terms`); assembly and coordinate projection skip it, velocity and acceleration
        analysis and the formulations use it like any other row.
    actuator_names
        Names of the n_u actuator inputs ``u``.
    q0
        Initial (approximate) coordinates, to be assembled by :func:`cmbs.kinematics.assemble`.
    qd0
        Initial velocities (approximate; velocity analysis makes them consistent).
    point_names, lines
        Names of drawable points and (i, j) index pairs of segments between them.
    equations
        The evaluator, see :class:`ModelEquations`.
    parameters
        Builder parameters (for provenance and ``replace``).
    constant_mass
        True when M does not depend on q (natural coordinates).
    coordinate_limits
        (lower, upper), each (n,) with ∓inf where unlimited, or None: bounds that position
        analysis keeps the coordinates within (:func:`cmbs.kinematics.assemble`; a robot's joint
        limits when it asks for them).  The dynamics does not enforce them.
    """

    name: str
    coordinate_names: tuple[str, ...]
    coordinate_kinds: tuple[str, ...]
    constraint_names: tuple[str, ...]
    drivers: np.ndarray
    actuator_names: tuple[str, ...]
    q0: np.ndarray
    qd0: np.ndarray
    point_names: tuple[str, ...]
    lines: tuple[tuple[int, int], ...]
    equations: ModelEquations = field(repr=False)
    description: str = ""
    source: str = ""
    parameters: dict = field(default_factory=dict, repr=False)
    constant_mass: bool = False
    segment_masses: tuple[tuple[str, float], ...] = ()
    nonholonomic: np.ndarray | None = None
    coordinate_limits: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)
    _no_input: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        n = len(self.coordinate_names)
        if len(set(self.coordinate_names)) != n:
            raise ModelError(f"model {self.name!r}: duplicate coordinate names")
        for label, array in (("q0", self.q0), ("qd0", self.qd0)):
            if np.shape(array) != (n,):
                raise ModelError(f"model {self.name!r}: {label} has shape {np.shape(array)}, expected ({n},)")
        if np.shape(self.drivers) != (len(self.constraint_names),):
            raise ModelError(f"model {self.name!r}: driver mask does not match the constraints")
        if self.nonholonomic is None:
            object.__setattr__(self, "nonholonomic", np.zeros(len(self.constraint_names), dtype=bool))
        if np.shape(self.nonholonomic) != (len(self.constraint_names),):
            raise ModelError(f"model {self.name!r}: nonholonomic mask does not match the constraints")
        for label in ("q0", "qd0", "drivers", "nonholonomic"):
            frozen = np.array(getattr(self, label), dtype=bool if label in ("drivers", "nonholonomic") else float)
            frozen.setflags(write=False)
            object.__setattr__(self, label, frozen)
        if self.coordinate_limits is not None:
            lower, upper = (np.array(limit, dtype=float) for limit in self.coordinate_limits)
            if lower.shape != (n,) or upper.shape != (n,) or np.isnan(lower).any() or np.isnan(upper).any() \
                    or np.any(lower > upper):
                raise ModelError(f"model {self.name!r}: coordinate_limits must be two arrays ({n},) with lower <= "
                                 "upper")
            for limit in (lower, upper):
                limit.setflags(write=False)
            object.__setattr__(self, "coordinate_limits", (lower, upper))
        object.__setattr__(self, "_no_input", np.zeros(len(self.actuator_names)))

    # ---------------------------------------------------------------- pickling
    def __getstate__(self) -> tuple[dict, list]:
        """The attributes and the paths of the read-only arrays among them (numpy's pickle
        restores arrays writeable; :mod:`cmbs.model.read_only`)."""
        return dict(vars(self)), read_only_paths(vars(self))

    def __setstate__(self, state: tuple[dict, list]) -> None:
        attributes, read_only = state
        vars(self).update(attributes)
        make_read_only(vars(self), read_only)

    # ---------------------------------------------------------------- sizes and names
    @property
    def n(self) -> int:
        """Number of coordinates."""
        return len(self.coordinate_names)

    @property
    def m(self) -> int:
        """Number of constraints (including drivers)."""
        return len(self.constraint_names)

    @property
    def n_u(self) -> int:
        """Number of actuator inputs."""
        return len(self.actuator_names)

    @property
    def holonomic(self) -> np.ndarray:
        """Boolean mask (m,) of the position-level rows (``~nonholonomic``)."""
        return ~self.nonholonomic

    @property
    def driver_names(self) -> tuple[str, ...]:
        return tuple(name for name, is_driver in zip(self.constraint_names, self.drivers) if is_driver)

    @property
    def total_mass(self) -> float:
        return float(sum(mass for _, mass in self.segment_masses))

    def coordinate_index(self, name: str) -> int:
        """Index of coordinate ``name`` (raises :class:`ModelError` naming the choices)."""
        try:
            return self.coordinate_names.index(name)
        except ValueError:
            raise ModelError(f"model {self.name!r} has no coordinate {name!r}"
                             f"{did_you_mean(name, self.coordinate_names)}; "
                             f"coordinates: {', '.join(self.coordinate_names)}") from None

    def coordinate_indices(self, names: Sequence[str | int]) -> np.ndarray:
        return np.array([name if isinstance(name, (int, np.integer)) else self.coordinate_index(name)
                         for name in names], dtype=np.int64)

    def without_drivers(self) -> "Model":
        """The same mechanism with its driver constraints removed (e.g. to simulate a driven
        model's free motion, or to drive it by forces instead); q0, q̇0 are kept."""
        keep = np.flatnonzero(~self.drivers)
        return self.replace(name=f"{self.name}-undriven",
                            constraint_names=tuple(self.constraint_names[k] for k in keep),
                            drivers=np.zeros(keep.size, dtype=bool), nonholonomic=self.nonholonomic[keep],
                            equations=self.equations.without_drivers() if hasattr(self.equations, "without_drivers")
                            and np.array_equal(keep, np.arange(keep.size)) else _RowSubset(self.equations, keep))

    def replace(self, **changes: object) -> "Model":
        """A copy with some fields changed (the model itself is never mutated)."""
        return dataclasses.replace(self, **changes)

    # ---------------------------------------------------------------- evaluation
    def new_terms(self) -> Terms:
        """A workspace for :meth:`evaluate`."""
        return self.equations.new_terms()

    def evaluate(self, q: np.ndarray, qd: np.ndarray, t: float = 0.0, u: np.ndarray | None = None,
                 out: Terms | None = None) -> Terms:
        """M, Q, Φ, A, γ, Φ_t at (q, q̇, t, u), written into ``out`` (or a new :class:`Terms`).

        ``q`` and ``qd`` must be float64 arrays of size n; ``u`` of size n_u (zeros if None).
        Read-only ones (such as the model's own ``q0``) are copied first: compiled equations
        would otherwise compile, and load, a second kernel for them.
        """
        if not (q.flags.writeable and qd.flags.writeable):
            q, qd = _writable(q), _writable(qd)
        terms = out if out is not None else self.equations.new_terms()
        self.equations.evaluate(q, qd, t, self._no_input if u is None else u, terms)
        return terms

    def _at(self, q: np.ndarray, qd: np.ndarray | None, t: float, u: np.ndarray | None) -> Terms:
        qd = np.zeros(self.n) if qd is None else _writable(qd)
        return self.evaluate(_writable(q), qd, float(t), None if u is None else _writable(u))

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """M(q), (n, n)."""
        return np.array(self._at(q, None, 0.0, None).M)

    def forces(self, q: np.ndarray, qd: np.ndarray, t: float = 0.0, u: np.ndarray | None = None) -> np.ndarray:
        """Q(q, q̇, t, u), (n,): applied forces, gravity, springs, inputs, minus velocity terms."""
        return self._at(q, qd, t, u).Q.copy()

    def constraints(self, q: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Φ(q, t), (m,) (0 in nonholonomic rows)."""
        return self._at(q, None, t, None).phi.copy()

    def jacobian(self, q: np.ndarray, t: float = 0.0) -> np.ndarray:
        """A = Φ_q, (m, n)."""
        return self._at(q, None, t, None).A.copy()

    def gamma(self, q: np.ndarray, qd: np.ndarray, t: float = 0.0) -> np.ndarray:
        """γ with A q̈ = γ, (m,)."""
        return self._at(q, qd, t, None).gamma.copy()

    def constraints_t(self, q: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Φ_t, (m,) (b_k in nonholonomic rows B_k q̇ + b_k = 0)."""
        return self._at(q, None, t, None).phi_t.copy()

    def kinetic_energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        return float(self.equations.kinetic_energy(np.asarray(q, float), np.asarray(qd, float)))

    def potential_energy(self, q: np.ndarray) -> float:
        return float(self.equations.potential_energy(np.asarray(q, float)))

    def energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        """Total mechanical energy T + V."""
        return self.kinetic_energy(q, qd) + self.potential_energy(q)

    def time_function_problem(self, times: Sequence[float]) -> str:
        """The model's first function of time (driver, force, torque; by name, with its expression)
        whose value or derivatives are not finite at one of ``times``, as a sentence, else ""."""
        for equations in (self.equations, base_equations(self)[0]):
            pack = getattr(equations, "time_functions", None)
            if pack is not None:
                return pack.problem(times)
        return ""

    def energy_parts(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """T and V at every row of q, q̇ (k, n): vectorised when the base equations can (constant
        M, linear gravity potential: natural coordinates), else row by row."""
        q, qd = np.asarray(q, dtype=float).reshape(-1, self.n), np.asarray(qd, dtype=float).reshape(-1, self.n)
        base = base_equations(self)[0]      # wrappers keep the energies of their base equations
        if hasattr(base, "energy_parts"):
            return base.energy_parts(q, qd)
        return (np.array([self.kinetic_energy(qi, qdi) for qi, qdi in zip(q, qd)]),
                np.array([self.potential_energy(qi) for qi in q]))

    def energy_history(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """T + V at every row of q, q̇ (k, n) (:meth:`energy_parts`)."""
        kinetic, potential = self.energy_parts(q, qd)
        return kinetic + potential

    @property
    def work_sources(self) -> tuple[str, ...] | None:
        """What does work on the mechanism besides gravity, springs, actuators (which do work only
        with nonzero inputs) and workless constraints: its moving drivers (a driver of a constant
        holds its coordinate), dampers, applied forces and torques, by name.  () means T + V is
        conserved by the exact motion with zero inputs; None that the equations do not say (see
        :class:`ModelEquations`)."""
        sources = getattr(self.equations, "work_sources", None)
        if sources is None:
            return None
        steady = getattr(self.equations, "steady_drivers", frozenset())
        return tuple(f"driver {name!r}" for name in self.driver_names if name not in steady) + tuple(sources)

    def point_positions(self, q: np.ndarray) -> np.ndarray:
        """(n_points, 2) positions (x, z) of :attr:`point_names` in the plane, (n_points, 3) in
        space."""
        return self.equations.point_positions(np.asarray(q, dtype=float))


def _writable(values: object) -> np.ndarray:
    """``values`` as a float array that can be written (read-only ones, such as a model's q0,
    are copied): numba compiles, and a process loads, a separate kernel for read-only arrays."""
    array = np.asarray(values, dtype=float)
    return array if array.flags.writeable else array.copy()


class WrappedEquations:
    """Base of equations built on other equations (``self.inner``) that change only some terms:
    energies and drawn points are those of the inner mechanism."""

    inner: ModelEquations

    def kinetic_energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        return self.inner.kinetic_energy(q, qd)

    def potential_energy(self, q: np.ndarray) -> float:
        return self.inner.potential_energy(q)

    def point_positions(self, q: np.ndarray) -> np.ndarray:
        return self.inner.point_positions(q)


class _RowSubset(WrappedEquations):
    """Equations of a model restricted to some constraint rows (see :meth:`Model.without_drivers`)."""

    def __init__(self, equations: ModelEquations, rows: np.ndarray):
        self.inner = equations
        self.rows = rows
        self.row_origin = rows          # row k of these equations is row rows[k] of ``inner``
        self.inner_terms = equations.new_terms()
        self.n = self.inner_terms.Q.size

    def new_terms(self) -> Terms:
        inner = self.inner_terms
        constant = inner.M if not inner.M.flags.writeable else None
        return Terms(self.n, self.rows.size, constant_mass=constant)

    def evaluate(self, q: np.ndarray, qd: np.ndarray, t: float, u: np.ndarray, terms: Terms) -> None:
        self.inner.evaluate(q, qd, t, u, self.inner_terms)
        assign_terms(terms, self.inner_terms, self.rows)

    @property
    def work_sources(self) -> tuple[str, ...] | None:
        """The inner equations' (dropping rows removes no force)."""
        return getattr(self.inner, "work_sources", None)

    @property
    def steady_drivers(self) -> frozenset[str]:
        """The inner equations' (the rows kept keep their names)."""
        return getattr(self.inner, "steady_drivers", frozenset())

