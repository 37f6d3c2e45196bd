"""Forward dynamics of the recorded stride: open-loop replay and closed-loop tracking (issue 5,
item 3; thesis Pätkau, UPC, ch. 6-7; docs/gait.md).

Plant.  The subject's ``human`` model with **residual actuators** (``human(residual_actuators=True)``:
forces on hip.x, hip.z and a torque on the absolute trunk angle after the 11 joint torques), so
that all 14 independent coordinates z = :data:`~cmbs.gait.reconstruct.INDEPENDENT` are actuated
as in the thesis (§4.2, ch. 6) and in OpenSim.  Contact, as in :mod:`cmbs.gait.inverse`:

* ``"grf"``: the measured ground reaction forces at the centres of pressure are known loads.  Their
  generalized force Q_ext = [I - C, C]ᵀF on (ankle, toe) of each foot depends on t only (the CoP's
  foot coordinates are fixed per frame), so it is a force (I - C)ᵀF at the ankle point plus CᵀF at
  the toe point, each component a linear :class:`~cmbs.model.drivers.Table` between the frames
  (``human(point_forces=...)``; identical to :func:`cmbs.gait.inverse.with_loads` inside the
  stride, and compiled).  The residual actuators carry only the residual hip wrench.
* ``"hip"`` (variant (a), the thesis's): no ground; the residual actuators carry the whole contact
  wrench.

Open loop.  The 14 inverse-dynamics generalized forces Q_z at the frames (:func:`cmbs.gait.inverse.
inverse`), turned into inputs and interpolated by a cubic spline (:class:`cmbs.SampledInput`),
drive the plant from the recorded initial state; nothing corrects the drift (the unstable
inverted-pendulum dynamics of the upright body amplify the O(h⁴) input interpolation and RK4
errors), and :func:`departure` reports when |z - z_ref| first exceeds 5° or 5 cm.

Closed loop (thesis ch. 6), both on the 14 coordinates z, e = z_ref - z:

* PD:  τ_z = K_p e + K_d ė (+ the IDA forces as feed-forward), K_p = ω² m_z + k_c,
  K_d = 2 √(K_p m_z), with m_z the diagonal of the reduced mass matrix Rᵀ M R at the initial pose
  (q̇ = R ż): each coordinate, alone with the others held, is a critically damped oscillator of
  natural frequency ≥ ω.  k_c = m g ℓ_leg on the 12 angles (0 on hip.x, hip.z; m body mass, ℓ_leg
  thigh + shank) bounds the load stiffness |∂(r × F)/∂θ| ≤ |F||r| of a ground force of body
  weight acting a leg length from the joint: the GRF is a known force fixed in the foot, so a
  rotated foot turns it into a destabilizing moment (≈ 35 N m/rad about the ankle at heel strike)
  that ω² m_z alone (1.6 N m/rad for the 4·10⁻³ kg m² foot at ω = 20) cannot hold — without k_c
  the ankles do not settle in mode ``grf`` (NRMSE > 100 %).
* computed torque (:class:`cmbs.control.ComputedTorque`): τ_z = Rᵀ(M(R z̈_c + S) - Q),
  z̈_c = z̈_ref + K_d ė + K_p e, so that with the exact model ë + K_d ė + K_p e = 0; K_p = ω²,
  K_d = 2ω (critically damped: e(t) = (e₀ + (ė₀ + ω e₀) t) e^{-ωt}).

Default ω = 20 rad/s (K_p = 400 s⁻², K_d = 40 s⁻¹): an initial error decays to 1 % in
6.64/ω = 0.33 s, a third of the stride, and a constant unmodelled force d leaves an error d/(m_z ω²).

The reference for the controllers is the prepared stride's z resampled at the step (1 ms) from its
cubic spline through the frames (:func:`fine_motion`; :class:`~cmbs.control.Reference` splines it
again); only the independent columns of the resampled motion are used.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.interpolate import CubicSpline

from cmbs.control.base import Reference, input_map
from cmbs.control.computed_torque import ComputedTorque
from cmbs.control.pd import PD
from cmbs.control.study import Fault, TrackingRun, robustness_study
from cmbs.errors import CmbsError
from cmbs.gait.inverse import GRAVITY, MODES, grf_loads, inverse
from cmbs.gait.reconstruct import INDEPENDENT
from cmbs.inputs import SampledInput
from cmbs.kinematics import assemble, velocities
from cmbs.model.drivers import Table
from cmbs.model.model import Model
from cmbs.trajectory import Trajectory

CONTROLLERS = ("pd", "ctc")
OMEGA = 20.0            # rad/s: K_p = 400 s⁻², K_d = 40 s⁻¹ (module docstring)
STEP = 1e-3             # s: RK4 step and controller reference grid
ANGLE_LIMIT = np.radians(5.0)
DISTANCE_LIMIT = 0.05   # m


def grf_point_forces(model: Model, reference: Trajectory) -> dict[str, tuple[str, Table, Table]]:
    """The measured GRF at the CoPs as forces at the ankle and toe points of each foot
    ({name: (point, fx, fz)}, linear tables over the frames): the ankle gets (I - C)ᵀF, the toe
    CᵀF (module docstring), the columns of :func:`cmbs.gait.inverse.grf_loads`."""
    loads, _ = grf_loads(model, reference)
    forces = {}
    for side in "rl":
        for point in (f"{side}_ankle", f"{side}_toe"):
            cx, cz = model.coordinate_indices([f"{point}.x", f"{point}.z"])
            forces[f"grf_{point}"] = (point, Table(reference.t, loads[:, cx], "linear"),
                                      Table(reference.t, loads[:, cz], "linear"))
    return forces


def tracking_plant(model: Model, reference: Trajectory, contact: str = "grf") -> Model:
    """The subject's ``human`` model (``model``'s parameters) with residual actuators and, for
    ``contact`` ``grf``, the measured GRF as known point forces; initial state the reference's."""
    from cmbs.library import load_library_model

    if contact not in MODES:
        raise CmbsError(f"contact must be one of {', '.join(MODES)}, got {contact!r}")
    parameters = {k: v for k, v in model.parameters.items() if k not in ("residual_actuators", "point_forces")}
    forces = grf_point_forces(model, reference) if contact == "grf" else None
    plant = load_library_model("human", **parameters, residual_actuators=True, point_forces=forces)
    return plant.replace(q0=reference.q[0].copy(), qd0=reference.qd[0].copy())


