"""Gait results in the coordinates of OpenSim's full-body gait model (Rajagopal et al. 2016,
*IEEE Trans. Biomed. Eng.* 63:2068, file ``Rajagopal2015.osim`` of opensim-models); docs/gait.md
has the table.

OpenSim's frame is X forward, Y up, Z to the subject's right; ``pelvis_tilt``, ``hip_flexion_r``
and ``arm_flex_r`` are rotations about Z (joint axis ``0 0 1``, unrotated joint frames), positive
counter-clockwise seen from the right, i.e. from the cmbs model's +x (forward) towards +z (up):
the cmbs sense; knee, ankle and elbow (rotated frames, oblique axes) follow from their ranges
(knee 0-120°, elbow 0-150°: flexion > 0) and the model's reference IK output (ankle > 0 in
dorsiflexion).  Each OpenSim joint angle is then ``s (q - q₀)`` with the cmbs relative angle q,
its neutral value q₀ (OpenSim's 0: the model's standing pose ``model.q0``, every angle 0 there
except the ankles) and s = +1, except the knee (s = -1: cmbs knee flexion < 0).
Ankle: OpenSim's 0 is the foot flat with the shank vertical; the cmbs foot is the line from the
ankle to the "toe" point, whose angle to the sole depends on where the toe point sits (the
library model's standing pose puts it on the ground, 60.7°; the reconstruction puts it at the
subject's HBM2 foot origin, near ankle height), so the neutral ankle angle is measured on the
recorded stride by :func:`ankle_neutral` (foot flat in mid-stance) and passed in.  The cmbs trunk
(hip → neck) is one rigid segment: pelvis and torso move together, ``pelvis_tilt`` = trunk - 90°
(> 0 leaning back, i.e. posterior tilt) and ``lumbar_extension`` = 0.  ``pelvis_tx``,
``pelvis_ty`` place the pelvis origin, which is at p = hip - R(tilt) h from the cmbs hip point
(midpoint of the hip joint centres), h = the hip centres' position in the pelvis frame
(``hip_r``'s ``location_in_parent`` (-0.056276, -0.07849, 0.07726) m: (x, y) of
:data:`HIP_IN_PELVIS`).  The cmbs neck angle (> 0 head back) has no counterpart (the model's
head is part of its torso): column ``neck_extension``.

Generalized forces (an OpenSim inverse-dynamics ``.sto``: ``<coordinate>_moment`` [N m],
``<coordinate>_force`` [N]) follow from the same map by virtual work, Q_os·δq_os = Q·δq: a joint
moment is s τ; the hip wrench (F_x, F_z on hip.x, hip.z; τ about the hip on the trunk angle)
becomes ``pelvis_tx_force`` = F_x, ``pelvis_ty_force`` = F_z and ``pelvis_tilt_moment`` =
τ + (R(tilt) h) × F, the same wrench about the pelvis origin.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from cmbs.errors import CmbsError
from cmbs.gait.reconstruct import INDEPENDENT
from cmbs.model.model import Model
from cmbs.opensim_files import write_storage
from cmbs.trajectory import Trajectory

#: (x, y) of the right hip joint centre in the pelvis frame of Rajagopal2015.osim [m] (the left
#: one mirrors z), so also of the midpoint of both, the cmbs hip point.
HIP_IN_PELVIS = (-0.056276, -0.07849)
#: cmbs relative angle -> (OpenSim coordinate, sign s); OpenSim = s (q - q₀).
ANGLES = {
    "r_hip": ("hip_flexion_r", 1.0), "r_knee": ("knee_angle_r", -1.0), "r_ankle": ("ankle_angle_r", 1.0),
    "l_hip": ("hip_flexion_l", 1.0), "l_knee": ("knee_angle_l", -1.0), "l_ankle": ("ankle_angle_l", 1.0),
    "r_shoulder": ("arm_flex_r", 1.0), "r_elbow": ("elbow_flex_r", 1.0),
    "l_shoulder": ("arm_flex_l", 1.0), "l_elbow": ("elbow_flex_l", 1.0),
    "neck": ("neck_extension", 1.0),
}
#: Columns written that name no coordinate of the OpenSim model.
NO_COUNTERPART = ("neck_extension",)
KINEMATICS_NAME = "Coordinates"                             # as OpenSim's inverse kinematics
MOMENTS_NAME = "Inverse Dynamics Generalized Forces"        # as OpenSim's inverse dynamics


def ankle_neutral(reference: Trajectory, *, rate: float = 0.5) -> dict[str, float]:
    """Neutral (OpenSim 0) values [rad] of the cmbs ankle angles ``r_ankle``, ``l_ankle`` from a
    recorded stride (:func:`cmbs.gait.prepare_stride`'s motion).

    With the foot flat on the ground its line ankle → toe makes the angle α_flat with the
    horizontal; with the shank also vertical (pointing down, -90°) the cmbs ankle angle, from
    shank to foot, is α_flat + 90°.  α_flat is the median foot-line angle over the frames where
    the foot is loaded (``<side>_contact``) and turns slower than ``rate`` rad/s (finite
    differences): mid-stance.  Stride 1: 34 right and 17 left frames (13-46 and 69-85 of 114),
    α_flat = -7.0° and -1.7°, neutral 83.0° and 88.3°; the library's standing pose would give
    58.9° (toe point on the ground), 24-29° away.

    Raises
    ------
    CmbsError
        ``reference`` without the contact extras or the foot coordinates, non-positive
        ``rate``, or no loaded frame that slow.
    """
    if not (isinstance(rate, (int, float)) and np.isfinite(rate) and rate > 0):
        raise CmbsError(f"rate must be a positive number [rad/s], got {rate!r}")
    neutral = {}
    for side in ("r", "l"):
        needed = [f"{side}_ankle.x", f"{side}_ankle.z", f"{side}_toe.x", f"{side}_toe.z"]
        missing = [name for name in needed if name not in reference.names] + \
            ([f"{side}_contact"] if f"{side}_contact" not in reference.extras else [])
        if missing:
            raise CmbsError(f"the neutral ankle angle needs the recorded stride's {', '.join(missing)} "
                            "(cmbs gait prepare)")
        ankle_x, ankle_z, toe_x, toe_z = (np.asarray(reference[name], dtype=float) for name in needed)
        foot = np.arctan2(toe_z - ankle_z, toe_x - ankle_x)
        loaded = np.asarray(reference[f"{side}_contact"], dtype=bool)
        flat = loaded & (np.abs(np.gradient(foot, reference.t)) < rate) if len(foot) > 1 else loaded
        if not np.any(flat):
            raise CmbsError(f"no frame with the {side} foot loaded and turning slower than {rate:g} rad/s: "
                            "cannot find its flat-foot angle")
        neutral[f"{side}_ankle"] = float(np.median(foot[flat]) + np.pi / 2)
    return neutral


def kinematics(model: Model, motion: Trajectory, *, ankle: dict[str, float] | None = None,
               hip_in_pelvis: tuple[float, float] = HIP_IN_PELVIS) -> dict[str, np.ndarray]:
    """OpenSim coordinates of ``motion`` (a motion of the ``human`` ``model``: the reference or a
    simulated run): ``{name: (k,) values}``, angles in degrees, ``pelvis_tx``/``pelvis_ty`` in
    metres (module docstring).  ``ankle``: neutral ``r_ankle``/``l_ankle`` [rad]
    (:func:`ankle_neutral` of the recorded stride); None takes the model's standing pose.

    Raises
    ------
    CmbsError
        ``motion`` lacks one of the 14 independent coordinates, ``ankle`` has other keys than
        ``r_ankle``/``l_ankle`` or non-finite values, or ``hip_in_pelvis`` is not two finite
        numbers.
    """
    z, standing = _independent(model, motion), _standing(model)
    if ankle is not None:
        if not (isinstance(ankle, dict) and set(ankle) <= {"r_ankle", "l_ankle"}
                and all(isinstance(value, (int, float, np.floating)) and np.isfinite(value)
                        for value in ankle.values())):
            raise CmbsError(f"ankle must map r_ankle/l_ankle to finite neutral angles [rad], got {ankle!r}")
        standing.update(ankle)
    tilt = z["trunk"] - standing["trunk"]
    origin = np.stack([z["hip.x"], z["hip.z"]], axis=1) - _rotated(tilt, _offset(hip_in_pelvis))
    columns = {"pelvis_tilt": np.degrees(tilt), "pelvis_tx": origin[:, 0], "pelvis_ty": origin[:, 1]}
    for joint in ("r_hip", "r_knee", "r_ankle", "l_hip", "l_knee", "l_ankle"):
        name, sign = ANGLES[joint]
        columns[name] = np.degrees(sign * (z[joint] - standing[joint]))
    columns["lumbar_extension"] = np.zeros_like(tilt)
    for joint in ("r_shoulder", "r_elbow", "l_shoulder", "l_elbow", "neck"):
        name, sign = ANGLES[joint]
        columns[name] = np.degrees(sign * (z[joint] - standing[joint]))
    return columns


def generalized_forces(model: Model, motion: Trajectory, forces: np.ndarray, *,
                       hip_in_pelvis: tuple[float, float] = HIP_IN_PELVIS) -> dict[str, np.ndarray]:
    """OpenSim inverse-dynamics columns of ``forces`` (k, 14), the generalized forces on
    :data:`cmbs.gait.INDEPENDENT` at the poses of ``motion`` (e.g.
    :attr:`cmbs.gait.inverse.GaitInverse.forces`): ``pelvis_tilt_moment``, ``pelvis_tx_force``,
    ``pelvis_ty_force`` [N m, N] and ``<coordinate>_moment`` [N m] of each joint (module
    docstring).

    Raises
    ------
    CmbsError
        ``forces`` not (k, 14) for the k instants of ``motion``, or as :func:`kinematics`.
    """
    forces = np.asarray(forces, dtype=float)
    if forces.shape != (len(motion.t), len(INDEPENDENT)):
        raise CmbsError(f"forces must have shape ({len(motion.t)}, {len(INDEPENDENT)}) (instants, independent "
                        f"coordinates), got {forces.shape}")
    z, standing = _independent(model, motion), _standing(model)
    lever = _rotated(z["trunk"] - standing["trunk"], _offset(hip_in_pelvis))      # origin -> hip
    force = forces[:, :2]
    columns = {"pelvis_tilt_moment": forces[:, 2] + lever[:, 0] * force[:, 1] - lever[:, 1] * force[:, 0],
               "pelvis_tx_force": force[:, 0], "pelvis_ty_force": force[:, 1]}
    for joint, (name, sign) in ANGLES.items():
        columns[f"{name}_moment"] = sign * forces[:, INDEPENDENT.index(joint)]
    return columns


def write_kinematics(path: str | os.PathLike, model: Model, motion: Trajectory, *,
                     ankle: dict[str, float] | None = None) -> Path:
    """:func:`kinematics` of ``motion`` as an OpenSim motion file (``.mot`` or ``.sto``,
    ``inDegrees=yes``); returns the path."""
    return write_storage(path, motion.t, kinematics(model, motion, ankle=ankle), in_degrees=True,
                         name=KINEMATICS_NAME)


def write_moments(path: str | os.PathLike, model: Model, motion: Trajectory, forces: np.ndarray) -> Path:
    """:func:`generalized_forces` as an OpenSim inverse-dynamics storage file (``.sto`` or
    ``.mot``, ``inDegrees=no``); returns the path."""
    return write_storage(path, motion.t, generalized_forces(model, motion, forces), in_degrees=False,
                         name=MOMENTS_NAME)


def _independent(model: Model, motion: Trajectory) -> dict[str, np.ndarray]:
    missing = [name for name in INDEPENDENT if name not in motion.names]
    if missing:
        raise CmbsError(f"the motion lacks the human model's coordinates {', '.join(missing)}")
    return {name: np.asarray(motion[name], dtype=float) for name in INDEPENDENT}


def _standing(model: Model) -> dict[str, float]:
    """The independent coordinates at the model's standing pose q0."""
    missing = [name for name in INDEPENDENT if name not in model.coordinate_names]
    if missing:
        raise CmbsError(f"model {model.name!r} lacks the human model's coordinates {', '.join(missing)}")
    return {name: float(model.q0[model.coordinate_index(name)]) for name in INDEPENDENT}


def _offset(hip_in_pelvis: tuple[float, float]) -> np.ndarray:
    offset = np.asarray(hip_in_pelvis, dtype=float)
    if offset.shape != (2,) or not np.all(np.isfinite(offset)):
        raise CmbsError(f"hip_in_pelvis must be two finite numbers (x, y) [m], got {hip_in_pelvis!r}")
    return offset


def _rotated(angle: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """(k, 2) R(angle) vector, counter-clockwise."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * vector[0] - s * vector[1], s * vector[0] + c * vector[1]], axis=1)
