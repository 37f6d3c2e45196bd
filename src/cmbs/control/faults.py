"""Faults for robustness studies (thesis ch. 7): what the controller does not know.

- :func:`mass_fault`: a segment's mass (and inertia) scaled by a factor from time t0 on — the
  plant changes, the controller keeps its nominal model.  For natural-coordinate models the
  segment's element mass matrix and gravity force are scaled (both are linear in the mass).
  For robots a body's spatial inertia is scaled: M(q) and the bias forces C(q, q̇) q̇ + g(q) are
  linear in the bodies' spatial inertias (Featherstone 2008, §6.2 and §5.3), so the faulty
  robot's terms are the nominal ones plus those of a tree whose only inertia is (factor - 1)
  times that body's.
- :class:`ActuatorFault`: the inputs reaching the plant are ``scale·u + offset`` from t0 on.
- :class:`SensorNoise`: the controller sees q + noise, q̇ + noise (Gaussian, seeded, drawn
  once per sensor sample period and held, so that it is a fixed function of time).
- A wrong initial state is simply a different ``q0``/``qd0`` given to :func:`cmbs.simulate`.
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np

from cmbs.errors import CmbsError, did_you_mean
from cmbs.model.model import Model, ModelEquations, Terms, WrappedEquations, assign_terms, base_equations
from cmbs.model.natural import NaturalEquations
from cmbs.model.robot import RobotEquations
from cmbs.model.robot_kernel import RobotKernel, energies, evaluate_terms, scratch_size
from cmbs.model.spatial import SpatialEquations

Law = Callable[[float, np.ndarray, np.ndarray], np.ndarray]


class _MassFaultEquations(WrappedEquations):
    """Natural-coordinate equations with ΔM, ΔQ_gravity added from t0 on."""

    def __init__(self, inner: NaturalEquations, delta_mass: np.ndarray, delta_gravity: np.ndarray, t0: float):
        self.inner = inner
        self.delta_mass = delta_mass
        self.delta_gravity = delta_gravity
        self.t0 = t0
        self.inner_terms = inner.new_terms()

    def new_terms(self) -> Terms:
        return Terms(self.inner.n, self.inner.m, scratch=0)

    def evaluate(self, q: np.ndarray, qd: np.ndarray, t: float, u: np.ndarray, terms: Terms) -> None:
        self.inner.evaluate(q, qd, t, u, self.inner_terms)
        assign_terms(terms, self.inner_terms)
        if t >= self.t0:
            terms.M += self.delta_mass
            terms.Q += self.delta_gravity



class _RobotMassFaultEquations(WrappedEquations):
    """Robot equations with the terms of ``delta`` (the same tree carrying only the added
    inertia, no rows, springs nor loads) added from t0 on: ΔM(q) and ΔQ = -(ΔC(q, q̇) q̇ + Δg(q))."""

    def __init__(self, inner: ModelEquations, delta: RobotKernel, t0: float):
        self.inner = inner
        self.delta = delta
        self.t0 = t0
        n = delta.parent.shape[0]
        self.delta_terms = Terms(n, 0, scratch=scratch_size(delta))
        self.no_input = np.zeros(n)

    def new_terms(self) -> Terms:
        return self.inner.new_terms()

    def evaluate(self, q: np.ndarray, qd: np.ndarray, t: float, u: np.ndarray, terms: Terms) -> None:
        self.inner.evaluate(q, qd, t, u, terms)
        if t >= self.t0:
            evaluate_terms(self.delta, q, qd, t, self.no_input, self.delta_terms.buffer)
            terms.M += self.delta_terms.M
            terms.Q += self.delta_terms.Q

    def added_energies(self, q: np.ndarray, qd: np.ndarray) -> tuple[float, float]:
        """(ΔT, ΔV) of the added inertia at (q, q̇)."""
        return energies(self.delta, q, qd)


def _robot_mass_fault(model: Model, robot: RobotEquations, body: str, factor: float,
                      t0: float) -> _RobotMassFaultEquations:
    """The faulty equations of a robot model (``robot``: its base equations, which the model's
    may wrap) whose body ``body`` (the child link of a movable joint, with the links fixed to it)
    has ``factor`` times its mass and inertia."""
    kernel = robot.kernel
    carriers = {joint.child: k for k, joint in enumerate(robot.joints)}
    if body not in carriers:
        raise CmbsError(f"model {model.name!r} has no body {body!r}{did_you_mean(body, carriers)}; bodies (the "
                        f"child links of the movable joints): {', '.join(carriers)}")
    k = carriers[body]
    added = np.zeros_like(kernel.inertia)
    added[k] = kernel.inertia[k]
    added[k, 0] *= factor - 1.0
    added[k, 4:] *= factor - 1.0          # (m, centre of mass, inertia about it): m and I scale
    delta = kernel._replace(inertia=added, closure_ints=kernel.closure_ints[:0],
                            closure_reals=kernel.closure_reals[:0], drivers=kernel.drivers[:0],
                            tf_table=kernel.tf_table[:0], sizes=np.array([0, kernel.sizes[1]], np.int64),
                            springs=kernel.springs[:0], spring_reals=kernel.spring_reals[:0],
                            load_ints=kernel.load_ints[:0], load_reals=kernel.load_reals[:0],
                            point_springs=kernel.point_springs[:0], point_spring_reals=kernel.point_spring_reals[:0])
    return _RobotMassFaultEquations(model.equations, delta, t0)


def mass_fault_energy_parts(model: Model, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(ΔT, ΔV): the kinetic and potential energy the mass faults of ``model`` add to its nominal
    energies at the rows of q, q̇ (k, n), for times after the faults' t0: ΔT = ½ q̇ᵀ ΔM q̇ and
    ΔV = -ΔQ_g·q (natural coordinates: M is constant and gravity a constant generalized force,
    so its potential is -Q_g·q; robots: ΔT and ΔV = -Δm g·c of the added inertia).  Zeros for a
    model without mass faults."""
    q, qd = np.atleast_2d(np.asarray(q, dtype=float)), np.atleast_2d(np.asarray(qd, dtype=float))
    kinetic, potential = np.zeros(q.shape[0]), np.zeros(q.shape[0])
    equations = model.equations
    while isinstance(equations, WrappedEquations):
        if isinstance(equations, _MassFaultEquations):
            kinetic += 0.5 * np.einsum("ki,ij,kj->k", qd, equations.delta_mass, qd)
            potential -= q @ equations.delta_gravity
        if isinstance(equations, _RobotMassFaultEquations):
            for row, (q_row, qd_row) in enumerate(zip(q, qd)):
                added_kinetic, added_potential = equations.added_energies(q_row, qd_row)
                kinetic[row] += added_kinetic
                potential[row] += added_potential
        equations = equations.inner
    return kinetic, potential


