"""Planar models in natural coordinates (thesis §3.3-3.4; García de Jalón & Bayo 1994).

Coordinates are the Cartesian positions (x, z) of the moving basic points, plus optional angle
and distance coordinates.  Fixed points are constants, not coordinates.  Every constraint is one
of six kinds, each evaluated for all its rows at once by one compiled kernel:

============  ==============================================  =================================
kind          Φ                                               γ = -(Ȧq̇) - Φ_tt
============  ==============================================  =================================
rigid         d·d - L²,  d = r_j - r_i                        -2 ḋ·ḋ
distance      d·d - s²                                        -2 ḋ·ḋ + 2 ṡ²
angle         cos φ (u×v) - sin φ (u·v)                       see :func:`_angle_rows`
parallel      u×v  (point on a line, rotation lock)           -2 u̇×v̇
body point    r_k - r_i - ξ d - η R90 d,  d = r_j - r_i       0   (linear in q: constant A)
driver        q_c - f(t)                                      f''(t)   (Φ_t = -f'(t))
============  ==============================================  =================================

The angle constraint combines the sine (cross-product) and cosine (dot-product) forms of the
thesis: on rigid vectors it equals |u||v| sin(θ - φ), θ the actual angle from u to v, so its
derivative with respect to φ is -|u||v| cos(θ - φ) = -|u||v| at the solution — well conditioned
at every angle, where the pure sine form fails at ±90° and the cosine form at 0° and 180°.

Element mass matrix of a segment from point i to j (velocities ẋ_i, ż_i, ẋ_j, ż_j), local COM
(x̄_G, z̄_G) with x̄ from i towards j, mass m, inertia I_i about i, a = m x̄_G/L, b = m z̄_G/L,
c = I_i/L² (thesis eq. 3.30)::

    [ m-2a+c    0       a-c     -b  ]
    [ 0         m-2a+c  b        a-c]
    [ a-c       b       c        0  ]
    [ -b        a-c     0        c  ]

Derivation (thesis eq. 3.26-3.28, after García de Jalón & Bayo 1994): a material point at
(x̄, z̄) in the segment frame is at r = r_i + (x̄/L) d + (z̄/L) R90 d, so
ṙ = ṙ_i + (x̄/L) ḋ + (z̄/L) R90 ḋ and, since R90 ḋ ⊥ ḋ and |R90 ḋ| = |ḋ|,
T = ½∫ṙ·ṙ dm = ½[m ṙ_i·ṙ_i + 2a ṙ_i·ḋ + 2b ṙ_i·R90 ḋ + c ḋ·ḋ]; with ḋ = ṙ_j - ṙ_i that is the
matrix above (the ±b entries come from ṙ_i·R90 ṙ_j = ż_i ẋ_j - ẋ_i ż_j).

**Bodies** with more points (:meth:`NaturalModelBuilder.add_body`, points i, j, k, ...) are a
segment i→j (frame, rigidity row, element mass matrix) whose further points k have constant
local coordinates (ξ, η) = (along, across)/L: two *body point* rows each,
r_k = r_i + ξ d + η R90 d = C(ξ, η) (r_i, r_j) with C of :func:`point_map`.  The points k carry
no mass of their own; so that M stays positive definite (the projection and Udwadia-Kalaba
formulations need M⁻¹), the body adds μ |ṙ_k - C ṙ_e|² (μ = the body's mass) per point k:
the term B_kᵀ μ B_k with B_k the Jacobian of k's body point rows.  It vanishes on every motion
that keeps the body rigid (B_k q̇ = 0), so T is unchanged there, and it changes no solution of
M q̈ + Aᵀλ = Q, A q̈ = γ: its force μ B_kᵀ B_k q̈ is zero because B_k q̈ = γ_k = 0.

**Loads on segments and bodies.**  A force F at the point (x̄, z̄) of a segment adds Cᵀ F to
(x_i, z_i, x_j, z_j) (thesis eq. 3.32-3.35); in the segment frame ('body') its ground components
are F = F_x̄ e + F_z̄ R90 e, e = d/|d| (a follower force).  A moment τ on a segment is the
generalized force of its virtual work τ δθ with θ = atan2(d_z, d_x):
δθ = (d_x δd_z - d_z δd_x)/|d|², so Q = τ/|d|² (d_z, -d_x, -d_z, d_x).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Mapping, NamedTuple, Sequence

from cmbs.jit import borrow, njit
import numpy as np

from cmbs.errors import ModelError, did_you_mean
from cmbs.model.drivers import TimeFunction, TimeFunctionPack, as_time_function, driver_rows, is_constant, \
    packed_time_functions
from cmbs.model.limits import MAX_MAGNITUDE, MIN_LENGTH_RATIO
from cmbs.model.model import Model, Terms
from cmbs.model.packing import pack, unpack

# int sections of the packed kernel data, in this order
(_RIGID, _DISTANCE, _ANGLE, _PARALLEL, _DRIVER, _POINT_FORCE, _TORQUE, _SPRING, _ACTUATOR,
 _TF_TABLE, _TF_OPS, _BODY_POINT, _SEGMENT_FORCE, _MOMENT) = range(14)
# real sections
(_CONSTANTS, _LENGTH2, _Q_CONSTANT, _SPRING_PARAMETERS, _ACTUATOR_GAIN, _TF_REALS, _BODY_POINT_LOCAL,
 _SEGMENT_FORCE_AT) = range(8)
#: the kind of entry ("segment" or "body") of each builder section holding rigid bodies
_KIND = {"segments": "segment", "bodies": "body"}
#: frames of a segment force: components in the ground frame, or along (x̄, z̄) of the segment
FRAMES = ("ground", "body")


def element_mass_matrix(mass: float, length: float, com: tuple[float, float], inertia_com: float) -> np.ndarray:
    """4×4 mass matrix of a planar rigid segment in the velocities of its two points.

    ``com`` = (along, across) in the segment frame (origin at i, x̄ towards j); ``inertia_com``
    about the centre of mass; I_i = I_G + m(x̄_G² + z̄_G²) (parallel axes).
    """
    along, across = com
    inertia_i = inertia_com + mass * (along**2 + across**2)
    a = mass * along / length
    b = mass * across / length
    c = inertia_i / length**2
    return np.array([
        [mass - 2 * a + c, 0.0, a - c, -b],
        [0.0, mass - 2 * a + c, b, a - c],
        [a - c, b, c, 0.0],
        [-b, a - c, 0.0, c],
    ])


def point_map(length: float, local: tuple[float, float]) -> np.ndarray:
    """2×4 matrix C with r_P = C (x_i, z_i, x_j, z_j) for the point at ``local`` (along, across).

    r_P = r_i + (ξ/L)(r_j - r_i) + (η/L) R90 (r_j - r_i), R90 the +90° rotation (thesis eq. 3.32).
    """
    xi, eta = local[0] / length, local[1] / length
    return np.array([
        [1.0 - xi, eta, xi, -eta],
        [-eta, 1.0 - xi, eta, xi],
    ])


@dataclass
class _Point:
    name: str
    x: float
    z: float
    fixed: bool
    mass: float


@dataclass
class _Segment:
    name: str
    i: str
    j: str
    mass: float
    length: float | None
    com: tuple[float, float]
    inertia: float
    #: a body's further points (rigidly attached) and the local positions given for some of them
    extra: tuple[str, ...] = ()
    local: dict[str, tuple[float, float]] = field(default_factory=dict)
    section: str = "segments"


@dataclass
class NaturalModelBuilder:
    """Build a planar natural-coordinate :class:`~cmbs.model.model.Model` entry by entry.

    Every ``add_*`` method validates its entry and raises :class:`~cmbs.errors.ModelError`
    naming it; :meth:`build` checks the whole (unknown names, massless points) and packs the
    index arrays for the compiled kernel.

    Examples
    --------
    >>> b = NaturalModelBuilder("pendulum")
    >>> b.add_point("O", 0.0, 0.0, fixed=True)
    >>> b.add_point("P", 1.0, 0.0)
    >>> b.add_segment("rod", "O", "P", mass=1.0, com=(0.5, 0.0), inertia=1 / 12)
    >>> model = b.build()
    """

    name: str
    gravity: tuple[float, float] = (0.0, -9.81)
    description: str = ""
    source: str = ""
    _points: dict[str, _Point] = field(default_factory=dict)
    _segments: dict[str, _Segment] = field(default_factory=dict)
    _angles: dict[str, tuple] = field(default_factory=dict)
    _distances: dict[str, tuple] = field(default_factory=dict)
    _sliders: dict[str, tuple] = field(default_factory=dict)
    _drivers: dict[str, tuple[str, TimeFunction]] = field(default_factory=dict)
    _point_forces: dict[str, tuple] = field(default_factory=dict)
    _torques: dict[str, tuple[str, TimeFunction]] = field(default_factory=dict)
    _segment_forces: dict[str, tuple] = field(default_factory=dict)
    _moments: dict[str, tuple[str, TimeFunction]] = field(default_factory=dict)
    _springs: dict[str, tuple] = field(default_factory=dict)
    _actuators: dict[str, tuple[str, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.gravity = _pair(self.gravity, "model", "gravity")

    # ------------------------------------------------------------------ entries
    def _new_name(self, table: dict, section: str, name: str) -> str:
        if not isinstance(name, str) or not name:
            raise ModelError(f"name must be a non-empty string, got {name!r}", entry=section)
        if name in table:
            raise ModelError(f"duplicate name {name!r}", entry=f"{section}.{name}")
        return name

    def add_point(self, name: str, x: float, z: float, *, fixed: bool = False, mass: float = 0.0) -> None:
        """A basic point at (x, z): a ground point if ``fixed``, else its coordinates join q.

        For moving points (x, z) is only the initial guess; assembly makes it consistent.
        ``mass`` adds a point mass (e.g. a slider block).
        """
        self._new_name(self._points, "points", name)
        entry = f"points.{name}"
        x, z = _finite(x, entry, "x"), _finite(z, entry, "z")
        if _finite(mass, entry, "mass") < 0:
            raise ModelError(f"mass must be >= 0, got {mass}", entry=entry)
        if fixed and mass:
            raise ModelError("a fixed point cannot carry mass", entry=entry)
        self._points[name] = _Point(name, x, z, bool(fixed), float(mass))

    def add_segment(self, name: str, i: str, j: str, *, mass: float, com: tuple[float, float] | None = None,
                    inertia: float | None = None, length: float | None = None, _section: str = "segments") -> None:
        """A rigid segment from point ``i`` to point ``j`` (adds Φ = |r_j - r_i|² - L² = 0).

        ``com`` (along, across) in the segment frame and ``inertia`` about the COM are required
        when ``mass > 0``.  ``length`` defaults to the distance between the initial points.
        """
        self._new_name(self._segments, _section, name)
        entry = f"{_section}.{name}"
        mass = _finite(mass, entry, "mass")
        if mass < 0:
            raise ModelError(f"mass must be >= 0, got {mass}", entry=entry)
        if i == j:
            raise ModelError(f"both ends are point {i!r}", entry=entry)
        if mass > 0 and (com is None or inertia is None):
            raise ModelError(f"a {_KIND[_section]} with mass needs 'com' (along, across) and 'inertia' (about the COM)",
                             entry=entry)
        com = (0.0, 0.0) if com is None else _pair(com, entry, "com")
        inertia = 0.0 if inertia is None else _finite(inertia, entry, "inertia")
        if inertia < 0:
            raise ModelError(f"inertia must be >= 0, got {inertia}", entry=entry)
        if length is not None and _finite(length, entry, "length") <= 0:
            raise ModelError(f"length must be > 0, got {length}", entry=entry)
        self._segments[name] = _Segment(name, i, j, mass, None if length is None else float(length), com, inertia,
                                        section=_section)

    def add_body(self, name: str, points: Sequence[str], *, mass: float, com: tuple[float, float] | None = None,
                 inertia: float | None = None, length: float | None = None,
                 local: Mapping[str, tuple[float, float]] | None = None) -> None:
        """A rigid body through two or more points: one mass, centre of mass and inertia.

        The first two points I, J define the body frame and the rigidity row, as for a segment
        (``com``, ``inertia``, ``length`` as in :meth:`add_segment`); every further point K keeps
        the local position (along, across) it has in that frame: given in ``local`` ({K: (along,
        across)} in metres), else that of the initial positions.  A body is named like a
        segment, so angles, sliders, forces and moments take its name wherever a segment's.
        """
        entry = f"bodies.{name}"
        if isinstance(name, str) and name in self._segments:
            raise ModelError(f"name {name!r} is already a {_KIND[self._segments[name].section]}", entry=entry)
        if isinstance(points, str) or not isinstance(points, (list, tuple)) or not all(
                isinstance(p, str) for p in points):
            raise ModelError(f"points must be a list of point names, got {points!r}", entry=entry)
        if len(points) < 2:
            raise ModelError(f"a body needs at least two points (its frame), got {list(points)!r}", entry=entry)
        repeated = sorted({p for p in points if list(points).count(p) > 1})
        if repeated:
            raise ModelError(f"point(s) {', '.join(map(repr, repeated))} listed twice in {list(points)!r}",
                             entry=entry)
        given = {} if local is None else dict(local)
        misplaced = sorted(set(given) - set(points[2:]))
        if misplaced:
            raise ModelError(f"local is for the body's further points ({', '.join(points[2:]) or 'none'}), "
                             f"not {', '.join(map(repr, misplaced))}", entry=entry)
        given = {point: _pair(value, entry, f"local.{point}") for point, value in given.items()}
        self.add_segment(name, points[0], points[1], mass=mass, com=com, inertia=inertia, length=length,
                         _section="bodies")
        body = self._segments[name]
        body.extra, body.local = tuple(points[2:]), given

    def add_angle(self, name: str, *, segment: str | tuple[str, str] | None = None,
                  from_segment: str | tuple[str, str] | None = None,
                  to_segment: str | tuple[str, str] | None = None, initial: float | None = None) -> None:
        """An angle coordinate, counter-clockwise positive.

        Absolute: ``segment`` measured from the x axis.  Relative: from the direction of
        ``from_segment`` to that of ``to_segment``.  Each direction is a segment name (from its
        first point to its second) or a pair of point names ``(a, b)`` meaning r_b - r_a, so that
        e.g. a hip angle can be measured from the trunk's downward direction to the thigh.
        ``initial`` defaults to the angle of the initial point positions.
        """
        self._new_name(self._angles, "angles", name)
        entry = f"angles.{name}"
        if (segment is None) == (from_segment is None and to_segment is None):
            raise ModelError("give either 'segment' (absolute) or 'from' and 'to' (relative)", entry=entry)
        if segment is None and (from_segment is None or to_segment is None):
            raise ModelError("a relative angle needs both 'from' and 'to'", entry=entry)
        for label, spec in (("segment", segment), ("from", from_segment), ("to", to_segment)):
            if spec is not None and not isinstance(spec, str) and not (
                    isinstance(spec, (tuple, list)) and len(spec) == 2 and all(isinstance(p, str) for p in spec)):
                raise ModelError(f"{label} must be a segment name or a pair of point names, got {spec!r}",
                                 entry=entry)
        if initial is not None:
            initial = _finite(initial, entry, "initial")
        def as_spec(spec):
            return tuple(spec) if isinstance(spec, list) else spec

        u, v = (None, as_spec(segment)) if segment is not None else (as_spec(from_segment), as_spec(to_segment))
        self._angles[name] = (u, v, initial)

    def add_distance(self, name: str, i: str, j: str, *, initial: float | None = None) -> None:
        """A distance coordinate s between points i and j (Φ = |r_j - r_i|² - s² = 0)."""
        self._new_name(self._distances, "distances", name)
        if initial is not None:
            initial = _finite(initial, f"distances.{name}", "initial")
        self._distances[name] = (i, j, initial)

    def add_slider(self, name: str, *, point: str, line: tuple[str, str] | None = None,
                   segment: str | None = None, through: tuple[float, float] | None = None,
                   direction: tuple[float, float] | None = None, lock: str | None = None) -> None:
        """Prismatic joint: ``point`` stays on a line, given by two points (``line``), a segment
        (``segment``, the line through its ends) or a ground line (``through`` and
        ``direction``).  With ``lock`` the named segment also stays parallel to the line
        (no rotation of the slider block)."""
        self._new_name(self._sliders, "sliders", name)
        entry = f"sliders.{name}"
        given = [line is not None, segment is not None, through is not None or direction is not None]
        if sum(given) != 1:
            raise ModelError("give exactly one of 'line' (two points), 'segment', or 'through' and 'direction'",
                             entry=entry)
        if through is not None or direction is not None:
            if through is None or direction is None:
                raise ModelError("a ground line needs both 'through' and 'direction'", entry=entry)
            through, direction = _pair(through, entry, "through"), _pair(direction, entry, "direction")
            if math.hypot(*direction) == 0:
                raise ModelError("direction must not be the zero vector", entry=entry)
        if line is not None:
            line = tuple(line)
            if len(line) != 2:
                raise ModelError(f"line must name two points, got {line!r}", entry=entry)
        self._sliders[name] = (point, line, segment, through, direction, lock)

    def add_driver(self, coordinate: str, function: object, *, name: str | None = None) -> None:
        """Rheonomic driver Φ = q_c - f(t) on coordinate ``coordinate`` (``"B.x"``, an angle or
        distance name); ``function``: number, expression string, table or callable of t."""
        name = name or f"drive {coordinate}"
        self._new_name(self._drivers, "drivers", name)
        try:
            self._drivers[name] = (coordinate, as_time_function(function))
        except ModelError as error:
            raise error.located(entry=f"drivers.{name}") from None

    def add_force(self, name: str, *, point: str | None = None, fx: object = 0.0, fz: object = 0.0,
                  segment: str | None = None, at: tuple[float, float] | None = None, frame: str = "ground") -> None:
        """A force (fx, fz) at a basic point ``point``, or at the point ``at`` = (along, across) of
        a segment or body ``segment``; components may vary with t.

        ``frame``: "ground" (fx, fz along the ground x, z axes) or, on a segment, "body" (along
        its x̄ axis from its first point to its second and its z̄ axis, a follower force).
        """
        if segment is not None or at is not None or frame != "ground":
            self._add_segment_force(name, point, segment, at, frame, fx, fz)
            return
        if name in self._segment_forces:
            raise ModelError(f"duplicate name {name!r}", entry=f"forces.{name}")
        if point is None:
            raise ModelError("give 'point' (a basic point), or 'segment' and 'at' (a point of a segment or body)",
                             entry=f"forces.{name}")
        self._new_name(self._point_forces, "forces", name)
        try:
            self._point_forces[name] = (point, as_time_function(fx), as_time_function(fz))
        except ModelError as error:
            raise error.located(entry=f"forces.{name}") from None

    def add_torque(self, name: str, *, angle: str, torque: object) -> None:
        """A torque acting on angle coordinate ``angle`` (generalized force +T on it): between the
        two segments of a relative angle, or between ground and the segment of an absolute one."""
        self._new_name(self._torques, "torques", name)
        try:
            self._torques[name] = (angle, as_time_function(torque))
        except ModelError as error:
            raise error.located(entry=f"torques.{name}") from None

    def _add_segment_force(self, name: str, point: str | None, segment: str | None,
                           at: tuple[float, float] | None, frame: str, fx: object, fz: object) -> None:
        """:meth:`add_force` at a point of a segment or body (checks the combination of keys)."""
        entry = f"forces.{name}"
        if name in self._point_forces:
            raise ModelError(f"duplicate name {name!r}", entry=entry)
        self._new_name(self._segment_forces, "forces", name)
        if point is not None and segment is None and at is None:
            raise ModelError(f"a force at a basic point is in the ground frame, got frame={frame!r}; for the "
                             "frame of a segment give 'segment' and 'at' instead of 'point'", entry=entry)
        if point is not None:
            raise ModelError("give either 'point' (a basic point, ground frame) or 'segment' and 'at', not both",
                             entry=entry)
        if not isinstance(segment, str) or at is None:
            raise ModelError(f"a force on a segment needs 'segment' (a name) and 'at' (along, across), got "
                             f"segment={segment!r}, at={at!r}", entry=entry)
        if frame not in FRAMES:
            raise ModelError(f"frame must be one of {', '.join(map(repr, FRAMES))}, got {frame!r}", entry=entry)
        at = _pair(at, entry, "at")
        try:
            self._segment_forces[name] = (segment, at, frame, as_time_function(fx), as_time_function(fz))
        except ModelError as error:
            raise error.located(entry=entry) from None

    def add_moment(self, name: str, *, segment: str, moment: object) -> None:
        """A moment (counter-clockwise positive) on segment or body ``segment``, from the ground:
        virtual work ``moment``·δθ, θ the direction of the segment (module docstring)."""
        self._new_name(self._moments, "moments", name)
        if not isinstance(segment, str):
            raise ModelError(f"segment must be a segment or body name, got {segment!r}", entry=f"moments.{name}")
        try:
            self._moments[name] = (segment, as_time_function(moment))
        except ModelError as error:
            raise error.located(entry=f"moments.{name}") from None

    def add_spring(self, name: str, i: str, j: str, *, stiffness: float, damping: float = 0.0,
                   rest_length: float | None = None) -> None:
        """Linear spring-damper between points: tension f = k(ℓ - ℓ0) + c ℓ̇ pulls them together.

        ``rest_length`` defaults to the initial distance."""
        self._new_name(self._springs, "springs", name)
        entry = f"springs.{name}"
        if i == j:
            raise ModelError(f"both ends are point {i!r}", entry=entry)
        values = [_finite(v, entry, label) for v, label in ((stiffness, "stiffness"), (damping, "damping"))]
        if values[0] < 0 or values[1] < 0:
            raise ModelError("stiffness and damping must be >= 0", entry=entry)
        if rest_length is not None and _finite(rest_length, entry, "rest_length") < 0:
            raise ModelError(f"rest_length must be >= 0, got {rest_length}", entry=entry)
        self._springs[name] = (i, j, values[0], values[1], rest_length)

    def add_actuator(self, name: str, *, coordinate: str, gain: float = 1.0) -> None:
        """Actuator input u_k entering as a generalized force gain·u_k on ``coordinate`` (a torque
        on an angle, a force along a distance or a point coordinate)."""
        self._new_name(self._actuators, "actuators", name)
        self._actuators[name] = (coordinate, _finite(gain, f"actuators.{name}", "gain"))

    # ------------------------------------------------------------------ build
    def build(self) -> Model:
        """Validate the whole model and return it (coordinates at the approximate initial guess)."""
        return _Assembler(self).model()


def _finite(value: object, entry: str, label: str) -> float:
    """``value`` as a float: a number, finite, of magnitude at most :data:`MAX_MAGNITUDE`."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise ModelError(f"{label} must be a number, got {value!r}", entry=entry)
    if not math.isfinite(float(value)):
        raise ModelError(f"{label} must be finite, got {value!r}", entry=entry)
    if abs(float(value)) > MAX_MAGNITUDE:
        raise ModelError(f"{label} = {float(value):g} is out of range: |{label}| must be <= {MAX_MAGNITUDE:g}",
                         entry=entry)
    return float(value)