def ida_forces(model: Model, reference: Trajectory, contact: str) -> np.ndarray:
    """(k, 14) inverse-dynamics generalized forces on :data:`INDEPENDENT` at the frames."""
    return inverse(model, reference, contact).forces


def ida_input(plant: Model, model: Model, reference: Trajectory, contact: str,
              interpolation: str = "spline") -> SampledInput:
    """The plant's inputs u(t) that realise the IDA forces, ``interpolation`` between the frames."""
    forces = ida_forces(model, reference, contact)
    return SampledInput(reference.t, forces @ input_map(plant, INDEPENDENT).T, interpolation)


def fine_motion(reference: Trajectory, step: float = STEP) -> Trajectory:
    """The reference resampled every ``step`` over the stride by its cubic spline through the
    frames (q, q̇, q̈ from the spline; constraint-consistent at the frames only)."""
    if not 0 < step < reference.t[-1] - reference.t[0]:
        raise CmbsError(f"step must be > 0 and shorter than the stride, got {step!r}")
    count = int(np.floor((reference.t[-1] - reference.t[0]) / step + 1e-9)) + 1
    times = reference.t[0] + step * np.arange(count)
    spline = CubicSpline(reference.t, reference.q, axis=0)
    return Trajectory(times, spline(times), spline(times, 1), spline(times, 2), reference.names,
                      info={"resampled": f"cubic spline through the frames every {step:g} s"})


def perturbed_state(plant: Model, reference: Trajectory, degrees: float, hip: float = 0.0
                    ) -> tuple[np.ndarray, np.ndarray]:
    """A wrong initial state: the trunk and the 11 joint angles ``degrees`` above the reference's
    first frame, the hip ``hip`` m forward and up, the dependent coordinates re-assembled with
    all 14 z held (Φ = 0), velocities ż of the reference (A q̇ = 0)."""
    q = reference.q[0].copy()
    columns = plant.coordinate_indices(list(INDEPENDENT))
    q[columns[:2]] += hip
    q[columns[2:]] += np.radians(degrees)
    q = assemble(plant, q, fixed=list(INDEPENDENT), tolerance=1e-12)
    qd = velocities(plant, q, qd=reference.qd[0], fixed=list(INDEPENDENT))
    return q, qd


def reduced_inertia(plant: Model, q: np.ndarray) -> np.ndarray:
    """Diagonal of Rᵀ M R (q̇ = R ż, columns of R from A q̇ = 0 with ż = e_i): the inertia
    [kg, kg m²] of each independent coordinate moving alone."""
    columns = plant.coordinate_indices(list(INDEPENDENT))
    M = plant.mass_matrix(q)
    diagonal = np.zeros(len(columns))
    for i, c in enumerate(columns):
        unit = np.zeros(plant.n)
        unit[c] = 1.0
        r = velocities(plant, q, qd=unit, fixed=list(INDEPENDENT))
        diagonal[i] = r @ M @ r
    return diagonal


def controller(kind: str, plant: Model, model: Model, reference: Trajectory, contact: str, *,
               omega: float = OMEGA, feed_forward: bool = True, step: float = STEP):
    """The ``pd`` or ``ctc`` law (module docstring) on the nominal ``plant``, following
    :func:`fine_motion` of ``reference``."""
    if kind not in CONTROLLERS:
        raise CmbsError(f"controller must be one of {', '.join(CONTROLLERS)}, got {kind!r}")
    if not omega > 0:
        raise CmbsError(f"omega must be > 0, got {omega!r}")
    target = Reference(fine_motion(reference, step), INDEPENDENT)
    if kind == "ctc":
        return ComputedTorque(plant, target, kp=omega**2, kd=2 * omega)
    kp, kd = pd_gains(plant, reference.q[0], omega)
    forces = SampledInput(reference.t, ida_forces(model, reference, contact), "spline") if feed_forward else None
    return PD(plant, target, kp=kp, kd=kd, feed_forward=forces)


