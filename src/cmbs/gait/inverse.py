"""Inverse dynamics of a recorded stride on the 14-DOF human model (issue 5, item 2; docs/gait.md).

The reference motion of :mod:`cmbs.gait.reconstruct` prescribes the 14 independent coordinates
z = (hip.x, hip.z, trunk, 11 relative angles) (Pätkau, UPC thesis §4.2: the model driven by its
independent coordinates, eq. 3.6 driver rows; :func:`cmbs.motion.prescribe`).  The generalized
forces on them follow from the velocity transformation (thesis eq. 4.2, :mod:`cmbs.inverse.ida`)

    Q_z = Rᵀ (M q̈ - Q - Q_ext)

(R: q̇ = R ż, identity rows on z).  Its 11 relative-angle components are the joint torques
(counter-clockwise positive on the distal segment, minus on the proximal one); its hip.x, hip.z
and trunk components are the force on the hip point and the torque about it that the model needs
*in addition* to the known loads Q_ext: moving hip.x with every angle held translates the whole
body, turning the trunk angle rotates the whole body about the hip, so

    Q_hip = Σ m a_G - m g - F_ext,        Q_trunk = Σ (moments about the hip)       (Newton-Euler)

Two analyses:

* ``"hip"`` (the thesis's): Q_ext = 0; the hip wrench carries the whole ground contact.
* ``"grf"``: Q_ext = the measured ground reaction force F on each foot at its centre of pressure
  p.  On the foot segment (ankle i, toe j) p = r_i + C(ξ, η)(r_j - r_i) with
  C = [[ξ, -η], [η, ξ]] ((ξ, η) the CoP's coordinates along the foot and across it, +90°, in units
  of the foot length; thesis eq. 3.32, :func:`cmbs.model.natural.point_map`), a linear Jacobian,
  so the generalized force is Q_ext = [I - C, C]ᵀ F on (x_i, z_i, x_j, z_j).  The CoP moves along
  the foot: (ξ, η) are computed at every frame from the reference pose.  The hip wrench is then a
  *residual*, the inconsistency between model and data (OpenSim's residual actuators).

Between frames Q_ext (both feet) is interpolated linearly, the prescribed z by quintic Hermite
pieces through the reference's z, ż, z̈ at the frames (C², exact at the frames).

Lab moments.  The file's sagittal moments are internal, per kg, positive for hip extension, knee
extension and ankle plantarflexion.  The model's hip angle is flexion-positive (thigh forward,
counter-clockwise), its knee angle extension-positive (flexion < 0), its ankle angle
dorsiflexion-positive (toe up), each torque counter-clockwise on the distal segment, so the lab
moment is ``-τ_hip/m``, ``+τ_knee/m``, ``-τ_ankle/m`` (:data:`LAB_SIGN`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cmbs.errors import CmbsError
from cmbs.gait.reconstruct import INDEPENDENT, smooth
from cmbs.kinematics import kinematic_analysis
from cmbs.model.drivers import TimeFunction
from cmbs.model.model import Model, Terms, WrappedEquations, base_equations
from cmbs.model.natural import point_map
from cmbs.motion import prescribe
from cmbs.trajectory import Trajectory

MODES = ("hip", "grf")
RESIDUAL = INDEPENDENT[:3]          # hip.x, hip.z, trunk
JOINTS = INDEPENDENT[3:]            # the 11 relative angles = the model's actuators' coordinates
LEG_JOINTS = ("r_hip", "r_knee", "r_ankle", "l_hip", "l_knee", "l_ankle")   # order of extras['lab_moments']
LAB_SIGN = {"hip": -1.0, "knee": 1.0, "ankle": -1.0}
GRAVITY = 9.81


class QuinticHermite(TimeFunction):
    """C² piecewise quintic through (t_i, z_i, ż_i, z̈_i), exact value and derivatives at the
    samples.  On [t_i, t_i + h], s = t - t_i, p = z_i + ż_i s + z̈_i s²/2 + c₃s³ + c₄s⁴ + c₅s⁵ with
    Δ₀ = z_{i+1} - z_i - ż_i h - z̈_i h²/2, Δ₁ = ż_{i+1} - ż_i - z̈_i h, Δ₂ = z̈_{i+1} - z̈_i:
    c₃ = (20Δ₀ - 8Δ₁h + Δ₂h²)/(2h³), c₄ = (-30Δ₀ + 14Δ₁h - 2Δ₂h²)/(2h⁴), c₅ = (12Δ₀ - 6Δ₁h + Δ₂h²)/(2h⁵)
    (the three end conditions solved; checked against scipy's ``BPoly.from_derivatives``)."""

    def __init__(self, times: np.ndarray, values: np.ndarray, rates: np.ndarray, accelerations: np.ndarray):
        t, z, v, a = (np.asarray(x, dtype=float) for x in (times, values, rates, accelerations))
        h = np.diff(t)
        d0 = z[1:] - z[:-1] - v[:-1] * h - 0.5 * a[:-1] * h**2
        d1 = v[1:] - v[:-1] - a[:-1] * h
        d2 = a[1:] - a[:-1]
        self.breaks = t
        self.coefficients = np.stack([
            (12 * d0 - 6 * d1 * h + d2 * h**2) / (2 * h**5), (-30 * d0 + 14 * d1 * h - 2 * d2 * h**2) / (2 * h**4),
            (20 * d0 - 8 * d1 * h + d2 * h**2) / (2 * h**3), 0.5 * a[:-1], v[:-1], z[:-1]], axis=1)

    def __call__(self, t: float) -> tuple[float, float, float]:
        i = min(max(int(np.searchsorted(self.breaks, t, side="right")) - 1, 0), len(self.coefficients) - 1)
        s = t - self.breaks[i]
        c5, c4, c3, c2, c1, c0 = self.coefficients[i]
        value = ((((c5 * s + c4) * s + c3) * s + c2) * s + c1) * s + c0
        first = (((5 * c5 * s + 4 * c4) * s + 3 * c3) * s + 2 * c2) * s + c1
        second = ((20 * c5 * s + 12 * c4) * s + 6 * c3) * s + 2 * c2
        return float(value), float(first), float(second)


class _AppliedLoads(WrappedEquations):
    """The equations of ``inner`` with a known generalized force Q_ext(t) added to Q, linear in t
    between the rows of ``table`` (k, n) at ``times`` (held outside), shifted by ``t0``."""

    def __init__(self, inner, times: np.ndarray, table: np.ndarray, t0: float = 0.0):
        self.inner = inner
        self.times = np.asarray(times, dtype=float)
        self.table = np.asarray(table, dtype=float)
        self.t0 = float(t0)

    def new_terms(self) -> Terms:
        return self.inner.new_terms()

    def load(self, t: float) -> np.ndarray:
        t = min(max(t + self.t0, self.times[0]), self.times[-1])
        i = min(int(np.searchsorted(self.times, t, side="right")) - 1, len(self.times) - 2)
        w = (t - self.times[i]) / (self.times[i + 1] - self.times[i])
        return (1.0 - w) * self.table[i] + w * self.table[i + 1]

    def evaluate(self, q: np.ndarray, qd: np.ndarray, t: float, u: np.ndarray, terms: Terms) -> None:
        self.inner.evaluate(q, qd, t, u, terms)
        terms.Q += self.load(t)



def with_loads(model: Model, times: np.ndarray, table: np.ndarray, t0: float = 0.0) -> Model:
    """``model`` with the known generalized force ``table`` (k, n) at ``times`` added to Q
    (linear between them; the model's time t is ``times``' time ``t + t0``)."""
    table = np.asarray(table, dtype=float)
    if table.shape != (len(times), model.n):
        raise CmbsError(f"load table has shape {table.shape}, expected ({len(times)}, {model.n})")
    return model.replace(equations=_AppliedLoads(model.equations, times, table, t0))


def cop_local(ankle: np.ndarray, toe: np.ndarray, cop: np.ndarray) -> np.ndarray:
    """(k, 2) coordinates (ξ, η) of ``cop`` in the foot frame: p - r_i = ξ d + η R90 d with
    d = r_j - r_i (ankle i, toe j), i.e. ξ = (p - r_i)·d/|d|², η = d × (p - r_i)/|d|²."""
    d, p = toe - ankle, cop - ankle
    norm2 = np.sum(d * d, axis=1)
    return np.stack([np.sum(p * d, axis=1) / norm2, (d[:, 0] * p[:, 1] - d[:, 1] * p[:, 0]) / norm2], axis=1)


def grf_loads(model: Model, motion: Trajectory) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Generalized force (k, n) of the measured GRF of both feet at their CoPs on the reference
    poses (module docstring) and the CoPs' foot coordinates {side: (k, 2)} (0 without contact)."""
    loads = np.zeros((len(motion.t), model.n))
    local = {}
    for side in ("r", "l"):
        columns = model.coordinate_indices([f"{side}_ankle.x", f"{side}_ankle.z", f"{side}_toe.x", f"{side}_toe.z"])
        force, contact = np.asarray(motion[f"{side}_grf"]), np.asarray(motion[f"{side}_contact"], dtype=bool)
        xi = cop_local(motion.q[:, columns[:2]], motion.q[:, columns[2:]], np.asarray(motion[f"{side}_cop"]))
        xi[~contact] = 0.0
        for k in np.flatnonzero(contact):
            loads[k, columns] += point_map(1.0, (xi[k, 0], xi[k, 1])).T @ force[k]
        local[side] = xi
    return loads, local


@dataclass(frozen=True)
class GaitInverse:
    """Inverse dynamics of a stride: ``motion`` (q, q̇, q̈ at ``motion.t``), ``forces`` (k, 14)
    generalized forces on :data:`INDEPENDENT`, the known ``loads`` (k, n) at the reference frames
    (zero for mode ``hip``), ``loaded`` (the model with those loads added to Q; the one to replay),
    ``mode`` and the ``cop`` foot coordinates."""

    motion: Trajectory
    forces: np.ndarray
    loads: np.ndarray
    loaded: Model
    mode: str
    cop: dict[str, np.ndarray]

    @property
    def body_mass(self) -> float:
        """Total mass of the model [kg]."""
        return self.loaded.total_mass

    @property
    def residual(self) -> np.ndarray:
        """(k, 3) hip force x, z [N] and torque about the hip [N m] (the hip.x, hip.z, trunk components)."""
        return self.forces[:, :3]

    @property
    def torques(self) -> np.ndarray:
        """(k, 11) joint torques [N m] on :data:`JOINTS` (= the model's actuators, in order)."""
        return self.forces[:, 3:]

    def torque(self, joint: str) -> np.ndarray:
        """Generalized force history on one of :data:`INDEPENDENT`."""
        return self.forces[:, INDEPENDENT.index(joint)]

    def lab_convention(self) -> np.ndarray:
        """(k, 6) leg torques of :data:`LEG_JOINTS` in the lab's convention [N m/kg] (LAB_SIGN)."""
        return np.stack([LAB_SIGN[joint[2:]] * self.torque(joint) for joint in LEG_JOINTS], axis=1) / self.body_mass

    def inputs(self) -> np.ndarray:
        """(k, n_u) actuator inputs: the joint torques, ordered as ``loaded.actuator_names``."""
        return self.forces[:, [INDEPENDENT.index(name.removeprefix("tau_")) for name in self.loaded.actuator_names]]


def prescribed_model(model: Model, reference: Trajectory, loads: np.ndarray) -> Model:
    """``model`` with ``loads`` (k, n) at the reference frames added to Q and its independent
    coordinates prescribed by quintic Hermite pieces through the reference's z, ż, z̈."""
    loaded = with_loads(model.replace(q0=reference.q[0], qd0=reference.qd[0]), reference.t, loads)
    columns = model.coordinate_indices(list(INDEPENDENT))
    functions = {name: QuinticHermite(reference.t, reference.q[:, c], reference.qd[:, c], reference.qdd[:, c])
                 for name, c in zip(INDEPENDENT, columns)}
    return prescribe(loaded, functions)


def inverse(model: Model, reference: Trajectory, mode: str = "grf", *, times: np.ndarray | None = None) -> GaitInverse:
    """Inverse dynamics of the prepared ``reference`` (:func:`cmbs.gait.prepare_stride`'s motion)
    on its ``model``, at the reference frames (``times`` None: their q, q̇, q̈ are used as they
    are) or at ``times`` inside the stride (kinematic analysis of the prescribed model).
    ``mode`` ``hip`` or ``grf`` (module docstring).

    Raises
    ------
    CmbsError
        Unknown ``mode``, a reference without the GRF extras, or ``times`` outside the stride.
    """
    if mode not in MODES:
        raise CmbsError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    if list(reference.names) != list(model.coordinate_names):
        raise CmbsError(f"the reference's coordinates are not those of model {model.name!r}")
    if mode == "grf":
        missing = [k for s in "rl" for k in (f"{s}_grf", f"{s}_cop", f"{s}_contact") if k not in reference.extras]
        if missing:
            raise CmbsError(f"mode 'grf' needs the reference extras {', '.join(missing)} (cmbs gait prepare)")
        loads, cop = grf_loads(model, reference)
    else:
        loads, cop = np.zeros((len(reference.t), model.n)), {}
    loaded = with_loads(model, reference.t, loads)
    if times is None:
        motion = Trajectory(reference.t, reference.q, reference.qd, reference.qdd, reference.names)
    else:
        times = np.asarray(times, dtype=float)
        if times.size == 0 or times[0] < reference.t[0] - 1e-12 or times[-1] > reference.t[-1] + 1e-12:
            raise CmbsError(f"times must lie in the stride [{reference.t[0]:g}, {reference.t[-1]:g}] s")
        start = int(np.clip(np.searchsorted(reference.t, times[0]), 0, len(reference.t) - 1))
        motion = kinematic_analysis(prescribed_model(model, reference, loads), times, q0=reference.q[start],
                                    tolerance=1e-12)
    return GaitInverse(motion, independent_forces(loaded, motion), loads, loaded, mode, cop)


def independent_forces(model: Model, motion: Trajectory) -> np.ndarray:
    """(k, 14) Q_z = Rᵀ(M q̈ - Q) on :data:`INDEPENDENT` (thesis eq. 4.2) at every instant of
    ``motion``.  With A = [A_d A_z] (dependent, independent columns) R = [-A_d⁻¹A_z; I], so
    Q_z = r_z - A_zᵀ y with A_dᵀ y = r_d, r = M q̈ - Q: one solve per instant."""
    independent = model.coordinate_indices(list(INDEPENDENT))
    dependent = np.setdiff1d(np.arange(model.n), independent)
    terms = model.new_terms()
    forces = np.zeros((len(motion.t), len(INDEPENDENT)))
    for k, t in enumerate(motion.t):
        model.evaluate(motion.q[k], motion.qd[k], t, out=terms)
        r = terms.M @ motion.qdd[k] - terms.Q
        A = terms.A
        y = np.linalg.solve(A[:, dependent].T, r[dependent])
        forces[k] = r[independent] - A[:, independent].T @ y
    return forces


def centre_of_mass(model: Model, q: np.ndarray) -> np.ndarray:
    """(k, 2) whole-body centre of mass of a natural-coordinate model at the poses ``q`` (k, n)."""
    equations, _ = base_equations(model)
    total = np.zeros((len(q), 2))
    for segment in equations.segments:
        if segment.mass > 0:
            total += segment.mass * q[:, segment.indices] @ point_map(segment.length, segment.com).T
    return total / sum(s.mass for s in equations.segments)


@dataclass(frozen=True)
class Comparison:
    """Model leg torques vs the lab's moments [N m/kg] over the stride, per joint of
    :data:`LEG_JOINTS`: Pearson correlation and RMS difference, and the correlation with the lab
    curve low-passed at ``cutoff`` Hz (the lab's moments are unfiltered: at heel strike the hip
    moment carries 0.2-0.3 N m/kg above 6 Hz, where the model's, from 6 Hz kinematics, has 0.03)."""

    joints: tuple[str, ...]
    correlation: np.ndarray
    rms_difference: np.ndarray
    correlation_filtered: np.ndarray
    cutoff: float
    model: np.ndarray
    lab: np.ndarray


def compare_with_lab(result: GaitInverse, reference: Trajectory, cutoff: float = 6.0) -> Comparison:
    """Correlate :meth:`GaitInverse.lab_convention` with ``reference['lab_moments']`` (same
    frames); the filtered correlation smooths the lab curve over the stride with the reference's
    smoothing spline (:func:`cmbs.gait.reconstruct.smooth`) at ``cutoff`` Hz."""
    lab = np.asarray(reference["lab_moments"], dtype=float)
    ours = result.lab_convention()
    if lab.shape != ours.shape:
        raise CmbsError(f"lab moments {lab.shape} and model torques {ours.shape} are not at the same frames")
    joints = range(len(LEG_JOINTS))
    correlation = np.array([np.corrcoef(ours[:, j], lab[:, j])[0, 1] for j in joints])
    filtered = np.array([np.corrcoef(ours[:, j], smooth(reference.t, lab[:, j], cutoff, reference.t)[0])[0, 1]
                         for j in joints])
    rms = np.sqrt(np.mean((ours - lab) ** 2, axis=0))
    return Comparison(LEG_JOINTS, correlation, rms, filtered, cutoff, ours, lab)


@dataclass(frozen=True)
class Residuals:
    """RMS and peak |·| over the stride of the hip force x, z [N] and torque [N m], and as % of
    body weight m g (forces) and of m g × height (torque)."""

    rms: np.ndarray
    peak: np.ndarray
    rms_percent: np.ndarray
    peak_percent: np.ndarray


def residual_summary(result: GaitInverse, height: float) -> Residuals:
    """:class:`Residuals` of ``result`` for a subject of ``height`` [m]."""
    weight = result.body_mass * GRAVITY
    scale = np.array([weight, weight, weight * height]) / 100.0
    rms = np.sqrt(np.mean(result.residual**2, axis=0))
    peak = np.max(np.abs(result.residual), axis=0)
    return Residuals(rms, peak, rms / scale, peak / scale)


def replay(model: Model, reference: Trajectory, mode: str, start: float, duration: float, *,
           step: float = 1e-3, rtol: float = 1e-10) -> tuple[Trajectory, Trajectory]:
    """Forward dynamics driven by the inverse-dynamics torques over [start, start + duration]:
    (simulated, prescribed) motions at the same instants (t = 0 at ``start``).

    The inverse dynamics runs at every ``step`` (kinematic analysis of the prescribed model); the
    undriven model gets the known loads of ``mode`` plus the hip wrench (generalized forces on
    hip.x, hip.z, trunk) as external forces, and the 11 joint torques as actuator inputs, both
    linear in t between the steps; it starts from the prescribed state at ``start`` and is
    integrated by RK45 with ``rtol`` (lagrange formulation)."""
    from cmbs.simulate import simulate

    times = start + np.arange(0.0, duration + 0.5 * step, step)
    fine = inverse(model, reference, mode, times=times)
    known = fine.loaded.equations
    table = np.array([known.load(t) for t in times])
    table[:, model.coordinate_indices(list(RESIDUAL))] += fine.residual
    plant = with_loads(model, times, table, t0=start)
    inputs = fine.inputs()
    local = times - start

    def u(t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return np.array([np.interp(t, local, column) for column in inputs.T])

    run = simulate(plant, t_end=float(local[-1]), integrator="rk45", dt=step, rtol=rtol, atol=1e-12,
                   q0=fine.motion.q[0], qd0=fine.motion.qd[0], u=u)
    prescribed = Trajectory(local, fine.motion.q, fine.motion.qd, fine.motion.qdd, fine.motion.names)
    return run, prescribed