def _check_length(length: float, size: float, entry: str, what: str) -> None:
    """A length at least :data:`MIN_LENGTH_RATIO` of ``size`` (the model size, at least 1 m)."""
    if length < MIN_LENGTH_RATIO * size:
        raise ModelError(f"{what} {length:g} is below {MIN_LENGTH_RATIO:g} of the model size {size:g} (the largest "
                         "coordinate or given length, at least 1): the points are (nearly) coincident", entry=entry)


def _pair(value: object, entry: str, label: str) -> tuple[float, float]:
    if not isinstance(value, (tuple, list, np.ndarray)) or len(value) != 2:
        raise ModelError(f"{label} must be a pair of numbers, got {value!r}", entry=entry)
    return _finite(value[0], entry, label), _finite(value[1], entry, label)


class _Assembler:
    """Turns a builder into index arrays (extended coordinates: q followed by constants)."""

    def __init__(self, builder: NaturalModelBuilder):
        self.b = builder
        self.names: list[str] = []
        self.kinds: list[str] = []
        self.q0: list[float] = []
        self.constants: list[float] = []
        self.constant_slot: dict[float, int] = {}
        self.point_index: dict[str, tuple[int, int]] = {}
        self.coordinate_of: dict[str, int] = {}
        self._coordinates()

    # extended index of a constant value (fixed point coordinate, reference vector)
    def _constant(self, value: float) -> int:
        if value not in self.constant_slot:
            self.constant_slot[value] = len(self.constants)
            self.constants.append(value)
        return -1 - self.constant_slot[value]  # resolved to n + slot once n is known

    def _coordinates(self) -> None:
        for point in self.b._points.values():
            if point.fixed:
                self.point_index[point.name] = (self._constant(point.x), self._constant(point.z))
            else:
                for axis, value in (("x", point.x), ("z", point.z)):
                    self.coordinate_of[f"{point.name}.{axis}"] = len(self.names)
                    self.names.append(f"{point.name}.{axis}")
                    self.kinds.append(axis)
                    self.q0.append(value)
                self.point_index[point.name] = (len(self.names) - 2, len(self.names) - 1)
        for name, (i, j, initial) in self.b._distances.items():
            entry = f"distances.{name}"
            self._check_coordinate_name(name, entry)
            start, end = self._position(i, entry), self._position(j, entry)
            self.coordinate_of[name] = len(self.names)
            self.names.append(name)
            self.kinds.append("distance")
            self.q0.append(initial if initial is not None else float(np.hypot(*(end - start))))
        for name, (u_spec, v_spec, initial) in self.b._angles.items():
            entry = f"angles.{name}"
            self._check_coordinate_name(name, entry)
            u = self._direction(u_spec, entry)[1]
            v = self._direction(v_spec, entry)[1]
            actual = math.atan2(u[0] * v[1] - u[1] * v[0], u @ v)
            self.coordinate_of[name] = len(self.names)
            self.names.append(name)
            self.kinds.append("angle")
            self.q0.append(initial if initial is not None else actual)

    def _size(self) -> float:
        """The model size: the largest point coordinate or given segment length, at least 1 (m)."""
        return max([1.0, *(max(abs(p.x), abs(p.z)) for p in self.b._points.values()),
                    *(s.length for s in self.b._segments.values() if s.length is not None)])

    def _work_sources(self) -> tuple[str, ...]:
        """The forces and torques that are not constant zero, and the springs with damping."""
        def nonzero(function: TimeFunction) -> bool:
            return not (is_constant(function) and function.value == 0)

        b = self.b
        return (tuple(f"force {name!r}" for name, (_, fx, fz) in b._point_forces.items() if nonzero(fx) or nonzero(fz))
                + tuple(f"torque {name!r}" for name, (_, torque) in b._torques.items() if nonzero(torque))
                + tuple(f"force {name!r}" for name, (*_, fx, fz) in b._segment_forces.items()
                        if nonzero(fx) or nonzero(fz))
                + tuple(f"moment {name!r}" for name, (_, moment) in b._moments.items() if nonzero(moment))
                + tuple(f"damper {name!r}" for name, spring in b._springs.items() if spring[3] > 0))

    def _direction(self, spec: str | tuple[str, str] | None, entry: str) -> tuple[list[int], np.ndarray]:
        """Extended indices (x_a, z_a, x_b, z_b) and initial value of a direction r_b - r_a:
        a segment name, a pair of points, or None for the x axis."""
        if spec is None:
            return [self._constant(0.0), self._constant(0.0), self._constant(1.0), self._constant(0.0)], \
                np.array([1.0, 0.0])
        first, second = (self._segment(spec, entry).i, self._segment(spec, entry).j) if isinstance(spec, str) \
            else spec
        vector = self._position(second, entry) - self._position(first, entry)
        return self._xz(first, entry) + self._xz(second, entry), vector

    def _check_coordinate_name(self, name: str, entry: str) -> None:
        if name in self.coordinate_of:
            raise ModelError(f"name {name!r} is already a coordinate", entry=entry)

    def _point(self, name: str, entry: str) -> _Point:
        if name not in self.b._points:
            known = ", ".join(self.b._points) or "none"
            raise ModelError(f"unknown point {name!r}{did_you_mean(name, self.b._points)} (points: {known})",
                             entry=entry)
        return self.b._points[name]

    def _position(self, name: str, entry: str) -> np.ndarray:
        point = self._point(name, entry)
        return np.array([point.x, point.z])

    def _segment(self, name: str, entry: str) -> _Segment:
        if name not in self.b._segments:
            known = ", ".join(self.b._segments) or "none"
            raise ModelError(f"unknown segment {name!r}{did_you_mean(name, self.b._segments)} (segments: {known})",
                             entry=entry)
        return self.b._segments[name]

    def _coordinate(self, name: str, entry: str) -> int:
        if name not in self.coordinate_of:
            known = ", ".join(self.names)
            raise ModelError(f"unknown coordinate {name!r} (coordinates: {known})", entry=entry)
        return self.coordinate_of[name]

    def _xz(self, point: str, entry: str) -> list[int]:
        self._point(point, entry)
        return list(self.point_index[point])

    def _resolve(self, indices: np.ndarray, n: int) -> np.ndarray:
        """Map negative placeholders of constants to n + slot."""
        indices = np.asarray(indices, dtype=np.int64)
        return np.where(indices < 0, n - 1 - indices, indices)

    def model(self) -> Model:
        b = self.b
        n = len(self.names)
        size = self._size()
        constraint_names: list[str] = []

        rigid, lengths2, lines = [], [], []
        point_order = list(b._points)
        for segment in b._segments.values():
            entry = f"{segment.section}.{segment.name}"
            start, end = self._position(segment.i, entry), self._position(segment.j, entry)
            length = segment.length if segment.length is not None else float(np.hypot(*(end - start)))
            if length <= 0:
                raise ModelError(f"its points {segment.i!r} and {segment.j!r} coincide: length is 0", entry=entry)
            _check_length(length, size, entry, "length")
            segment.length = length
            rigid.append(self._xz(segment.i, entry) + self._xz(segment.j, entry))
            lengths2.append(length**2)
            constraint_names.append(f"rigid {segment.name}")
            lines.extend(self._outline(segment, point_order, entry))

        distance_rows = []
        for name, (i, j, _) in b._distances.items():
            entry = f"distances.{name}"
            distance_rows.append(self._xz(i, entry) + self._xz(j, entry) + [self.coordinate_of[name]])
            constraint_names.append(f"distance {name}")

        angle_rows = []
        for name, (u_spec, v_spec, _) in b._angles.items():
            entry = f"angles.{name}"
            angle_rows.append(self._direction(u_spec, entry)[0] + self._direction(v_spec, entry)[0]
                              + [self.coordinate_of[name]])
            constraint_names.append(f"angle {name}")

        parallel_rows = []
        for name, (point, line, segment, through, direction, lock) in b._sliders.items():
            entry = f"sliders.{name}"
            if line is not None:
                line_points = self._xz(line[0], entry) + self._xz(line[1], entry)
                base = self._xz(line[0], entry)
            elif segment is not None:
                s = self._segment(segment, entry)
                line_points = self._xz(s.i, entry) + self._xz(s.j, entry)
                base = self._xz(s.i, entry)
            else:
                base = [self._constant(through[0]), self._constant(through[1])]
                tip = [self._constant(through[0] + direction[0]), self._constant(through[1] + direction[1])]
                line_points = base + tip
            parallel_rows.append(line_points + base + self._xz(point, entry))
            constraint_names.append(f"slider {name}")
            if lock is not None:
                s = self._segment(lock, entry)
                parallel_rows.append(line_points + self._xz(s.i, entry) + self._xz(s.j, entry))
                constraint_names.append(f"slider {name} lock")

        body_points = self._body_points(constraint_names)

        driver_rows, functions, labels = [], [], []
        for name, (coordinate, function) in b._drivers.items():
            driver_rows.append([self._coordinate(coordinate, f"drivers.{name}"), len(functions)])
            functions.append(function)
            labels.append(f"driver {name}")
            constraint_names.append(name)

        force_rows = []
        for name, (point, fx, fz) in b._point_forces.items():
            xz = self._xz(point, f"forces.{name}")
            force_rows.append(xz + [len(functions), len(functions) + 1])
            functions.extend([fx, fz])
            labels.extend([f"force {name} (fx)", f"force {name} (fz)"])

        segment_force_rows, segment_force_at, load_segments = [], [], []
        for name, (segment_name, at, frame, fx, fz) in b._segment_forces.items():
            entry = f"forces.{name}"
            segment = self._segment(segment_name, entry)
            segment_force_rows.append(self._xz(segment.i, entry) + self._xz(segment.j, entry)
                                      + [len(functions), len(functions) + 1, FRAMES.index(frame)])
            segment_force_at.append((at[0] / segment.length, at[1] / segment.length))
            load_segments.append(list(b._segments).index(segment.name))
            functions.extend([fx, fz])
            labels.extend([f"force {name} (fx)", f"force {name} (fz)"])

        moment_rows = []
        for name, (segment_name, moment) in b._moments.items():
            entry = f"moments.{name}"
            segment = self._segment(segment_name, entry)
            moment_rows.append(self._xz(segment.i, entry) + self._xz(segment.j, entry) + [len(functions)])
            load_segments.append(list(b._segments).index(segment.name))
            functions.append(moment)
            labels.append(f"moment {name}")

        torque_rows = []
        for name, (angle, torque) in b._torques.items():
            entry = f"torques.{name}"
            if angle not in b._angles:
                raise ModelError(f"unknown angle {angle!r} (angles: {', '.join(b._angles) or 'none'})", entry=entry)
            torque_rows.append([self.coordinate_of[angle], len(functions)])
            functions.append(torque)
            labels.append(f"torque {name}")

        spring_rows, spring_parameters = [], []
        for name, (i, j, stiffness, damping, rest) in b._springs.items():
            entry = f"springs.{name}"
            spring_rows.append(self._xz(i, entry) + self._xz(j, entry))
            initial = float(np.hypot(*(self._position(j, entry) - self._position(i, entry))))
            if initial == 0:
                raise ModelError(f"its points {i!r} and {j!r} coincide at their initial positions: the direction "
                                 "of the spring force is undefined", entry=entry)
            _check_length(initial, size, entry, "initial length")
            rest = rest if rest is not None else initial
            spring_parameters.append([stiffness, damping, rest])

        actuator_rows, gains = [], []
        for name, (coordinate, gain) in b._actuators.items():
            actuator_rows.append([self._coordinate(coordinate, f"actuators.{name}")])
            gains.append(gain)

        if n == 0:
            raise ModelError("the model has no coordinates: every point is fixed (give a moving point)",
                             entry="points")
        n_ext = n + len(self.constants)
        mass_ext = np.zeros((n_ext, n_ext))
        gravity_ext = np.zeros(n_ext)
        g = np.array(b.gravity, dtype=float)
        segment_masses = []
        segment_data = []
        for k, segment in enumerate(b._segments.values()):
            idx = self._resolve(rigid[k], n)
            element = element_mass_matrix(segment.mass, segment.length, segment.com, segment.inertia)
            element_gravity = point_map(segment.length, segment.com).T @ (segment.mass * g)
            mass_ext[np.ix_(idx, idx)] += element
            gravity_ext[idx] += element_gravity
            segment_masses.append((segment.name, segment.mass))
            element.setflags(write=False)
            element_gravity.setflags(write=False)
            idx.setflags(write=False)
            segment_data.append(SegmentData(
                name=segment.name, points=(segment.i, segment.j), indices=idx, mass_matrix=element,
                gravity=element_gravity, rigid_row=k, mass=segment.mass, length=segment.length,
                com=segment.com, inertia=segment.inertia, kind=_KIND[segment.section],
                attached=tuple(BodyPoint(p.point, p.local, p.row) for p in body_points if p.body is segment)))
        for point in body_points:
            idx = self._resolve(point.indices, n)
            mass_ext[np.ix_(idx, idx)] += further_point_mass(point.body.mass, point.body.length, point.local)
        for point in b._points.values():
            if point.mass:
                idx = self._resolve(self.point_index[point.name], n)
                mass_ext[idx, idx] += point.mass
                gravity_ext[idx] += point.mass * g
                segment_masses.append((point.name, point.mass))
        mass = mass_ext[:n, :n].copy()
        self._check_mass(mass)
        mass.setflags(write=False)

        tf = TimeFunctionPack.build(functions, labels)
        def resolve(rows, width):
            return self._resolve(np.array(rows, dtype=np.int64).reshape(-1, width), n)

        ints, reals = pack(
            [resolve(rigid, 4), resolve(distance_rows, 5), resolve(angle_rows, 9), resolve(parallel_rows, 8),
             np.array(driver_rows, dtype=np.int64).reshape(-1, 2), _force_rows(force_rows, n, self),
             np.array(torque_rows, dtype=np.int64).reshape(-1, 2),
             resolve(spring_rows, 4), np.array(actuator_rows, dtype=np.int64).reshape(-1),
             tf.table, tf.ops, resolve([p.indices for p in body_points], 6), resolve(segment_force_rows, 7),
             resolve(moment_rows, 5)],
            [np.array(self.constants), np.array(lengths2), gravity_ext[:n].copy(),
             np.array(spring_parameters).reshape(-1, 3), np.array(gains), tf.reals,
             np.array([(p.local[0] / p.body.length, p.local[1] / p.body.length) for p in body_points]).reshape(-1, 2),
             np.array(segment_force_at).reshape(-1, 2)])

        m = len(constraint_names)
        drivers = np.zeros(m, dtype=bool)
        drivers[m - len(driver_rows):] = True
        point_xz = np.array([self._resolve(self.point_index[p], n) for p in point_order], dtype=np.int64).reshape(-1, 2)
        equations = NaturalEquations(
            n=n, m=m, ints=ints, reals=reals, mass=mass, time_functions=tf,
            constants=np.array(self.constants), gravity_ext=gravity_ext,
            springs=(resolve(spring_rows, 4), np.array(spring_parameters).reshape(-1, 3)),
            point_xz=point_xz, segments=tuple(segment_data), work_sources=self._work_sources(),
            steady_drivers=frozenset(name for name, (_, function) in b._drivers.items() if is_constant(function)),
            load_segments=tuple(load_segments))
        return Model(
            name=b.name, coordinate_names=tuple(self.names), coordinate_kinds=tuple(self.kinds),
            constraint_names=tuple(constraint_names), drivers=drivers, actuator_names=tuple(b._actuators),
            q0=np.array(self.q0), qd0=np.zeros(n), point_names=tuple(point_order), lines=tuple(lines),
            equations=equations, description=b.description, source=b.source,
            parameters={"gravity": tuple(b.gravity)}, constant_mass=True,
            segment_masses=tuple(segment_masses))

    def _outline(self, segment: _Segment, point_order: list[str], entry: str) -> list[tuple[int, int]]:
        """The drawn edges: I-J of a segment, the closed polygon I, J, K, ... of a larger body."""
        corners = [point_order.index(self._point(p, entry).name) for p in (segment.i, segment.j, *segment.extra)]
        return list(zip(corners, corners[1:] + corners[:1])) if segment.extra else [(corners[0], corners[1])]

    def _body_points(self, constraint_names: list[str]) -> list[_BodyPointRows]:
        """The further points of every body, each with its two rows 'body NAME: K.x', 'body NAME:
        K.z' appended to ``constraint_names``.  A point's local position is the given one, else
        that of the initial positions in the frame of the body's first two points."""
        rows = []
        for body in self.b._segments.values():
            entry = f"{body.section}.{body.name}"
            start = self._position(body.i, entry)
            d = self._position(body.j, entry) - start
            drawn = float(np.hypot(*d))
            for point in body.extra:
                indices = self._xz(body.i, entry) + self._xz(body.j, entry) + self._xz(point, entry)
                if point in body.local:
                    local = body.local[point]
                elif drawn == 0:
                    raise ModelError(f"its points {body.i!r} and {body.j!r} are at the same initial position, so "
                                     f"the frame that places {point!r} is undefined: give local.{point}", entry=entry)
                else:
                    offset = self._position(point, entry) - start
                    local = (float(offset @ d) / drawn, float(d[0] * offset[1] - d[1] * offset[0]) / drawn)
                rows.append(_BodyPointRows(body, point, indices, local, len(constraint_names)))
                constraint_names.extend([f"body {body.name}: {point}.x", f"body {body.name}: {point}.z"])
        return rows

    def _check_mass(self, mass: np.ndarray) -> None:
        """M restricted to point coordinates must be positive definite (every point carries mass)."""
        point_coordinates = [k for k, kind in enumerate(self.kinds) if kind in ("x", "z")]
        block = mass[np.ix_(point_coordinates, point_coordinates)]
        if block.size == 0:
            return
        eigenvalues, vectors = np.linalg.eigh(block)
        scale = max(np.max(np.abs(eigenvalues)), 1.0)
        if eigenvalues[0] <= 1e-12 * scale:
            null = vectors[:, 0]
            involved = sorted({self.names[point_coordinates[k]].rsplit(".", 1)[0]
                               for k in np.flatnonzero(np.abs(null) > 1e-6)})
            raise ModelError(
                f"mass matrix is not positive definite (smallest eigenvalue {eigenvalues[0]:.3g}): "
                f"no mass moves with point(s) {', '.join(involved)}; give a segment there mass and inertia, "
                "or a point mass", entry=", ".join(f"points.{point}" for point in involved))