def pd_gains(plant: Model, q: np.ndarray, omega: float = OMEGA) -> tuple[np.ndarray, np.ndarray]:
    """(K_p, K_d) of the PD law on :data:`INDEPENDENT`: K_p = ω² m_z + k_c, K_d = 2√(K_p m_z)
    (module docstring; m_z from :func:`reduced_inertia` at ``q``)."""
    inertia = reduced_inertia(plant, q)
    hip, knee, ankle = (q[plant.coordinate_indices([f"{p}.x", f"{p}.z"])] for p in ("hip", "r_knee", "r_ankle"))
    leg = np.linalg.norm(knee - hip) + np.linalg.norm(ankle - knee)
    load = np.r_[0.0, 0.0, np.full(len(INDEPENDENT) - 2, plant.total_mass * GRAVITY * leg)]
    kp = omega**2 * inertia + load
    return kp, 2.0 * np.sqrt(kp * inertia)


@dataclass(frozen=True)
class OpenLoop:
    """Open-loop replay: the ``run``, the errors z - z_ref (k, 14) at its times, and the first
    time ``departed`` (inf if never) an angle error exceeds ``angle_limit`` or a hip error
    ``distance_limit``, with the coordinate that did."""

    run: Trajectory
    error: np.ndarray
    departed: float
    coordinate: str
    angle_limit: float
    distance_limit: float


def departure(run: Trajectory, reference: Trajectory, *, angle: float = ANGLE_LIMIT,
              distance: float = DISTANCE_LIMIT) -> tuple[np.ndarray, float, str]:
    """Errors z - z_ref of ``run`` (reference spline at its times), the first time |error|
    exceeds ``distance`` [m] on hip.x/hip.z or ``angle`` [rad] on an angle, and which."""
    columns = [run.names.index(name) for name in INDEPENDENT]
    spline = CubicSpline(reference.t, reference.q[:, columns], axis=0)
    error = run.q[:, columns] - spline(run.t)
    limits = np.array([distance, distance] + [angle] * (len(INDEPENDENT) - 2))
    over = np.abs(error) > limits
    rows = np.flatnonzero(over.any(axis=1))
    if rows.size == 0:
        return error, float("inf"), ""
    return error, float(run.t[rows[0]]), INDEPENDENT[int(np.flatnonzero(over[rows[0]])[0])]


def open_loop(model: Model, reference: Trajectory, contact: str = "grf", *, t_end: float | None = None,
              step: float = STEP, interpolation: str = "spline") -> OpenLoop:
    """Replay the IDA forces (spline inputs) through the forward dynamics of the plant from the
    recorded initial state (RK4, ``step``, Lagrange) over ``t_end`` (default the stride)."""
    from cmbs.simulate import simulate

    plant = tracking_plant(model, reference, contact)
    t_end = float(reference.t[-1]) if t_end is None else t_end
    run = simulate(plant, t_end=t_end, integrator="rk4", dt=step, q0=reference.q[0], qd0=reference.qd[0],
                   u=ida_input(plant, model, reference, contact, interpolation))
    error, departed, coordinate = departure(run, reference)
    return OpenLoop(run, error, departed, coordinate, ANGLE_LIMIT, DISTANCE_LIMIT)


def tracking_study(model: Model, reference: Trajectory, kind: str = "ctc", *, contact: str = "grf",
                   faults: Sequence[str | Fault] = (), initial_error: float = 0.0, t_end: float | None = None,
                   omega: float = OMEGA, feed_forward: bool = True, step: float = STEP) -> list[TrackingRun]:
    """The nominal tracking run of controller ``kind`` and one run per fault
    (:func:`cmbs.control.study.robustness_study`), all from :func:`perturbed_state` with
    ``initial_error`` degrees (from the recorded state when 0), RK4 at ``step``."""
    plant = tracking_plant(model, reference, contact)
    law = controller(kind, plant, model, reference, contact, omega=omega, feed_forward=feed_forward, step=step)
    q0, qd0 = perturbed_state(plant, reference, initial_error) if initial_error else (reference.q[0], reference.qd[0])
    motion = fine_motion(reference, step)
    t_end = float(motion.t[-1]) if t_end is None else t_end
    if not 0 < t_end <= motion.t[-1] + 1e-12:
        raise CmbsError(f"t_end must lie in (0, {motion.t[-1]:g}] s (the stride), got {t_end!r}")
    return robustness_study(plant, law, motion, INDEPENDENT, t_end=t_end, faults=faults, q0=q0, qd0=qd0,
                            integrator="rk4")