def nominal_work_sources(model: Model) -> tuple[str, ...] | None:
    """:attr:`~cmbs.model.model.Model.work_sources` of ``model`` without its mass faults.  A
    mass changed from t = 0 on changes no force that does work, so the changed mechanism
    conserves its own energy (nominal + :func:`mass_fault_energy_parts`) when the nominal one
    conserves its own."""
    equations = model.equations
    while isinstance(equations, (_MassFaultEquations, _RobotMassFaultEquations)):
        equations = equations.inner
    return model.replace(equations=equations).work_sources


def check_mass_factor(segment: str, factor: float) -> None:
    """A mass fault's factor is finite and > 0: a zero or negative mass has no physical meaning."""
    if not (math.isfinite(factor) and factor > 0):
        raise CmbsError(f"mass fault on segment {segment!r}: the mass factor must be > 0 (finite), got {factor!r}")


def mass_fault(model: Model, segment: str, *, factor: float, t0: float = 0.0) -> Model:
    """``model`` whose segment ``segment`` has ``factor`` times its mass and inertia from ``t0``
    (e.g. factor 1.025 for the thesis's 2.5 % fault).  Natural-coordinate models only, planar
    (a segment or body) or spatial (a body or rod: its share of M and gravity,
    :class:`~cmbs.model.spatial.FreeBody`), and robots (the body a movable joint carries, named
    by its child link: e.g. a payload on the last link).  Energies are reported with the
    nominal masses; :func:`mass_fault_energy_parts` gives what the faulty masses add."""
    check_mass_factor(segment, factor)
    robot = base_equations(model)[0]
    if isinstance(robot, RobotEquations):
        faulty = _robot_mass_fault(model, robot, segment, factor, t0)
        return model.replace(name=f"{model.name} ({segment} mass x{factor:g} from t={t0:g})", equations=faulty)
    equations = model.equations
    if isinstance(equations, NaturalEquations):
        shares = {s.name: (s.indices, s.mass_matrix, s.gravity) for s in equations.segments}
        kind = "segment"
    elif isinstance(equations, SpatialEquations):
        shares = {b.name: ((b.slots[:, None] + np.arange(3)).ravel(), b.mass, b.gravity)
                  for b in equations.free_bodies}
        kind = "body"
    else:
        raise CmbsError(f"mass faults need a natural-coordinate model (planar or spatial) or a robot; "
                        f"{model.name!r} is neither")
    if segment not in shares:
        raise CmbsError(f"model {model.name!r} has no {kind} {segment!r}{did_you_mean(segment, shares)}; "
                        f"{'segments' if kind == 'segment' else 'bodies and rods'}: {', '.join(shares)}")
    indices, mass_matrix, gravity = shares[segment]
    n = model.n
    keep = indices < n
    local = np.flatnonzero(keep)
    rows = indices[keep]
    delta_mass = np.zeros((n, n))
    delta_mass[np.ix_(rows, rows)] = (factor - 1.0) * mass_matrix[np.ix_(local, local)]
    delta_gravity = np.zeros(n)
    delta_gravity[rows] = (factor - 1.0) * gravity[local]
    faulty = _MassFaultEquations(equations, delta_mass, delta_gravity, t0)
    return model.replace(name=f"{model.name} ({segment} mass x{factor:g} from t={t0:g})", equations=faulty,
                         constant_mass=False)