def _force_rows(rows: list, n: int, assembler: _Assembler) -> np.ndarray:
    """(k, 4): x index, z index (extended), time-function index of fx, of fz."""
    array = np.array(rows, dtype=np.int64).reshape(-1, 4)
    array[:, :2] = assembler._resolve(array[:, :2], n)
    return array


def further_point_mass(mass: float, length: float, local: tuple[float, float]) -> np.ndarray:
    """μ BᵀB (6×6, μ = ``mass``) in (x_i, z_i, x_j, z_j, x_k, z_k) for the body point rows
    B = [-C(ξ, η), I₂] of the point at ``local`` (along, across) of a body of ``length``: it keeps
    M positive definite without acting on any rigid motion (module docstring)."""
    B = np.hstack([-point_map(length, local), np.eye(2)])
    return mass * (B.T @ B)


@dataclass
class _BodyPointRows:
    """A further point of a body while assembling: extended indices (x_i, z_i, x_j, z_j, x_k,
    z_k, constants still as placeholders), local position (along, across) and its first row."""

    body: _Segment
    point: str
    indices: list[int]
    local: tuple[float, float]
    row: int


@dataclass(frozen=True)
class BodyPoint:
    """A further point of a body: its name, local position (along, across) in metres in the
    body frame, and ``row``, the first of its two body point rows (x, then z), whose multipliers
    λ are the force (x, z) that the rest of the mechanism applies to the body at the point."""

    name: str
    local: tuple[float, float]
    row: int


