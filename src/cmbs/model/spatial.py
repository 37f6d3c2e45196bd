"""Spatial models in natural coordinates (García de Jalón & Bayo, *Kinematic and Dynamic Simulation
of Multibody Systems*, Springer 1994, ch. 3 and 5).

Coordinates are the Cartesian components of the moving basic points (x, y, z each) and of unit
vectors (three components each).  Fixed points and vectors are constants, not coordinates.  There
are no rotation parameters: the constraints are at most quadratic and the mass matrix is constant.

**Bodies.**  A body is located by an origin point O and three independent basis elements
b₁, b₂, b₃, each either the difference P - O of a further basic point P, or a unit vector V.  A
material point of the body is at

    r = r_O + c₁ b₁ + c₂ b₂ + c₃ b₃,   c = X₀⁻¹ (r₀ - r_O,0),   X₀ = [b₁ b₂ b₃] at the start,

with constant coefficients c: r is linear in the body's coordinates, r = (aᵀ ⊗ I₃) q_e with
a = e₀ + B c over the slots (O, head of b₁, head of b₂, head of b₃), where B has a 1 for each
basis element in its slot and a -1 in O's slot for each point difference.  Hence the constant
element mass matrix and the gravity force (book eq. 5.20-5.27 in this notation)::

    M_e = (∫ a aᵀ dm) ⊗ I₃ = (m e₀e₀ᵀ + m (e₀ c̄ᵀBᵀ + B c̄ e₀ᵀ) + B J_c Bᵀ) ⊗ I₃,
    Q_e = (∫ a dm) ⊗ g = m (e₀ + B c̄) ⊗ g,

with c̄ = X₀⁻¹ (r_G - r_O) at the start and J_c = ∫ c cᵀ dm = X₀⁻¹ (S_G + m d dᵀ) X₀⁻ᵀ,
d = r_G - r_O, S_G = ∫ s sᵀ dm = ½ tr(I_G) I₃ - I_G from the inertia tensor I_G about the centre
of mass (all in ground axes at the start).  The six rigid-body constraints keep the basis's
scalar products: bₖ·bₗ = (bₖ·bₗ)₀ for k ≤ l.  Further body-fixed points and vectors E are linear
rows E - T - Σ cₖ bₖ = 0 (T = O for a point, nothing for a vector); like the planar bodies, the
body then adds μ |Ė - Σ cₖ ḃₖ|² (μ = its mass) to the kinetic energy, which vanishes on every
rigid motion and keeps M positive definite.  A body may use fixed elements (a ground axis for a
revolute joint to the ground); its products of two fixed elements are identities, not rows.

A **rod** is a slender body between two points i and j (its rotation about its own axis is no
coordinate): r = (1 - c) r_i + c r_j, M_e = ∫ [(1-c)²  c(1-c); c(1-c)  c²] dm ⊗ I₃ with
∫ c dm = m c̄ and ∫ c² dm = (I_⊥ + m c̄² L²)/L² (I_⊥ about the centre of mass, perpendicular to
the axis), and one rigid row |r_j - r_i|² = L² (mass 0: a massless link, the row alone).  A
**point mass** adds m I₃ to its point.

**Joints by shared elements** (book ch. 3.3), with the rows of the elements they share once
(a product of two elements that two bodies share is one row, not two):

==============  ======================================================================
spherical       a shared point
revolute        a shared point and a shared unit vector (the axis)
universal       a shared point; a·b = 0 for an axis a of one body and b of the other
cylindrical     a shared axis u; a slide: point P of one body on the line through a point
                O of the other along u, r_P - r_O - s u = 0 (s a coordinate)
prismatic       a cylindrical joint whose bodies share a second unit vector
planar          a shared normal n; (P - O)·n = 0 for points of either body
rigid (weld)    a shared origin and basis: the two are one body
point on line   a slide with a fixed (or body) point and axis
point in plane  (P - O)·n = 0 with a fixed (or body) point O and normal n
==============  ======================================================================

A scalar product row a·b = value relates two elements (vectors or point differences).

A constant **moment** M on a body does the virtual work M·δθ.  With G = (X₀ᵀX₀)⁻¹ the inverse
Gram matrix of the basis (constant for a rigid body: the dual basis bᵏ = Σₗ Gₖₗ bₗ turns with it),
the angular velocity is ω = ½ Σₖ bᵏ × ḃₖ (ḃₖ = ω × bₖ: Σₖ bᵏ × (ω × bₖ) = 3ω - ω), so
δθ = ½ Σₖₗ Gₖₗ bₗ × δbₖ and the generalized force on the head of bₖ (minus on its tail) is
½ Σₗ Gₖₗ (M × bₗ).

Each constraint is one of these kinds, evaluated for all its rows by one compiled kernel:

===========  =====================================  ==========================================
kind         Φ                                      γ = -(Ȧ q̇)
===========  =====================================  ==========================================
dot          a·b - value,  a = x_aₕ - x_aₜ, ...       -2 ȧ·ḃ
linear       E - T - Σ cₖ (x_hₖ - x_tₖ)  (3 rows)     0   (constant A)
angle        cos θ (r × v)·a - sin θ r·v              the velocity-quadratic part of Φ̈, negated
distance     |x_j - x_i|² - s²                        -2 |ẋ_j - ẋ_i|² + 2 ṡ²
slide        x_P - x_O - s u  (3 rows)                2 ṡ u̇
driver       q_c - f(t)                               f''(t)   (Φ_t = -f'(t))
===========  =====================================  ==========================================

An **angle coordinate** θ (massless) is the angle from r to v about the unit vector a, both
across it: on such vectors the row equals |r||v| sin(θ* - θ), θ* the actual angle, with
∂Φ/∂θ = -|r||v| at the solution, well conditioned at every angle as in the plane.  A **distance
coordinate** s (massless) is the distance between two points, a **slide** s the position of a
point along a line.  Drivers hold a coordinate (a
point's, an angle, a distance) at a function of time; actuators add gain·u to one.

(rigid-body rows and rods are dot rows; a unit vector is the difference of its
coordinates and a constant zero vector.)  Loads: gravity, constant forces at points, constant
moments on bodies, linear spring-dampers between points.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import NamedTuple, Sequence

import numpy as np

from cmbs.errors import ModelError, did_you_mean
from cmbs.jit import borrow, njit
from cmbs.model.drivers import TimeFunction, TimeFunctionPack, as_time_function, driver_rows, is_constant, \
    packed_time_functions
from cmbs.model.model import Model, Terms
from cmbs.model.packing import pack, unpack

# int sections of the kernel
(_DOT, _LINEAR, _SPRING, _POINT_FORCE, _MOMENT, _ANGLE, _DRIVER, _ACTUATOR, _TF_TABLE, _TF_OPS, _DISTANCE,
 _SLIDER, _ROTATIONAL_SPRING) = range(13)
# real sections
_DOT_VALUE, _LINEAR_COEFFICIENTS, _Q_CONSTANT, _SPRING_PARAMETERS, _POINT_FORCE_FRAME, _CONSTANTS = 0, 1, 2, 3, 4, 5
_MOMENT_VALUE, _ACTUATOR_GAIN, _TF_REALS, _ROTATIONAL_SPRING_PARAMETERS = 6, 7, 8, 9
#: a load's components along the ground axes, or along a body's axes (turning with it)
FRAMES = ("ground", "body")


@dataclass
class _Element:
    name: str
    kind: str               # "point" or "vector"
    value: np.ndarray
    fixed: bool
    mass: float = 0.0


@dataclass
class _Body:
    name: str
    origin: str
    basis: tuple[str, str, str]
    mass: float
    com: np.ndarray
    inertia: np.ndarray
    points: tuple[str, ...]
    vectors: tuple[str, ...]


@dataclass
class _Rod:
    name: str
    i: str
    j: str
    mass: float
    com: float
    inertia: float | None


@dataclass
class SpatialModelBuilder:
    """Builds a spatial natural-coordinate :class:`~cmbs.model.model.Model` (module docstring).

    Positions are in metres in ground axes, masses in kg, inertia tensors in kg m² about the
    centre of mass in ground axes at the initial configuration; ``gravity`` in m/s²."""

    name: str
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    description: str = ""
    source: str = ""
    _elements: dict[str, _Element] = field(default_factory=dict)
    _bodies: dict[str, _Body] = field(default_factory=dict)
    _rods: dict[str, _Rod] = field(default_factory=dict)
    _distances: dict[str, tuple[str, str, float | None]] = field(default_factory=dict)    # coordinates
    _sliders: dict[str, tuple[str, str, str, float | None]] = field(default_factory=dict)  # coordinates
    _dots: dict[str, tuple[object, object, float | None]] = field(default_factory=dict)
    _springs: dict[str, tuple[str, str, float, float, float | None]] = field(default_factory=dict)
    _forces: dict[str, tuple[str, tuple[TimeFunction, ...], str | None]] = field(default_factory=dict)
    _moments: dict[str, tuple[str, tuple[TimeFunction, ...], bool]] = field(default_factory=dict)
    _rotational_springs: dict[str, tuple[str, float, float, float | None]] = field(default_factory=dict)
    _angles: dict[str, tuple[object, object, str, float | None]] = field(default_factory=dict)
    _drivers: dict[str, tuple[str, TimeFunction]] = field(default_factory=dict)
    _actuators: dict[str, tuple[str, float]] = field(default_factory=dict)

    # ------------------------------------------------------------------ elements
    def add_point(self, name: str, position: Sequence[float], *, fixed: bool = False, mass: float = 0.0) -> None:
        """A basic point at ``position`` (x, y, z); fixed points are constants; ``mass`` a point
        mass at it."""
        entry = f"points.{name}"
        value = _vector3(position, entry, "position")
        if not (math.isfinite(mass) and mass >= 0.0):
            raise ModelError(f"mass must be a finite number >= 0, got {mass!r}", entry=entry)
        if mass > 0.0 and fixed:
            raise ModelError("a fixed point cannot carry mass", entry=entry)
        self._new_element(_Element(name, "point", value, fixed, float(mass)))

    def add_vector(self, name: str, direction: Sequence[float], *, fixed: bool = False) -> None:
        """A unit vector along ``direction`` (normalised here: a zero vector is refused)."""
        value = _vector3(direction, f"vectors.{name}", "direction")
        norm = float(np.linalg.norm(value))
        if norm == 0.0:
            raise ModelError("direction must not be zero", entry=f"vectors.{name}")
        self._new_element(_Element(name, "vector", value / norm, fixed))

    def _new_element(self, element: _Element) -> None:
        if element.name in self._elements:
            raise ModelError(f"{element.name!r} is defined twice (points and vectors share their names)",
                             entry=f"{element.kind}s.{element.name}")
        self._elements[element.name] = element

    # ------------------------------------------------------------------ bodies
    def add_body(self, name: str, *, origin: str, basis: Sequence[str], mass: float, com: Sequence[float],
                 inertia: Sequence[Sequence[float]], points: Sequence[str] = (), vectors: Sequence[str] = ()) -> None:
        """A rigid body located by point ``origin`` and three basis elements (names of points,
        meaning point - origin, or of unit vectors), with centre of mass ``com`` and inertia
        tensor ``inertia`` about it (ground axes, initial configuration); ``points`` and
        ``vectors`` are further elements fixed to it."""
        entry = f"bodies.{name}"
        self._check_new(self._bodies, name, "bodies")
        if isinstance(basis, str) or len(basis) != 3:
            raise ModelError(f"basis must name three elements, got {basis!r}", entry=entry)
        if not (isinstance(mass, (int, float)) and math.isfinite(mass) and mass > 0.0):
            raise ModelError(f"mass must be a finite number > 0, got {mass!r}", entry=entry)
        try:
            tensor = np.array(inertia, dtype=float)
        except (TypeError, ValueError):
            tensor = np.zeros(0)
        if tensor.shape != (3, 3) or not np.all(np.isfinite(tensor)):
            raise ModelError(f"inertia must be a finite 3x3 tensor, got {inertia!r}", entry=entry)
        if not np.allclose(tensor, tensor.T, rtol=1e-12, atol=1e-12 * max(1.0, np.abs(tensor).max())):
            raise ModelError(f"the inertia tensor must be symmetric, got {inertia!r}", entry=entry)
        moments = np.linalg.eigvalsh(tensor)
        slack = 1e-12 * max(1.0, moments.max())
        if moments[0] < -slack or moments[0] + moments[1] < moments[2] - slack:
            raise ModelError(f"the inertia tensor is not that of a body (principal moments "
                             f"{', '.join(f'{value:.6g}' for value in moments)}: each must be >= 0 and at most the "
                             "sum of the other two)", entry=entry)
        self._bodies[name] = _Body(name, origin, tuple(basis), float(mass), _vector3(com, entry, "com"), tensor,
                                   tuple(points), tuple(vectors))

    def add_rod(self, name: str, i: str, j: str, *, mass: float, com: float = 0.5,
                inertia: float | None = None) -> None:
        """A slender rigid rod from point ``i`` to point ``j``: mass, centre of mass at ``com``
        (fraction of the length from i) and moment of inertia about it perpendicular to the axis
        (default m L²/12, a uniform rod centred)."""
        entry = f"rods.{name}"
        self._check_new(self._rods, name, "rods")
        if not (math.isfinite(mass) and mass >= 0.0):
            raise ModelError(f"mass must be a finite number >= 0 (0: a massless link), got {mass!r}", entry=entry)
        if not math.isfinite(com):
            raise ModelError(f"com must be finite, got {com!r}", entry=entry)
        if inertia is not None and not (math.isfinite(inertia) and inertia >= 0.0):
            raise ModelError(f"inertia must be a finite number >= 0, got {inertia!r}", entry=entry)
        if mass == 0.0 and inertia:
            raise ModelError(f"a massless rod has no inertia, got {inertia!r}", entry=entry)
        self._rods[name] = _Rod(name, i, j, float(mass), float(com), None if inertia is None else float(inertia))

    # ------------------------------------------------------------------ constraints and loads
    def add_distance(self, name: str, i: str, j: str, *, initial: float | None = None) -> None:
        """A distance coordinate ``name`` (massless, as in the plane): s = |r_j - r_i|, the row
        |r_j - r_i|² - s² = 0; to drive or to actuate (a linear actuator between two points).
        ``initial`` defaults to the start distance.  A fixed length is a rod (mass 0 for a
        massless link)."""
        self._check_new(self._distances, name, "distances")
        _optional_number(initial, f"distances.{name}", "initial", positive=True)
        self._distances[name] = (i, j, initial)

    def add_slider(self, name: str, *, point: str, origin: str, axis: str, initial: float | None = None) -> None:
        """A slide coordinate ``name`` (massless): ``point`` stays on the line through ``origin``
        along the unit vector ``axis``, at s along it: r_point - r_origin - s u = 0 (three rows).
        With the axis shared by two bodies it is a cylindrical joint, with a second shared vector
        a prismatic joint; with ground elements a point on a fixed line.  ``initial`` defaults
        to the start value (point - origin)·u."""
        self._check_new(self._sliders, name, "sliders")
        _optional_number(initial, f"sliders.{name}", "initial")
        self._sliders[name] = (point, origin, axis, initial)

    def add_dot(self, name: str, a: str | tuple[str, str], b: str | tuple[str, str], *,
                value: float | None = None) -> None:
        """a·b = value (default: the initial product) for elements a, b: a unit vector's name or
        a pair of points (head, tail) meaning head - tail."""
        self._check_new(self._dots, name, "dots")
        _optional_number(value, f"dots.{name}", "value")
        self._dots[name] = (a, b, value)

    def add_spring(self, name: str, i: str, j: str, *, stiffness: float, damping: float = 0.0,
                   rest_length: float | None = None) -> None:
        """A linear spring-damper between points i and j: tension k (ℓ - ℓ₀) + c ℓ̇."""
        self._check_new(self._springs, name, "springs")
        for label, value in (("stiffness", stiffness), ("damping", damping)):
            if not (math.isfinite(value) and value >= 0.0):
                raise ModelError(f"{label} must be a finite number >= 0, got {value!r}", entry=f"springs.{name}")
        _optional_number(rest_length, f"springs.{name}", "rest_length", positive=True)
        self._springs[name] = (i, j, float(stiffness), float(damping), rest_length)

    def add_force(self, name: str, *, point: str, force: Sequence[object], body: str | None = None) -> None:
        """A force (fx, fy, fz) in N at a point, each component a number or a function of time
        (an expression, a table or a callable, as for drivers); along the ground axes, or with
        ``body`` along that body's axes (a follower force: the axes are the ground's at the
        start and turn with the body, F = X X₀⁻¹ f with X = [b₁ b₂ b₃])."""
        self._check_new(self._forces, name, "forces")
        self._forces[name] = (point, _time_functions3(force, f"forces.{name}", "force"), body)

    def add_moment(self, name: str, *, body: str, moment: Sequence[object], frame: str = "ground") -> None:
        """A moment (mx, my, mz) in N m on a body, each component a number or a function of
        time; along the ground axes (``frame="ground"``) or the body's (``"body"``, turning with
        it as for :meth:`add_force`)."""
        self._check_new(self._moments, name, "moments")
        if frame not in FRAMES:
            raise ModelError(f"frame must be one of {', '.join(map(repr, FRAMES))}, got {frame!r}",
                             entry=f"moments.{name}")
        self._moments[name] = (body, _time_functions3(moment, f"moments.{name}", "moment"), frame == "body")

    def add_rotational_spring(self, name: str, *, angle: str, stiffness: float, damping: float = 0.0,
                              rest_angle: float | None = None) -> None:
        """A rotational spring-damper on angle coordinate ``angle`` (about its axis, e.g. a
        revolute joint's): the torque -k (θ - θ₀) - c θ̇ between the two elements of the angle;
        ``rest_angle`` θ₀ defaults to the start angle."""
        self._check_new(self._rotational_springs, name, "rotational_springs")
        entry = f"rotational_springs.{name}"
        for label, value in (("stiffness", stiffness), ("damping", damping)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value)
                                                                                    and value >= 0.0):
                raise ModelError(f"{label} must be a finite number >= 0, got {value!r}", entry=entry)
        _optional_number(rest_angle, entry, "rest_angle")
        self._rotational_springs[name] = (angle, float(stiffness), float(damping), rest_angle)

    def add_angle(self, name: str, *, reference: str | tuple[str, str], vector: str | tuple[str, str], axis: str,
                  initial: float | None = None) -> None:
        """An angle coordinate ``name``: the angle from element ``reference`` to element ``vector``
        (each a unit vector's name or a pair of points (head, tail)) about the unit vector
        ``axis``, right-handed; both elements must stay across the axis (a revolute joint's
        axis and a vector of each of its two bodies).  ``initial`` chooses the turn (default: the
        start value in (-π, π])."""
        self._check_new(self._angles, name, "angles")
        _optional_number(initial, f"angles.{name}", "initial")
        self._angles[name] = (reference, vector, axis, initial)

    def add_driver(self, coordinate: str, function: object, *, name: str | None = None) -> None:
        """Rheonomic driver Φ = q_c - f(t) on ``coordinate`` (``"P.x"`` or an angle's name);
        ``function``: number, expression string, table or callable of t (docs/model-format.md)."""
        name = name or f"drive {coordinate}"
        self._check_new(self._drivers, name, "drivers")
        try:
            self._drivers[name] = (coordinate, as_time_function(function))
        except ModelError as error:
            raise error.located(entry=f"drivers.{name}") from None

    def add_actuator(self, name: str, *, coordinate: str, gain: float = 1.0) -> None:
        """An actuator input u_k entering as the generalized force gain·u_k on ``coordinate`` (a
        torque on an angle, a force along a point coordinate)."""
        self._check_new(self._actuators, name, "actuators")
        _optional_number(gain, f"actuators.{name}", "gain")
        self._actuators[name] = (coordinate, float(gain))

    def _check_new(self, table: dict, name: str, section: str) -> None:
        if name in table:
            raise ModelError(f"{name!r} is defined twice", entry=f"{section}.{name}")

    def build(self) -> Model:
        return _Assembler(self).model()


def _optional_number(value: object, entry: str, label: str, positive: bool = False) -> None:
    """ModelError unless ``value`` is None or a finite number (> 0 with ``positive``)."""
    if value is None:
        return
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or (positive and not value > 0):
        raise ModelError(f"{label} must be a finite number{' > 0' if positive else ''}, got {value!r}", entry=entry)


def _time_functions3(value: object, entry: str, label: str) -> tuple[TimeFunction, ...]:
    """Three time functions from three components (numbers, expressions, tables, callables)."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)) or len(value) != 3:
        raise ModelError(f"{label} must be three components (numbers or functions of t), got {value!r}", entry=entry)
    functions = []
    for axis, component in zip("xyz", value):
        try:
            functions.append(as_time_function(component))
        except ModelError as error:
            raise ModelError(error.problem, entry=f"{entry}.{label}.{axis}") from None
    return tuple(functions)


def _vector3(value: object, entry: str, label: str) -> np.ndarray:
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        array = None
    if array is None or array.shape != (3,) or not np.all(np.isfinite(array)):
        raise ModelError(f"{label} must be three finite numbers, got {value!r}", entry=entry)
    return array


class _Assembler:
    """Coordinates, constant extended coordinates, rows, mass matrix and gravity of a builder."""

    def __init__(self, builder: SpatialModelBuilder):
        self.b = builder
        self.gravity = _vector3(builder.gravity, "model", "gravity")
        self.index: dict[str, int] = {}
        names, kinds, q0, constants = [], [], [], []
        free = [e for e in builder._elements.values() if not e.fixed]
        n = 3 * len(free) + len(builder._angles) + len(builder._distances) + len(builder._sliders)
        for element in free:
            self.index[element.name] = len(q0)
            axes = ("x", "y", "z")
            names += [f"{element.name}.{axis}" for axis in axes]
            kinds += list(axes) if element.kind == "point" else ["direction"] * 3
            q0 += list(element.value)
        for section, table, kind in (("angles", builder._angles, "angle"),
                                     ("distances", builder._distances, "distance"),
                                     ("sliders", builder._sliders, "distance")):
            for name in table:                   # massless coordinates after the elements'
                if name in builder._elements or name in names:
                    raise ModelError(f"{name!r} is already the name of a coordinate, point or vector",
                                     entry=f"{section}.{name}")
                names.append(name)
                kinds.append(kind)
                q0.append(0.0)                   # set in model() from the elements
        for element in builder._elements.values():
            if element.fixed:
                self.index[element.name] = n + len(constants)
                constants += list(element.value)
        self.zero = n + len(constants)
        constants += [0.0, 0.0, 0.0]
        self.n, self.names, self.kinds = n, names, kinds
        self.q0, self.constants = np.array(q0), np.array(constants)
        self.x0 = np.concatenate([self.q0, self.constants])
        self.mass_ext = np.zeros((self.x0.size, self.x0.size))
        self.gravity_ext = np.zeros(self.x0.size)
        # each body's and rod's own share of M and gravity: {owner: ({(slot, slot): coefficient}, {slot: weight})}
        self.shares: dict[str, tuple[dict[tuple[int, int], float], dict[int, float]]] = {}
        self.owner = ""

    # ------------------------------------------------------------ lookups
    def _element(self, name: object, entry: str, kind: str | None = None) -> _Element:
        elements = self.b._elements
        if not isinstance(name, str) or name not in elements:
            raise ModelError(f"no {kind or 'point or vector'} {name!r}{did_you_mean(str(name), elements)}", entry=entry)
        element = elements[name]
        if kind is not None and element.kind != kind:
            raise ModelError(f"{name!r} is a {element.kind}, not a {kind}", entry=entry)
        return element

    def _pair(self, spec: object, entry: str) -> tuple[int, int]:
        """(head, tail) extended indices of an element spec: a vector (tail: the zero constant) or
        a pair of points."""
        if isinstance(spec, str):
            vector = self._element(spec, entry, "vector")
            return self.index[vector.name], self.zero
        if isinstance(spec, (tuple, list)) and len(spec) == 2:
            head, tail = (self._element(name, entry, "point") for name in spec)
            return self.index[head.name], self.index[tail.name]
        raise ModelError(f"an element is a vector's name or a pair of point names, got {spec!r}", entry=entry)

    def _coordinate(self, name: object, entry: str) -> int:
        """The index of coordinate ``name`` ("P.x", an angle's name)."""
        if not isinstance(name, str) or name not in self.names:
            raise ModelError(f"no coordinate {name!r}{did_you_mean(str(name), self.names)} (coordinates: "
                             f"{', '.join(self.names)})", entry=entry)
        return self.names.index(name)

    def _check_moving(self, indices: Sequence[int], entry: str) -> None:
        """ModelError for a row between fixed elements only: it involves no coordinate."""
        if min(indices) >= self.n:
            raise ModelError("relates fixed elements only: it constrains no coordinate (remove it)", entry=entry)

    def _frame(self, frames: dict[str, "BodyFrame"], body: object, entry: str) -> "BodyFrame":
        """The :class:`BodyFrame` of body ``body`` (its basis and X₀⁻¹)."""
        if not isinstance(body, str) or body not in frames:
            raise ModelError(f"no body {body!r}{did_you_mean(str(body), frames)}", entry=entry)
        return frames[body]

    def _value(self, pair: tuple[int, int]) -> np.ndarray:
        return self.x0[pair[0]:pair[0] + 3] - self.x0[pair[1]:pair[1] + 3]

    # ------------------------------------------------------------ assembly
    def model(self) -> Model:
        b = self.b
        dots, dot_values, dot_names = [], [], []
        linear, coefficients, linear_names = [], [], []
        lines: list[tuple[str, str]] = []
        frames: dict[str, BodyFrame] = {}
        shared_products: set[frozenset[tuple[int, int]]] = set()
        owned: dict[str, tuple[list[str], list[int], list[int]]] = {}    # elements, dot rows, linear rows
        for body in b._bodies.values():
            entry = f"bodies.{body.name}"
            self.owner = body.name
            elements, own_dots, own_linear = owned.setdefault(body.name, ([body.origin], [], []))
            origin = self._element(body.origin, entry, "point")
            o = self.index[origin.name]
            basis, labels = [], []
            for spec in body.basis:
                element = self._element(spec, entry)
                basis.append((self.index[element.name], o if element.kind == "point" else self.zero))
                labels.append(f"({element.name}-{origin.name})" if element.kind == "point" else element.name)
                if element.kind == "point":
                    lines.append((origin.name, element.name))
            if len({pair[0] for pair in basis}) != 3 or o in {pair[0] for pair in basis}:
                raise ModelError("origin and basis must be four different elements", entry=entry)
            X0 = np.column_stack([self._value(pair) for pair in basis])
            scale = np.prod(np.linalg.norm(X0, axis=0))
            if not abs(np.linalg.det(X0)) > 1e-9 * scale:
                raise ModelError(f"the basis elements {list(body.basis)} are coplanar at the start: they do not locate "
                                 "the body", entry=entry)
            for k in range(3):
                for l in range(k, 3):
                    if min(*basis[k], *basis[l]) >= self.n:
                        continue            # between fixed elements only: an identity, no row
                    product = frozenset((basis[k], basis[l]))
                    if product in shared_products:
                        continue            # of elements shared with an earlier body: its row already
                    shared_products.add(product)
                    own_dots.append(len(dots))
                    dots.append((*basis[k], *basis[l]))
                    dot_values.append(float(self._value(basis[k]) @ self._value(basis[l])))
                    dot_names.append(f"rigid {body.name}: {labels[k]}·{labels[l]}")
            self._body_mass(body, o, basis, X0)
            frames[body.name] = BodyFrame(body.name, o, tuple(basis), np.linalg.inv(X0))
            elements += list(body.basis)
            for spec in body.points + body.vectors:
                element = self._element(spec, entry, "point" if spec in body.points else "vector")
                elements.append(element.name)
                own_linear.append(len(linear))
                target = (self.index[element.name], o if element.kind == "point" else self.zero)
                c = np.linalg.solve(X0, self._value(target))
                for axis in range(3):
                    linear_names.append(f"body {body.name}: {element.name}.{'xyz'[axis]}")
                linear.append((*target, *[index for pair in basis for index in pair]))
                coefficients.append(c)
                self._rigidity_mass(body.mass, target, basis, c)
                if element.kind == "point":
                    lines.append((origin.name, element.name))
        for rod in b._rods.values():
            entry = f"rods.{rod.name}"
            i, j = (self._element(name, entry, "point") for name in (rod.i, rod.j))
            pair = (self.index[j.name], self.index[i.name])
            length = float(np.linalg.norm(self._value(pair)))
            if not length > 0.0:
                raise ModelError(f"points {rod.i!r} and {rod.j!r} coincide", entry=entry)
            self.owner = rod.name
            owned[rod.name] = ([rod.i, rod.j], [len(dots)], [])
            dots.append((*pair, *pair))
            dot_values.append(length * length)
            dot_names.append(f"rigid {rod.name}")
            self._rod_mass(rod, self.index[i.name], self.index[j.name], length)
            lines.append((i.name, j.name))
        self.owner = ""                         # point masses: no body's
        for element in b._elements.values():
            if element.mass > 0.0:
                p = self.index[element.name]
                self.mass_ext[p:p + 3, p:p + 3] += element.mass * np.eye(3)
                self.gravity_ext[p:p + 3] += element.mass * self.gravity
        for name, (a, bb, value) in b._dots.items():
            entry = f"dots.{name}"
            first, second = self._pair(a, entry), self._pair(bb, entry)
            self._check_moving((*first, *second), entry)
            dots.append((*first, *second))
            dot_values.append(float(self._value(first) @ self._value(second)) if value is None else float(value))
            dot_names.append(f"dot {name}")
        angles, angle_names = [], []
        for k, (name, (reference, vector, axis, initial)) in enumerate(b._angles.items()):
            entry = f"angles.{name}"
            first, second = self._pair(reference, entry), self._pair(vector, entry)
            normal = (self.index[self._element(axis, entry, "vector").name], self.zero)
            r, v, a = self._value(first), self._value(second), self._value(normal)
            for label, element in (("reference", r), ("vector", v)):
                if abs(element @ a) > 1e-6 * np.linalg.norm(element):
                    raise ModelError(f"the {label} is not across the axis {axis!r} at the start (their product is "
                                     f"{element @ a:.3g}): the angle about the axis is that of two vectors across it",
                                     entry=entry)
            coordinate = self.names.index(name)
            start = math.atan2(float(np.cross(r, v) @ a), float(r @ v))
            self.q0[coordinate] = self.x0[coordinate] = start if initial is None else float(initial)
            angles.append((*first, *second, *normal, coordinate))
            angle_names.append(f"angle {name}")
        distances, distance_names = [], []
        for name, (i, j, initial) in b._distances.items():
            entry = f"distances.{name}"
            pair = tuple(self.index[self._element(p, entry, "point").name] for p in (j, i))
            coordinate = self.names.index(name)
            start = float(np.linalg.norm(self._value(pair)))
            self.q0[coordinate] = self.x0[coordinate] = start if initial is None else float(initial)
            distances.append((*pair, coordinate))
            distance_names.append(f"distance {name}")
        sliders, slider_names = [], []
        for name, (point, origin, axis, initial) in b._sliders.items():
            entry = f"sliders.{name}"
            p, o = (self.index[self._element(e, entry, "point").name] for e in (point, origin))
            u = self.index[self._element(axis, entry, "vector").name]
            if p == o:
                raise ModelError(f"point and origin are both {point!r}", entry=entry)
            if min(p, o) >= self.n and u >= self.n:
                raise ModelError("point, origin and axis are fixed: the slide constrains nothing that moves",
                                 entry=entry)
            along = self.x0[p:p + 3] - self.x0[o:o + 3]
            direction = self.x0[u:u + 3]
            start = float(along @ direction)
            off = float(np.linalg.norm(along - start * direction))
            if off > 1e-6 * max(1.0, float(np.linalg.norm(along))):
                raise ModelError(f"{point!r} is {off:.6g} m off the line through {origin!r} along {axis!r} at the "
                                 "start", entry=entry)
            coordinate = self.names.index(name)
            self.q0[coordinate] = self.x0[coordinate] = start if initial is None else float(initial)
            sliders.append((p, o, u, coordinate))
            lines.append((origin, point))
            slider_names += [f"slider {name}.{axis_name}" for axis_name in "xyz"]
        drivers, functions, labels, driver_names = [], [], [], []
        for name, (coordinate, function) in b._drivers.items():
            drivers.append((self._coordinate(coordinate, f"drivers.{name}"), len(functions)))
            functions.append(function)
            labels.append(f"driver {name}")
            driver_names.append(name)
        forces, force_frames = [], []
        for name, (point, components, body_name) in b._forces.items():
            entry = f"forces.{name}"
            p = self.index[self._element(point, entry, "point").name]
            frame = self._frame(frames, body_name, entry) if body_name is not None else None
            forces.append([p, *range(len(functions), len(functions) + 3), int(frame is not None),
                           *([index for pair in frame.basis for index in pair] if frame is not None else [0] * 6)])
            force_frames.append(frame.start_inverse.ravel() if frame is not None else np.zeros(9))
            functions += components
            labels += [f"force {name} {axis}" for axis in "xyz"]
        moments, moment_values = [], []
        for name, (body_name, components, in_body) in b._moments.items():
            frame = self._frame(frames, body_name, f"moments.{name}")
            moments.append([*(index for pair in frame.basis for index in pair),
                            *range(len(functions), len(functions) + 3), int(in_body)])
            inverse = frame.start_inverse              # (X₀ᵀX₀)⁻¹ = X₀⁻¹ X₀⁻ᵀ
            moment_values.append(np.concatenate([(inverse @ inverse.T).ravel(), inverse.ravel()]))
            functions += components
            labels += [f"moment {name} {axis}" for axis in "xyz"]
        rotational_springs, rotational_parameters = [], []
        for name, (angle, stiffness, damping, rest) in b._rotational_springs.items():
            entry = f"rotational_springs.{name}"
            if angle not in b._angles:
                raise ModelError(f"no angle {angle!r}{did_you_mean(str(angle), b._angles)}", entry=entry)
            coordinate = self.names.index(angle)
            rotational_springs.append(coordinate)
            rotational_parameters.append((stiffness, damping, self.q0[coordinate] if rest is None else float(rest)))
        actuators, gains = [], []
        for name, (coordinate, gain) in b._actuators.items():
            actuators.append(self._coordinate(coordinate, f"actuators.{name}"))
            gains.append(gain)
        time_functions = TimeFunctionPack.build(functions, labels)
        springs, spring_parameters = [], []
        for name, (i, j, stiffness, damping, rest) in b._springs.items():
            entry = f"springs.{name}"
            pair = tuple(self.index[self._element(p, entry, "point").name] for p in (i, j))
            length = float(np.linalg.norm(self.x0[pair[1]:pair[1] + 3] - self.x0[pair[0]:pair[0] + 3]))
            springs.append(pair)
            spring_parameters.append((stiffness, damping, length if rest is None else float(rest)))

        n = self.n
        mass = self.mass_ext[:n, :n].copy()
        q_constant = self.gravity_ext[:n].copy()
        int_sections = [np.array(dots, dtype=np.int64).reshape(-1, 4), np.array(linear, dtype=np.int64).reshape(-1, 8),
                        np.array(springs, dtype=np.int64).reshape(-1, 2),
                        np.array(forces, dtype=np.int64).reshape(-1, 11),
                        np.array(moments, dtype=np.int64).reshape(-1, 10),
                        np.array(angles, dtype=np.int64).reshape(-1, 7),
                        np.array(drivers, dtype=np.int64).reshape(-1, 2), np.array(actuators, dtype=np.int64),
                        time_functions.table, time_functions.ops, np.array(distances, dtype=np.int64).reshape(-1, 3),
                        np.array(sliders, dtype=np.int64).reshape(-1, 4),
                        np.array(rotational_springs, dtype=np.int64)]
        real_sections = [np.array(dot_values), np.array(coefficients).reshape(-1, 3), q_constant,
                         np.array(spring_parameters).reshape(-1, 3), np.array(force_frames).reshape(-1, 9),
                         self.constants, np.array(moment_values).reshape(-1, 18), np.array(gains),
                         time_functions.reals, np.array(rotational_parameters).reshape(-1, 3)]
        ints, reals = pack(int_sections, real_sections)
        mass.setflags(write=False)
        point_names = [e.name for e in b._elements.values() if e.kind == "point"]
        equations = SpatialEquations(n=n, m=len(dots) + 3 * len(linear) + len(angles) + len(distances)
                                     + 3 * len(sliders) + len(drivers),
                                     ints=ints,
                                     reals=reals, mass=mass, time_functions=time_functions,
                                     constants=self.constants, gravity_ext=self.gravity_ext.copy(),
                                     springs=(np.array(springs, dtype=np.int64).reshape(-1, 2),
                                              np.array(spring_parameters).reshape(-1, 3)),
                                     rotational_springs=(np.array(rotational_springs, dtype=np.int64),
                                                         np.array(rotational_parameters).reshape(-1, 3)),
                                     point_indices=np.array([self.index[p] for p in point_names], dtype=np.int64),
                                     free_bodies=tuple(self._free_body(name, elements,
                                                                       [*own_dots, *(len(dots) + 3 * k + d
                                                                                     for k in own_linear for d in range(3))])
                                                       for name, (elements, own_dots, own_linear) in owned.items()),
                                     moment_bodies=tuple(body for body, _, _ in b._moments.values()),
                                     gravity=tuple(float(g) for g in self.gravity), bodies=tuple(frames.values()),
                                     work_sources=tuple(f"force {name!r}" for name in b._forces)
                                     + tuple(f"moment {name!r}" for name in b._moments)
                                     + tuple(f"spring {name!r}" for name, s in b._springs.items() if s[3] > 0.0)
                                     + tuple(f"rotational spring {name!r}"
                                             for name, s in b._rotational_springs.items() if s[2] > 0.0),
                                     steady_drivers=frozenset(name for name, (_, function) in b._drivers.items()
                                                              if is_constant(function)))
        constraint_names = dot_names + linear_names + angle_names + distance_names + slider_names + driver_names
        return Model(name=b.name, coordinate_names=tuple(self.names), coordinate_kinds=tuple(self.kinds),
                     constraint_names=tuple(constraint_names),
                     drivers=np.arange(len(constraint_names)) >= len(constraint_names) - len(driver_names),
                     actuator_names=tuple(b._actuators), q0=self.q0.copy(), qd0=np.zeros(n),
                     point_names=tuple(point_names),
                     lines=tuple((point_names.index(i), point_names.index(j)) for i, j in lines),
                     equations=equations, description=b.description, source=b.source,
                     parameters={"gravity": tuple(float(g) for g in self.gravity)},
                     constant_mass=True)

    def _add_element_matrix(self, slots: Sequence[int], matrix: np.ndarray, weights: np.ndarray) -> None:
        """M_ext += matrix ⊗ I₃ over the 3-vectors at ``slots``; gravity += weights ⊗ g; the same
        into the share of the body or rod being assembled (``self.owner``)."""
        blocks, gravity = self.shares.setdefault(self.owner, ({}, {}))
        for a, p in enumerate(slots):
            self.gravity_ext[p:p + 3] += weights[a] * self.gravity
            gravity[p] = gravity.get(p, 0.0) + weights[a]
            for b, r in enumerate(slots):
                self.mass_ext[p:p + 3, r:r + 3] += matrix[a, b] * np.eye(3)
                blocks[p, r] = blocks.get((p, r), 0.0) + matrix[a, b]

    def _free_body(self, name: str, elements: Sequence[str], rows: Sequence[int]) -> "FreeBody":
        """The :class:`FreeBody` of body or rod ``name`` from its share of M and gravity."""
        slots = np.array([self.index[element] for element in elements], dtype=np.int64)
        blocks, weights = self.shares[name]
        position = {int(slot): k for k, slot in enumerate(slots)}
        matrix = np.zeros((slots.size, slots.size))
        for (p, r), value in blocks.items():
            matrix[position[p], position[r]] += value
        gravity = np.zeros(slots.size)
        for p, weight in weights.items():
            gravity[position[p]] += weight
        return FreeBody(name, tuple(elements), tuple(self.b._elements[e].kind for e in elements), slots,
                         np.kron(matrix, np.eye(3)), np.kron(gravity, self.gravity), np.array(rows, dtype=np.int64))

    def _body_mass(self, body: _Body, o: int, basis: list[tuple[int, int]], X0: np.ndarray) -> None:
        """The body's element mass matrix and gravity (module docstring)."""
        B = np.zeros((4, 3))
        for k, (head, tail) in enumerate(basis):
            B[k + 1, k] = 1.0
            if tail == o:
                B[0, k] = -1.0
        X0_inverse = np.linalg.inv(X0)
        d = body.com - self.x0[o:o + 3]
        c_bar = X0_inverse @ d
        second = 0.5 * np.trace(body.inertia) * np.eye(3) - body.inertia + body.mass * np.outer(d, d)
        J_c = X0_inverse @ second @ X0_inverse.T
        e0 = np.array([1.0, 0.0, 0.0, 0.0])
        first = body.mass * (B @ c_bar)
        matrix = body.mass * np.outer(e0, e0) + np.outer(e0, first) + np.outer(first, e0) + B @ J_c @ B.T
        self._add_element_matrix([o] + [head for head, _ in basis], matrix, body.mass * e0 + first)

    def _rigidity_mass(self, mass: float, target: tuple[int, int], basis: list[tuple[int, int]],
                       c: np.ndarray) -> None:
        """μ Bᵀ B for the linear rows of a further element (module docstring): B the rows' Jacobian
        over the extended coordinates."""
        weights: dict[int, float] = {}
        for index, weight in ((target[0], 1.0), (target[1], -1.0)):
            weights[index] = weights.get(index, 0.0) + weight
        for k, (head, tail) in enumerate(basis):
            for index, weight in ((head, -c[k]), (tail, c[k])):
                weights[index] = weights.get(index, 0.0) + weight
        slots = [index for index, weight in weights.items() if index != self.zero and weight != 0.0]
        row = np.array([weights[index] for index in slots])
        self._add_element_matrix(slots, mass * np.outer(row, row), np.zeros(len(slots)))

    def _rod_mass(self, rod: _Rod, i: int, j: int, length: float) -> None:
        inertia = rod.mass * length * length / 12.0 if rod.inertia is None else rod.inertia
        first = rod.mass * rod.com
        second = (inertia + rod.mass * (rod.com * length) ** 2) / (length * length)
        matrix = np.array([[rod.mass - 2.0 * first + second, first - second], [first - second, second]])
        self._add_element_matrix([i, j], matrix, np.array([rod.mass - first, first]))


class BodyFrame(NamedTuple):
    """Where a body's pose is read from: the extended index of its origin point, the (head, tail)
    extended indices of its three basis elements (tail: the origin for a point difference, the
    zero constant for a unit vector) and the inverse of their matrix X₀ = [b₁ b₂ b₃] as built."""

    name: str
    origin: int
    basis: tuple[tuple[int, int], ...]
    start_inverse: np.ndarray


@dataclass(frozen=True)
class SpatialEquations:
    """Compiled evaluator of a spatial natural-coordinate model (see the module docstring)."""

    n: int
    m: int
    ints: np.ndarray
    reals: np.ndarray
    mass: np.ndarray
    constants: np.ndarray
    gravity_ext: np.ndarray
    springs: tuple[np.ndarray, np.ndarray]
    rotational_springs: tuple[np.ndarray, np.ndarray]
    point_indices: np.ndarray
    #: each body's and rod's share of the model, for its free-body equation
    free_bodies: tuple["FreeBody", ...]
    #: the body of each moment, in the order of the moments
    moment_bodies: tuple[str, ...]
    time_functions: TimeFunctionPack
    #: the forces and dampers, by name (see :attr:`cmbs.model.model.Model.work_sources`)
    work_sources: tuple[str, ...] = ()
    #: the drivers of a constant, which hold their coordinate and do no work
    steady_drivers: frozenset[str] = frozenset()
    #: the acceleration of gravity (m/s², ground axes)
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    #: the rigid bodies' frames (:meth:`body_poses`), in the order they were added
    bodies: tuple[BodyFrame, ...] = ()

    def new_terms(self) -> Terms:
        """Terms whose scratch holds the time functions' (f, f', f'') and stack, then the extended
        x = (q, constants) and v = (q̇, 0)."""
        functions = self.time_functions
        return Terms(self.n, self.m, constant_mass=self.mass,
                     scratch=3 * (functions.count + functions.depth) + 2 * (self.n + self.constants.size))

    def compiled_kernel(self) -> "SpatialKernel | None":
        """The model's data for the compiled loops, or None when a driver is a Python callable."""
        if self.time_functions.python:
            return None
        return SpatialKernel(self.ints, self.reals, np.ascontiguousarray(self.mass, dtype=float))

    def moment_loads(self, body: str, q: np.ndarray, t: float) -> np.ndarray:
        """The generalized force (n,) of the moments on ``body`` alone at (q, t): the model's own
        kernel on a copy of its data that keeps only those moments."""
        int_sections, real_sections = unpack(self.ints, self.reals)
        for k in (_DOT, _LINEAR, _SPRING, _POINT_FORCE, _ANGLE, _DRIVER, _ACTUATOR, _DISTANCE, _SLIDER,
                  _ROTATIONAL_SPRING):
            int_sections[k] = np.zeros(0, dtype=np.int64)
        keep = [k for k, name in enumerate(self.moment_bodies) if name == body]
        int_sections[_MOMENT] = int_sections[_MOMENT].reshape(-1, 10)[keep]
        real_sections[_MOMENT_VALUE] = real_sections[_MOMENT_VALUE].reshape(-1, 18)[keep]
        real_sections[_Q_CONSTANT] = np.zeros(self.n)
        ints, reals = pack(int_sections, real_sections)
        loads = dataclasses.replace(self, m=0, ints=ints, reals=reals)
        terms = loads.new_terms()
        loads.evaluate(np.array(q, dtype=float), np.zeros(self.n), t, np.zeros(0), terms)
        return terms.Q.copy()

    def without_drivers(self) -> "SpatialEquations":
        """The same equations with the driver rows (the last constraints) removed, and the time
        functions only they used no longer evaluated (:meth:`TimeFunctionPack.keeping`)."""
        int_sections, real_sections = unpack(self.ints, self.reals)
        drivers = int_sections[_DRIVER].size // 2
        int_sections[_DRIVER] = np.zeros(0, dtype=np.int64)
        used = set(int_sections[_POINT_FORCE].reshape(-1, 11)[:, 1:4].ravel().tolist())
        used |= set(int_sections[_MOMENT].reshape(-1, 10)[:, 6:9].ravel().tolist())
        time_functions = self.time_functions.keeping(used)
        int_sections[_TF_TABLE] = time_functions.table.ravel() if used else np.zeros(0, dtype=np.int64)
        ints, reals = pack(int_sections, real_sections)
        return dataclasses.replace(self, m=self.m - drivers, ints=ints, reals=reals, time_functions=time_functions)

    def evaluate(self, q: np.ndarray, qd: np.ndarray, t: float, u: np.ndarray, terms: Terms) -> None:
        for k, function in self.time_functions.python:
            terms.scratch[3 * k:3 * k + 3] = function(t)
        _evaluate(q, qd, t, u, self.ints, self.reals, terms.buffer)

    def _extended(self, q: np.ndarray) -> np.ndarray:
        return np.concatenate([q, np.broadcast_to(self.constants, (*q.shape[:-1], self.constants.size))], axis=-1)

    def kinetic_energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        return 0.5 * float(qd @ self.mass @ qd)

    def energy_parts(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """T = ½ q̇ᵀ M q̇ and V = -Q_gravityᵀ x + Σ ½ k (ℓ - ℓ₀)² + Σ ½ k (θ - θ₀)² at every row of
        q, q̇ (k, n)."""
        x = self._extended(q)
        potential = -(x @ self.gravity_ext)
        rows, parameters = self.springs
        for (i, j), (stiffness, _, rest) in zip(rows, parameters):
            length = np.linalg.norm(x[:, j:j + 3] - x[:, i:i + 3], axis=1)
            potential = potential + 0.5 * stiffness * (length - rest) ** 2
        for coordinate, (stiffness, _, rest) in zip(*self.rotational_springs):
            potential = potential + 0.5 * stiffness * (q[:, coordinate] - rest) ** 2
        return 0.5 * np.sum((qd @ self.mass) * qd, axis=1), potential

    def potential_energy(self, q: np.ndarray) -> float:
        return float(self.energy_parts(np.atleast_2d(q), np.zeros((1, self.n)))[1][0])

    @property
    def body_names(self) -> tuple[str, ...]:
        """The names of :attr:`bodies`."""
        return tuple(body.name for body in self.bodies)

    def body_poses(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Origins (..., bodies, 3) and rotation matrices (..., bodies, 3, 3) of the bodies at
        coordinates ``q`` (..., n).

        With X = [b₁ b₂ b₃] the basis elements at q, R = X X₀⁻¹ maps the body as built onto the
        body at q: exact (and orthonormal, det +1) for a rigid motion, since every material point
        is r = r_O + X c.  The constraint error that integration leaves makes X X₀⁻¹ slightly
        non-orthonormal; R is its nearest rotation, the orthogonal factor of its polar
        decomposition U Vᵀ (SVD X X₀⁻¹ = U S Vᵀ; the last column of U negated should det(U Vᵀ)
        be -1).  Rows of q that are not finite give NaN."""
        x = self._extended(np.asarray(q, dtype=float))
        rows = x.reshape(-1, x.shape[-1])
        count = len(self.bodies)
        origins = np.empty((rows.shape[0], count, 3))
        rotations = np.full((rows.shape[0], count, 3, 3), np.nan)
        finite = np.all(np.isfinite(rows), axis=1)
        for k, body in enumerate(self.bodies):
            origins[:, k] = rows[:, body.origin:body.origin + 3]
            X = np.stack([rows[finite, head:head + 3] - rows[finite, tail:tail + 3] for head, tail in body.basis],
                         axis=-1)
            U, _, Vt = np.linalg.svd(X @ body.start_inverse)
            U[:, :, 2] *= np.sign(np.linalg.det(U @ Vt))[:, None]
            rotations[finite, k] = U @ Vt
        shape = x.shape[:-1]
        return origins.reshape(*shape, count, 3), rotations.reshape(*shape, count, 3, 3)

    def point_positions(self, q: np.ndarray) -> np.ndarray:
        """(n_points, 3) positions of the model's points."""
        x = self._extended(np.asarray(q, dtype=float))
        return np.stack([x[i:i + 3] for i in self.point_indices]) if self.point_indices.size else np.zeros((0, 3))


@njit(cache=True, inline="always")
def _add(buffer, a0, row, column, value, n):
    """A[row, column] += value where A is row-major at ``buffer[a0:]`` (constant columns skipped)."""
    if column < n:
        buffer[a0 + row * n + column] += value


@njit(cache=True, error_model="numpy")
def _evaluate(q, qd, t, u, ints, reals, buffer):
    """Q, Φ, A, γ, Φ_t of a spatial natural-coordinate model into ``buffer`` (layout of
    :class:`Terms`; its scratch holds the time functions' rows and stack, then the extended
    x = (q, constants) and v = (q̇, 0)): the dot, linear, angle, distance and driver rows of the
    module docstring; gravity, point forces, moments, spring-dampers and actuators."""
    q, qd, u, ints, reals, buffer = borrow((q, qd, u, ints, reals, buffer))
    n = q.shape[0]
    real_base = ints[0] + 2
    c0, c1 = ints[real_base + 1 + _CONSTANTS], ints[real_base + 2 + _CONSTANTS]
    n_ext = n + c1 - c0
    i_dot, n_dot = ints[1 + _DOT], (ints[2 + _DOT] - ints[1 + _DOT]) // 4
    i_linear, n_linear = ints[1 + _LINEAR], (ints[2 + _LINEAR] - ints[1 + _LINEAR]) // 8
    i_angle, n_angle = ints[1 + _ANGLE], (ints[2 + _ANGLE] - ints[1 + _ANGLE]) // 7
    i_distance, n_distance = ints[1 + _DISTANCE], (ints[2 + _DISTANCE] - ints[1 + _DISTANCE]) // 3
    i_slider, n_slider = ints[1 + _SLIDER], (ints[2 + _SLIDER] - ints[1 + _SLIDER]) // 4
    n_driver = (ints[2 + _DRIVER] - ints[1 + _DRIVER]) // 2
    m = n_dot + 3 * n_linear + n_angle + n_distance + 3 * n_slider + n_driver
    a0 = n + m
    g0 = a0 + m * n
    t0 = g0 + m
    s0 = t0 + m
    x0 = buffer.shape[0] - 2 * n_ext
    v0 = x0 + n_ext
    for k in range(n):
        buffer[x0 + k] = q[k]
        buffer[v0 + k] = qd[k]
    for k in range(n, n_ext):
        buffer[x0 + k] = reals[c0 + k - n]
        buffer[v0 + k] = 0.0
    # time functions: (f, f', f'') rows at the scratch's start, then the expression stack
    packed_time_functions(ints, reals, _TF_TABLE, _TF_OPS, _TF_REALS, t, buffer, s0, x0)
    buffer[a0:g0] = 0.0
    buffer[t0:s0] = 0.0
    row = 0
    r0 = ints[real_base + 1 + _DOT_VALUE]
    for k in range(n_dot):
        ah, at, bh, bt = ints[i_dot + 4 * k], ints[i_dot + 4 * k + 1], ints[i_dot + 4 * k + 2], ints[i_dot + 4 * k + 3]
        phi = -reals[r0 + k]
        gamma = 0.0
        for d in range(3):
            a = buffer[x0 + ah + d] - buffer[x0 + at + d]
            b = buffer[x0 + bh + d] - buffer[x0 + bt + d]
            da = buffer[v0 + ah + d] - buffer[v0 + at + d]
            db = buffer[v0 + bh + d] - buffer[v0 + bt + d]
            phi += a * b
            gamma -= 2.0 * da * db
            _add(buffer, a0, row, ah + d, b, n)
            _add(buffer, a0, row, at + d, -b, n)
            _add(buffer, a0, row, bh + d, a, n)
            _add(buffer, a0, row, bt + d, -a, n)
        buffer[n + row] = phi
        buffer[g0 + row] = gamma
        row += 1
    r0 = ints[real_base + 1 + _LINEAR_COEFFICIENTS]
    for k in range(n_linear):
        s = i_linear + 8 * k
        head, tail = ints[s], ints[s + 1]
        for d in range(3):
            value = buffer[x0 + head + d] - buffer[x0 + tail + d]
            _add(buffer, a0, row, head + d, 1.0, n)
            _add(buffer, a0, row, tail + d, -1.0, n)
            for e in range(3):
                c = reals[r0 + 3 * k + e]
                he, te = ints[s + 2 + 2 * e], ints[s + 3 + 2 * e]
                value -= c * (buffer[x0 + he + d] - buffer[x0 + te + d])
                _add(buffer, a0, row, he + d, -c, n)
                _add(buffer, a0, row, te + d, c, n)
            buffer[n + row] = value
            buffer[g0 + row] = 0.0
            row += 1

    for k in range(n_angle):
        _angle_row(buffer, ints, i_angle + 7 * k, n, a0, g0, x0, v0, row)
        row += 1
    for k in range(n_distance):
        j, i, c = ints[i_distance + 3 * k], ints[i_distance + 3 * k + 1], ints[i_distance + 3 * k + 2]
        length, rate = buffer[x0 + c], buffer[v0 + c]
        phi = -length * length
        gamma = 2.0 * rate * rate
        for d in range(3):
            e = buffer[x0 + j + d] - buffer[x0 + i + d]
            de = buffer[v0 + j + d] - buffer[v0 + i + d]
            phi += e * e
            gamma -= 2.0 * de * de
            _add(buffer, a0, row, j + d, 2.0 * e, n)
            _add(buffer, a0, row, i + d, -2.0 * e, n)
        buffer[n + row] = phi
        buffer[a0 + row * n + c] += -2.0 * length
        buffer[g0 + row] = gamma
        row += 1
    for k in range(n_slider):
        p, o, a, c = ints[i_slider + 4 * k], ints[i_slider + 4 * k + 1], ints[i_slider + 4 * k + 2], \
            ints[i_slider + 4 * k + 3]
        along, rate = buffer[x0 + c], buffer[v0 + c]
        for d in range(3):
            axis = buffer[x0 + a + d]
            buffer[n + row] = buffer[x0 + p + d] - buffer[x0 + o + d] - along * axis
            _add(buffer, a0, row, p + d, 1.0, n)
            _add(buffer, a0, row, o + d, -1.0, n)
            _add(buffer, a0, row, a + d, -along, n)
            buffer[a0 + row * n + c] += -axis
            buffer[g0 + row] = 2.0 * rate * buffer[v0 + a + d]
            row += 1
    row = driver_rows(ints, _DRIVER, buffer, n, a0, g0, t0, s0, x0, row)

    r0 = ints[real_base + 1 + _Q_CONSTANT]
    for k in range(n):
        buffer[k] = reals[r0 + k]
    i0 = ints[1 + _ACTUATOR]
    r0 = ints[real_base + 1 + _ACTUATOR_GAIN]
    for k in range(ints[2 + _ACTUATOR] - i0):
        buffer[ints[i0 + k]] += reals[r0 + k] * u[k]
    i0 = ints[1 + _POINT_FORCE]
    r0 = ints[real_base + 1 + _POINT_FORCE_FRAME]
    for k in range((ints[2 + _POINT_FORCE] - i0) // 11):
        s = i0 + 11 * k
        p = ints[s]
        f = _load_vector(buffer, ints, reals, s + 1, s + 5, r0 + 9 * k, s0, x0)
        for d in range(3):
            if p + d < n:
                buffer[p + d] += f[d]
    i0 = ints[1 + _MOMENT]
    r0 = ints[real_base + 1 + _MOMENT_VALUE]
    for k in range((ints[2 + _MOMENT] - i0) // 10):
        s = i0 + 10 * k
        p = r0 + 18 * k
        mx, my, mz = _load_vector(buffer, ints, reals, s + 6, s, p + 9, s0, x0)
        for l in range(3):
            hl, tl = ints[s + 2 * l], ints[s + 2 * l + 1]
            bx = buffer[x0 + hl] - buffer[x0 + tl]
            by = buffer[x0 + hl + 1] - buffer[x0 + tl + 1]
            bz = buffer[x0 + hl + 2] - buffer[x0 + tl + 2]
            cx, cy, cz = my * bz - mz * by, mz * bx - mx * bz, mx * by - my * bx       # M × b_l
            for kk in range(3):
                g = 0.5 * reals[p + 3 * kk + l]
                hk, tk = ints[s + 2 * kk], ints[s + 2 * kk + 1]
                for d, c in ((0, cx), (1, cy), (2, cz)):
                    if hk + d < n:
                        buffer[hk + d] += g * c
                    if tk + d < n:
                        buffer[tk + d] -= g * c
    i0 = ints[1 + _SPRING]
    r0 = ints[real_base + 1 + _SPRING_PARAMETERS]
    for k in range((ints[2 + _SPRING] - i0) // 2):
        i, j = ints[i0 + 2 * k], ints[i0 + 2 * k + 1]
        dx = buffer[x0 + j] - buffer[x0 + i]
        dy = buffer[x0 + j + 1] - buffer[x0 + i + 1]
        dz = buffer[x0 + j + 2] - buffer[x0 + i + 2]
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        ex, ey, ez = dx / length, dy / length, dz / length
        rate = (ex * (buffer[v0 + j] - buffer[v0 + i]) + ey * (buffer[v0 + j + 1] - buffer[v0 + i + 1])
                + ez * (buffer[v0 + j + 2] - buffer[v0 + i + 2]))
        tension = reals[r0 + 3 * k] * (length - reals[r0 + 3 * k + 2]) + reals[r0 + 3 * k + 1] * rate
        for d, e in ((0, ex), (1, ey), (2, ez)):
            if i + d < n:
                buffer[i + d] += tension * e
            if j + d < n:
                buffer[j + d] -= tension * e
    i0 = ints[1 + _ROTATIONAL_SPRING]
    r0 = ints[real_base + 1 + _ROTATIONAL_SPRING_PARAMETERS]
    for k in range(ints[2 + _ROTATIONAL_SPRING] - i0):
        c = ints[i0 + k]
        buffer[c] -= reals[r0 + 3 * k] * (buffer[x0 + c] - reals[r0 + 3 * k + 2]) + reals[r0 + 3 * k + 1] * buffer[v0 + c]


@njit(cache=True, inline="always")
def _load_vector(buffer, ints, reals, functions, frame, inverse, s0, x0):
    """A force's or moment's vector at time t: the three time functions at ``ints[functions:]``
    (values in the scratch at ``s0``), along the ground axes; when ``ints[functions + 3]`` is 1,
    along the axes of the body whose basis pairs are at ``ints[frame:]``: X X₀⁻¹ f, X₀⁻¹ at
    ``reals[inverse:]``."""
    fx, fy, fz = buffer[s0 + 3 * ints[functions]], buffer[s0 + 3 * ints[functions + 1]], \
        buffer[s0 + 3 * ints[functions + 2]]
    if ints[functions + 3] == 0:
        return fx, fy, fz
    gx, gy, gz = 0.0, 0.0, 0.0
    for l in range(3):
        c = reals[inverse + 3 * l] * fx + reals[inverse + 3 * l + 1] * fy + reals[inverse + 3 * l + 2] * fz
        b = _triple_at(buffer, x0, ints[frame + 2 * l], ints[frame + 2 * l + 1])
        gx += c * b[0]
        gy += c * b[1]
        gz += c * b[2]
    return gx, gy, gz


@njit(cache=True, inline="always")
def _triple_at(buffer, base, head, tail):
    """The 3-vector x[head] - x[tail] of the extended array at ``buffer[base:]``."""
    return (buffer[base + head] - buffer[base + tail], buffer[base + head + 1] - buffer[base + tail + 1],
            buffer[base + head + 2] - buffer[base + tail + 2])


@njit(cache=True, inline="always")
def _cross(a, b):
    return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


@njit(cache=True, inline="always")
def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, error_model="numpy")
def _angle_row(buffer, ints, s, n, a0, g0, x0, v0, row):
    """Row ``row`` of an angle coordinate θ from r to v about the axis a (module docstring):
    Φ = cos θ T - sin θ D, T = (r × v)·a, D = r·v; its Jacobian and γ = -(Ȧ q̇)."""
    rh, rt, vh, vt, ah, at, c = ints[s], ints[s + 1], ints[s + 2], ints[s + 3], ints[s + 4], ints[s + 5], ints[s + 6]
    r, v, a = _triple_at(buffer, x0, rh, rt), _triple_at(buffer, x0, vh, vt), _triple_at(buffer, x0, ah, at)
    dr, dv, da = _triple_at(buffer, v0, rh, rt), _triple_at(buffer, v0, vh, vt), _triple_at(buffer, v0, ah, at)
    angle, rate = buffer[x0 + c], buffer[v0 + c]
    co, si = math.cos(angle), math.sin(angle)
    r_v, v_a, a_r = _cross(r, v), _cross(v, a), _cross(a, r)
    T, D = _dot3(r_v, a), _dot3(r, v)
    buffer[n + row] = co * T - si * D
    for d in range(3):
        for head, tail, value in ((rh, rt, co * v_a[d] - si * v[d]), (vh, vt, co * a_r[d] - si * r[d]),
                                  (ah, at, co * r_v[d])):
            _add(buffer, a0, row, head + d, value, n)
            _add(buffer, a0, row, tail + d, -value, n)
    _add(buffer, a0, row, c, -si * T - co * D, n)
    T_rate = _dot3(_cross(dr, v), a) + _dot3(_cross(r, dv), a) + _dot3(r_v, da)
    D_rate = _dot3(dr, v) + _dot3(r, dv)
    T_quadratic = 2.0 * (_dot3(_cross(dr, dv), a) + _dot3(_cross(dr, v), da) + _dot3(_cross(r, dv), da))
    D_quadratic = 2.0 * _dot3(dr, dv)
    buffer[g0 + row] = -(-co * rate * rate * T - 2.0 * si * rate * T_rate + co * T_quadratic
                         + si * rate * rate * D - 2.0 * co * rate * D_rate - si * D_quadratic)


@dataclass(frozen=True)
class FreeBody:
    """A body's (or rod's) own share of a spatial model: its elements (``slots``: their indices
    in the extended coordinates x = (q, constants), three each), its element mass matrix and
    gravity force over them (3k×3k, 3k; with the rigidity mass of its further elements) and the
    constraint rows it owns (its rigid-body and further-element rows).  Its free-body equation
    M_e ẍ_e = Q_e + F_e - Σ_own A_rᵀ λ_r gives the forces F_e that the rest of the mechanism
    applies at its elements (:mod:`cmbs.inverse.spatial_reactions`)."""

    name: str
    elements: tuple[str, ...]
    kinds: tuple[str, ...]
    slots: np.ndarray
    mass: np.ndarray
    gravity: np.ndarray
    rows: np.ndarray


class SpatialKernel(NamedTuple):
    """A spatial natural-coordinate model as the compiled loops take it: its index and parameter
    arrays and its constant mass matrix."""

    ints: np.ndarray
    reals: np.ndarray
    mass: np.ndarray


@njit(cache=True, inline="always")
def _evaluate_spatial(kernel, q, qd, t, u, buffer):
    """:func:`_evaluate` for a :class:`SpatialKernel`."""
    _evaluate(q, qd, t, u, kernel.ints, kernel.reals, buffer)


SpatialKernel.evaluate = staticmethod(_evaluate_spatial)