class ActuatorFault:
    """Wrap a control law: from ``t0`` the plant receives ``scale·u + offset``."""

    def __init__(self, law: Law, *, t0: float = 0.0, scale: float = 1.0, offset: float | Sequence[float] = 0.0):
        self.law, self.t0, self.scale = law, t0, scale
        self.offset = np.asarray(offset, dtype=float)

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        u = np.asarray(self.law(t, q, qd), dtype=float)
        return self.scale * u + self.offset if t >= self.t0 else u


class SensorNoise:
    """Wrap a control law so that it sees noisy measurements: Gaussian noise of standard
    deviations ``position`` and ``velocity``, drawn once per sensor sample (every ``period``
    seconds) and held in between.  The noise of sample k comes from a generator seeded by
    (``seed``, k), so it is a fixed function of time: repeated calls, Runge-Kutta stages and
    step rejections all see the same measurement, and adaptive integrators step over the
    sample instants as over any piecewise-smooth input."""

    def __init__(self, law: Law, *, position: float, velocity: float = 0.0, seed: int = 0, period: float = 1e-3):
        if position < 0 or velocity < 0 or not period > 0:
            raise CmbsError(f"sensor noise needs standard deviations >= 0 and a period > 0, got {position}, "
                            f"{velocity}, {period}")
        self.law = law
        self.position, self.velocity, self.seed, self.period = position, velocity, seed, period
        self.last: tuple[int, np.ndarray, np.ndarray] | None = None

    def __call__(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        sample = int(np.floor(t / self.period + 1e-9))
        if self.last is None or self.last[0] != sample:
            rng = np.random.default_rng([self.seed, sample])
            self.last = (sample, rng.normal(0.0, self.position, q.shape), rng.normal(0.0, self.velocity, qd.shape))
        return self.law(t, q + self.last[1], qd + self.last[2])