@dataclass(frozen=True)
class SegmentData:
    """One rigid segment as assembled (used e.g. by :mod:`cmbs.inverse.reactions`).

    ``indices``: the extended indices (x_i, z_i, x_j, z_j) of its two points (q followed by the
    constants, so fixed points have indices ≥ n); ``mass_matrix``: its 4×4 element mass matrix
    (module docstring); ``gravity``: its element gravity generalized force C_Gᵀ (m g), (4,);
    ``rigid_row``: the row of its rigidity constraint 'rigid NAME' (segments come first, in
    order); ``com`` (along, across) in the segment frame and ``inertia`` about the COM;
    ``kind`` "segment" or "body"; ``attached``: a body's further points (:class:`BodyPoint`).
    """

    name: str
    points: tuple[str, str]
    indices: np.ndarray
    mass_matrix: np.ndarray
    gravity: np.ndarray
    rigid_row: int
    mass: float
    length: float
    com: tuple[float, float]
    inertia: float
    kind: str = "segment"
    attached: tuple[BodyPoint, ...] = ()


@dataclass(frozen=True)
class NaturalEquations:
    """Compiled evaluator of a natural-coordinate model (see the module docstring)."""

    n: int
    m: int
    ints: np.ndarray
    reals: np.ndarray
    mass: np.ndarray
    time_functions: TimeFunctionPack
    constants: np.ndarray
    gravity_ext: np.ndarray
    springs: tuple[np.ndarray, np.ndarray]
    point_xz: np.ndarray
    segments: tuple[SegmentData, ...] = ()
    #: the dampers, forces and torques, by name (see :attr:`cmbs.model.model.Model.work_sources`)
    work_sources: tuple[str, ...] = ()
    #: the drivers of a constant, which hold their coordinate and do no work
    steady_drivers: frozenset[str] = frozenset()
    #: the index in ``segments`` of the segment each segment force, then each moment, acts on
    load_segments: tuple[int, ...] = ()

    @property
    def _scratch_size(self) -> int:
        """Time-function values and stack (3 per row), then the extended x and v of the kernel."""
        return 3 * (self.time_functions.count + self.time_functions.depth) + 2 * (self.n + self.constants.size)

    def new_terms(self) -> Terms:
        return Terms(self.n, self.m, constant_mass=self.mass, scratch=self._scratch_size)

    def without_drivers(self) -> "NaturalEquations":
        """The same equations with the driver rows (the last section of constraints) removed, and
        the time functions only they used no longer evaluated (:meth:`TimeFunctionPack.keeping`)."""
        int_sections, real_sections = unpack(self.ints, self.reals)
        drivers = int_sections[_DRIVER].size // 2
        int_sections[_DRIVER] = np.zeros(0, dtype=np.int64)
        used = set(int_sections[_POINT_FORCE].reshape(-1, 4)[:, 2:].ravel().tolist())
        used |= set(int_sections[_TORQUE][1::2].tolist())
        used |= set(int_sections[_SEGMENT_FORCE].reshape(-1, 7)[:, 4:6].ravel().tolist())
        used |= set(int_sections[_MOMENT].reshape(-1, 5)[:, 4].tolist())
        time_functions = self.time_functions.keeping(used)
        int_sections[_TF_TABLE] = time_functions.table.ravel() if used else np.zeros(0, dtype=np.int64)
        new_ints, new_reals = pack(int_sections, real_sections)
        return dataclasses.replace(self, m=self.m - drivers, ints=new_ints, reals=new_reals,
                                   time_functions=time_functions)

    def compiled_kernel(self) -> "NaturalKernel | None":
        """The model's data for the compiled loops, or None when a time function is a Python
        callable (the loops then cannot evaluate the terms alone)."""
        if self.time_functions.python:
            return None
        return NaturalKernel(self.ints, self.reals, np.ascontiguousarray(self.mass, dtype=float))

    def evaluate(self, q: np.ndarray, qd: np.ndarray, t: float, u: np.ndarray, terms: Terms) -> None:
        for k, function in self.time_functions.python:
            terms.scratch[3 * k:3 * k + 3] = function(t)
        _evaluate(q, qd, t, u, self.ints, self.reals, terms.buffer)

    def _extended(self, q: np.ndarray) -> np.ndarray:
        return np.concatenate([q, self.constants])

    def segment_loads(self, q: np.ndarray, t: float) -> np.ndarray:
        """(len(segments), 4): the generalized forces on each segment's (x_i, z_i, x_j, z_j) of the
        segment forces and moments it carries at (q, t) (module docstring: C(ξ, η)ᵀ F and
        τ/|d|² (d_z, -d_x, -d_z, d_x)), e.g. to tell them from the forces at its points."""
        x = self._extended(np.asarray(q, dtype=float))
        ints, real_base = self.ints, int(self.ints[0]) + 2
        forces = ints[ints[1 + _SEGMENT_FORCE]:ints[2 + _SEGMENT_FORCE]].reshape(-1, 7)
        moments = ints[ints[1 + _MOMENT]:ints[2 + _MOMENT]].reshape(-1, 5)
        at = self.reals[ints[real_base + 1 + _SEGMENT_FORCE_AT]:ints[real_base + 2 + _SEGMENT_FORCE_AT]].reshape(-1, 2)
        loads = np.zeros((len(self.segments), 4))
        value = [function(t)[0] for function in self.time_functions.functions]
        for segment, row, (xi, eta) in zip(self.load_segments, forces, at):
            force = np.array(_segment_force(x, *row[:4], value[row[4]], value[row[5]], row[6]))
            length = self.segments[segment].length
            loads[segment] += point_map(length, (xi * length, eta * length)).T @ force
        for segment, row in zip(self.load_segments[len(forces):], moments):
            d = x[row[2:4]] - x[row[0:2]]
            loads[segment] += value[row[4]] / (d @ d) * np.array([d[1], -d[0], -d[1], d[0]])
        return loads

    def kinetic_energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        return 0.5 * float(qd @ self.mass @ qd)

    def energy_parts(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """T and V at every row of q, q̇ (k, n), vectorised: T = ½ q̇ᵀ M q̇ (M constant) and V as
        in :meth:`potential_energy`."""
        q_ext = np.concatenate([q, np.broadcast_to(self.constants, (q.shape[0], self.constants.size))], axis=1)
        potential = -(q_ext @ self.gravity_ext)
        rows, parameters = self.springs
        if rows.size:
            d = q_ext[:, rows[:, 2:4]] - q_ext[:, rows[:, 0:2]]
            stretch = np.hypot(d[..., 0], d[..., 1]) - parameters[:, 2]
            potential += 0.5 * np.sum(parameters[:, 0] * stretch**2, axis=1)
        return 0.5 * np.sum((qd @ self.mass) * qd, axis=1), potential

    def potential_energy(self, q: np.ndarray) -> float:
        """V = -Σ m g·r_G (linear in q: -Q_gravityᵀ q_ext) + Σ ½ k (ℓ - ℓ0)²."""
        q_ext = self._extended(q)
        energy = -float(self.gravity_ext @ q_ext)
        rows, parameters = self.springs
        if rows.size:
            d = q_ext[rows[:, 2:4]] - q_ext[rows[:, 0:2]]
            stretch = np.hypot(d[:, 0], d[:, 1]) - parameters[:, 2]
            energy += float(0.5 * np.sum(parameters[:, 0] * stretch**2))
        return energy

    def point_positions(self, q: np.ndarray) -> np.ndarray:
        return self._extended(q)[self.point_xz]


@njit(cache=True, inline="always")
def _add(buffer, a0, row, column, value, n):
    """A[row, column] += value where A is row-major at ``buffer[a0:]`` (constant columns skipped)."""
    if column < n:
        buffer[a0 + row * n + column] += value


@njit(cache=True, inline="always")
def _vector_pair(ints, r, x, v):
    """The vectors u = j - i and w = l - k of an angle or parallel row whose point coordinates
    (x_i, z_i, x_j, z_j, x_k, z_k, x_l, z_l) are ``ints[r:r + 8]``, and their rates."""
    ux, uz = x[ints[r + 2]] - x[ints[r]], x[ints[r + 3]] - x[ints[r + 1]]
    wx, wz = x[ints[r + 6]] - x[ints[r + 4]], x[ints[r + 7]] - x[ints[r + 5]]
    dux, duz = v[ints[r + 2]] - v[ints[r]], v[ints[r + 3]] - v[ints[r + 1]]
    dwx, dwz = v[ints[r + 6]] - v[ints[r + 4]], v[ints[r + 7]] - v[ints[r + 5]]
    return ux, uz, wx, wz, dux, duz, dwx, dwz


@njit(cache=True, inline="always")
def layout(ints, n, size):
    """Where the kernel's data and outputs are, for n coordinates and a terms buffer of ``size``:
    (start of the real-section offsets in ``ints``, first constant in ``reals``, n_ext = n +
    constant point coordinates, m, and in the buffer the offsets of A, γ, Φ_t, the scratch's
    time functions and the extended x, v at its end)."""
    real_base = ints[0] + 2
    c0, c1 = ints[real_base + 1 + _CONSTANTS], ints[real_base + 2 + _CONSTANTS]
    n_ext = n + c1 - c0
    m = ((ints[2 + _RIGID] - ints[1 + _RIGID]) // 4 + (ints[2 + _DISTANCE] - ints[1 + _DISTANCE]) // 5
         + (ints[2 + _ANGLE] - ints[1 + _ANGLE]) // 9 + (ints[2 + _PARALLEL] - ints[1 + _PARALLEL]) // 8
         + (ints[2 + _BODY_POINT] - ints[1 + _BODY_POINT]) // 3 + (ints[2 + _DRIVER] - ints[1 + _DRIVER]) // 2)
    a0 = n + m
    g0 = a0 + m * n
    t0 = g0 + m
    s0 = t0 + m
    return real_base, c0, n_ext, m, a0, g0, t0, s0, size - 2 * n_ext


@njit(cache=True)
def _evaluate(q, qd, t, u, ints, reals, buffer):
    """Q, Φ, A, γ, Φ_t of a natural-coordinate model into ``buffer`` (layout of :class:`Terms`;
    its scratch holds the time-function rows, their stack, and the extended x = (q, constants),
    v = (q̇, 0), so a call allocates nothing).

    The kernel indexes ``ints``, ``reals`` and ``buffer`` by offsets rather than through array
    views, and borrows its arguments (:func:`cmbs.jit.borrow`; a call from Python passes them
    as they are): numba counts no reference for what it views or passes on."""
    q, qd, u, ints, reals, buffer = borrow((q, qd, u, ints, reals, buffer))
    n = q.shape[0]
    real_base, c0, n_ext, m, a0, g0, t0, s0, x0 = layout(ints, n, buffer.shape[0])
    v0 = x0 + n_ext
    for k in range(n):
        buffer[x0 + k] = q[k]
        buffer[v0 + k] = qd[k]
    for k in range(n, n_ext):
        buffer[x0 + k] = reals[c0 + k - n]
        buffer[v0 + k] = 0.0
    x = buffer[x0:v0]
    v = buffer[v0:v0 + n_ext]

    # time functions: (f, f', f'') rows at the scratch's start, then the expression stack
    packed_time_functions(ints, reals, _TF_TABLE, _TF_OPS, _TF_REALS, t, buffer, s0, x0)

    buffer[a0:g0] = 0.0                      # A (a slice assignment: numba makes it a memset, which
    buffer[t0:s0] = 0.0                      # an element loop is not: 7x slower for 200 links)
    row = 0
    i0 = ints[1 + _RIGID]
    l0 = ints[real_base + 1 + _LENGTH2]
    for k in range((ints[2 + _RIGID] - i0) // 4):
        xi, zi, xj, zj = ints[i0 + 4 * k], ints[i0 + 4 * k + 1], ints[i0 + 4 * k + 2], ints[i0 + 4 * k + 3]
        dx, dz = x[xj] - x[xi], x[zj] - x[zi]
        dvx, dvz = v[xj] - v[xi], v[zj] - v[zi]
        buffer[n + row] = dx * dx + dz * dz - reals[l0 + k]
        _add(buffer, a0, row, xi, -2.0 * dx, n)
        _add(buffer, a0, row, zi, -2.0 * dz, n)
        _add(buffer, a0, row, xj, 2.0 * dx, n)
        _add(buffer, a0, row, zj, 2.0 * dz, n)
        buffer[g0 + row] = -2.0 * (dvx * dvx + dvz * dvz)
        row += 1

    i0 = ints[1 + _DISTANCE]
    for k in range((ints[2 + _DISTANCE] - i0) // 5):
        xi, zi, xj, zj, s = (ints[i0 + 5 * k], ints[i0 + 5 * k + 1], ints[i0 + 5 * k + 2], ints[i0 + 5 * k + 3],
                             ints[i0 + 5 * k + 4])
        dx, dz = x[xj] - x[xi], x[zj] - x[zi]
        dvx, dvz = v[xj] - v[xi], v[zj] - v[zi]
        buffer[n + row] = dx * dx + dz * dz - x[s] * x[s]
        _add(buffer, a0, row, xi, -2.0 * dx, n)
        _add(buffer, a0, row, zi, -2.0 * dz, n)
        _add(buffer, a0, row, xj, 2.0 * dx, n)
        _add(buffer, a0, row, zj, 2.0 * dz, n)
        buffer[a0 + row * n + s] += -2.0 * x[s]
        buffer[g0 + row] = -2.0 * (dvx * dvx + dvz * dvz) + 2.0 * v[s] * v[s]
        row += 1

    i0 = ints[1 + _ANGLE]
    for k in range((ints[2 + _ANGLE] - i0) // 9):
        r = i0 + 9 * k
        ux, uz, wx, wz, dux, duz, dwx, dwz = _vector_pair(ints, r, x, v)
        f, df = x[ints[r + 8]], v[ints[r + 8]]
        c, s = math.cos(f), math.sin(f)
        cross = ux * wz - uz * wx
        dot = ux * wx + uz * wz
        dcross = dux * wz + ux * dwz - duz * wx - uz * dwx
        ddot = dux * wx + ux * dwx + duz * wz + uz * dwz
        buffer[n + row] = c * cross - s * dot
        # ∂Φ/∂u = c (w_z, -w_x) - s (w_x, w_z);  ∂Φ/∂w = c (-u_z, u_x) - s (u_x, u_z)
        gux, guz = c * wz - s * wx, -c * wx - s * wz
        gwx, gwz = -c * uz - s * ux, c * ux - s * uz
        _add(buffer, a0, row, ints[r], -gux, n)
        _add(buffer, a0, row, ints[r + 1], -guz, n)
        _add(buffer, a0, row, ints[r + 2], gux, n)
        _add(buffer, a0, row, ints[r + 3], guz, n)
        _add(buffer, a0, row, ints[r + 4], -gwx, n)
        _add(buffer, a0, row, ints[r + 5], -gwz, n)
        _add(buffer, a0, row, ints[r + 6], gwx, n)
        _add(buffer, a0, row, ints[r + 7], gwz, n)
        buffer[a0 + row * n + ints[r + 8]] += -s * cross - c * dot
        # velocity-quadratic part of Φ̈ (terms without second derivatives)
        cross_vv = dux * dwz - duz * dwx
        dot_vv = dux * dwx + duz * dwz
        quadratic = (-c * df * df * cross - 2.0 * s * df * dcross + 2.0 * c * cross_vv
                     + s * df * df * dot - 2.0 * c * df * ddot - 2.0 * s * dot_vv)
        buffer[g0 + row] = -quadratic
        row += 1

    i0 = ints[1 + _PARALLEL]
    for k in range((ints[2 + _PARALLEL] - i0) // 8):
        r = i0 + 8 * k
        ux, uz, wx, wz, dux, duz, dwx, dwz = _vector_pair(ints, r, x, v)
        buffer[n + row] = ux * wz - uz * wx
        _add(buffer, a0, row, ints[r], -wz, n)
        _add(buffer, a0, row, ints[r + 1], wx, n)
        _add(buffer, a0, row, ints[r + 2], wz, n)
        _add(buffer, a0, row, ints[r + 3], -wx, n)
        _add(buffer, a0, row, ints[r + 4], uz, n)
        _add(buffer, a0, row, ints[r + 5], -ux, n)
        _add(buffer, a0, row, ints[r + 6], -uz, n)
        _add(buffer, a0, row, ints[r + 7], ux, n)
        buffer[g0 + row] = -2.0 * (dux * dwz - duz * dwx)
        row += 1

    i0 = ints[1 + _BODY_POINT]
    p0 = ints[real_base + 1 + _BODY_POINT_LOCAL]
    for k in range((ints[2 + _BODY_POINT] - i0) // 6):
        r = i0 + 6 * k
        xi, zi, xj, zj, xk, zk = ints[r], ints[r + 1], ints[r + 2], ints[r + 3], ints[r + 4], ints[r + 5]
        s, e = reals[p0 + 2 * k], reals[p0 + 2 * k + 1]
        dx, dz = x[xj] - x[xi], x[zj] - x[zi]
        buffer[n + row] = x[xk] - x[xi] - s * dx + e * dz
        _add(buffer, a0, row, xi, s - 1.0, n)
        _add(buffer, a0, row, zi, -e, n)
        _add(buffer, a0, row, xj, -s, n)
        _add(buffer, a0, row, zj, e, n)
        _add(buffer, a0, row, xk, 1.0, n)
        buffer[g0 + row] = 0.0
        buffer[n + row + 1] = x[zk] - x[zi] - s * dz - e * dx
        _add(buffer, a0, row + 1, xi, e, n)
        _add(buffer, a0, row + 1, zi, s - 1.0, n)
        _add(buffer, a0, row + 1, xj, -e, n)
        _add(buffer, a0, row + 1, zj, -s, n)
        _add(buffer, a0, row + 1, zk, 1.0, n)
        buffer[g0 + row + 1] = 0.0
        row += 2

    row = driver_rows(ints, _DRIVER, buffer, n, a0, g0, t0, s0, x0, row)

    # generalized forces
    r0 = ints[real_base + 1 + _Q_CONSTANT]
    for k in range(n):
        buffer[k] = reals[r0 + k]
    i0 = ints[1 + _POINT_FORCE]
    for k in range((ints[2 + _POINT_FORCE] - i0) // 4):
        xi, zi, fx, fz = ints[i0 + 4 * k], ints[i0 + 4 * k + 1], ints[i0 + 4 * k + 2], ints[i0 + 4 * k + 3]
        if xi < n:
            buffer[xi] += buffer[s0 + 3 * fx]
        if zi < n:
            buffer[zi] += buffer[s0 + 3 * fz]
    i0 = ints[1 + _TORQUE]
    for k in range((ints[2 + _TORQUE] - i0) // 2):
        buffer[ints[i0 + 2 * k]] += buffer[s0 + 3 * ints[i0 + 2 * k + 1]]
    i0 = ints[1 + _SEGMENT_FORCE]
    p0 = ints[real_base + 1 + _SEGMENT_FORCE_AT]
    for k in range((ints[2 + _SEGMENT_FORCE] - i0) // 7):
        r = i0 + 7 * k
        xi, zi, xj, zj = ints[r], ints[r + 1], ints[r + 2], ints[r + 3]
        fx, fz = _segment_force(x, xi, zi, xj, zj, buffer[s0 + 3 * ints[r + 4]], buffer[s0 + 3 * ints[r + 5]],
                                ints[r + 6])
        s, e = reals[p0 + 2 * k], reals[p0 + 2 * k + 1]
        _add_force(buffer, xi, (1.0 - s) * fx - e * fz, n)
        _add_force(buffer, zi, e * fx + (1.0 - s) * fz, n)
        _add_force(buffer, xj, s * fx + e * fz, n)
        _add_force(buffer, zj, s * fz - e * fx, n)
    i0 = ints[1 + _MOMENT]
    for k in range((ints[2 + _MOMENT] - i0) // 5):
        r = i0 + 5 * k
        xi, zi, xj, zj = ints[r], ints[r + 1], ints[r + 2], ints[r + 3]
        dx, dz = x[xj] - x[xi], x[zj] - x[zi]
        scale = buffer[s0 + 3 * ints[r + 4]] / (dx * dx + dz * dz)
        _add_force(buffer, xi, scale * dz, n)
        _add_force(buffer, zi, -scale * dx, n)
        _add_force(buffer, xj, -scale * dz, n)
        _add_force(buffer, zj, scale * dx, n)
    i0 = ints[1 + _SPRING]
    r0 = ints[real_base + 1 + _SPRING_PARAMETERS]
    for k in range((ints[2 + _SPRING] - i0) // 4):
        xi, zi, xj, zj = ints[i0 + 4 * k], ints[i0 + 4 * k + 1], ints[i0 + 4 * k + 2], ints[i0 + 4 * k + 3]
        dx, dz = x[xj] - x[xi], x[zj] - x[zi]
        length = math.sqrt(dx * dx + dz * dz)
        ex, ez = dx / length, dz / length
        rate = ex * (v[xj] - v[xi]) + ez * (v[zj] - v[zi])
        tension = reals[r0 + 3 * k] * (length - reals[r0 + 3 * k + 2]) + reals[r0 + 3 * k + 1] * rate
        _add_force(buffer, xi, tension * ex, n)
        _add_force(buffer, zi, tension * ez, n)
        _add_force(buffer, xj, -tension * ex, n)
        _add_force(buffer, zj, -tension * ez, n)
    i0 = ints[1 + _ACTUATOR]
    r0 = ints[real_base + 1 + _ACTUATOR_GAIN]
    for k in range(ints[2 + _ACTUATOR] - i0):
        buffer[ints[i0 + k]] += reals[r0 + k] * u[k]


@njit(cache=True, inline="always")
def _segment_force(x, xi, zi, xj, zj, first, second, frame):
    """Ground components of a segment force given as (first, second): (fx, fz) in the ground
    frame (frame 0), or (along, across) the segment from i to j (frame 1): F = f_a e + f_b R90 e."""
    if frame == 0:
        return first, second
    dx, dz = x[xj] - x[xi], x[zj] - x[zi]
    length = math.sqrt(dx * dx + dz * dz)
    ex, ez = dx / length, dz / length
    return first * ex - second * ez, first * ez + second * ex


@njit(cache=True, inline="always")
def _add_force(Q, index, value, n):
    if index < n:
        Q[index] += value


class NaturalKernel(NamedTuple):
    """A natural-coordinate model as the compiled loops take it (:mod:`cmbs.model.compiled`):
    its index and parameter arrays and its constant mass matrix."""

    ints: np.ndarray
    reals: np.ndarray
    mass: np.ndarray


@njit(cache=True, inline="always")
def _evaluate_natural(kernel, q, qd, t, u, buffer):
    """:func:`_evaluate` for a :class:`NaturalKernel`."""
    _evaluate(q, qd, t, u, kernel.ints, kernel.reals, buffer)


NaturalKernel.evaluate = staticmethod(_evaluate_natural)
