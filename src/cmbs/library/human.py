"""The 12-segment, 14-DOF planar human body of the thesis (Pätkau, UPC, §3.2.2, §4.2, Table 3.2).

13 points, 12 segments (trunk, head, 2 arms, 2 forearms with hands, 2 thighs, 2 shanks,
2 hind-feet), 26 point coordinates + 12 angles = 38 coordinates, 24 rigid-body constraints
(12 segment lengths, 12 angle definitions), 14 DOF: hip x, z, the trunk angle and 11 joint
angles.  x points forward, z up.

Anthropometry: Table 3.2 of the thesis for a male subject of 80 kg and 1.75 m.  Its PDF
extraction lost every '0' digit; the values below are the decoding with the fewest zeros
restored, with the inertia column in 10⁻² kg m² (the only reading that gives radii of gyration of
0.17-0.41 L).  Sum of masses: 80.639 kg.  The centre of mass is measured from the segment's first
point, along (x̄) and across (z̄, +90° from x̄).  De Leva (1996, J. Biomech. 29:1223) is the
published table the values were checked against; where the thesis's reading is ambiguous (head
and trunk COM), the thesis's printed value is kept.  ``body_mass`` and ``height`` scale the
table linearly (masses by M/80.639, lengths by H/1.75, inertias by both).  ``lengths`` replaces
the length of named segments (subject-specific, e.g. measured): a segment of length L' instead of
the scaled L keeps its mass and its COM fractions (x̄/L, z̄/L) and its radius-of-gyration fraction
k/L, so x̄' = x̄ L'/L, z̄' = z̄ L'/L and I' = m (k/L)² L'² = I (L'/L)² (I ∝ m L²).

Angles (counter-clockwise positive, all 0 when standing straight except the ankles):
``trunk`` absolute from the x axis (π/2 upright); ``neck`` from trunk (hip→neck) to head;
``r_hip``/``l_hip`` from the trunk's downward direction (neck→hip) to the thigh (flexion > 0);
``r_knee``/``l_knee`` from thigh to shank (flexion < 0); ``r_ankle``/``l_ankle`` from shank to
foot (ankle→toe; 60.7° standing); ``r_shoulder``/``l_shoulder`` from neck→hip to the arm
(flexion > 0); ``r_elbow``/``l_elbow`` from arm to forearm (flexion > 0).
"""

from __future__ import annotations

from cmbs.model.model import Model
from cmbs.model.natural import NaturalModelBuilder

REFERENCE_HEIGHT = 1.75  # m

# segment: (length m, COM along m, COM across m, mass kg, I_G kg m²) — thesis Table 3.2 decoded
SEGMENTS = {
    "trunk": (0.498, 0.230, 0.0, 37.81, 0.44448),
    "head": (0.343, 0.139, 0.039, 5.119, 0.02163),
    "arm": (0.311, 0.146, 0.0, 1.922, 0.0119),
    "forearm": (0.376, 0.171, 0.0, 2.299, 0.00974),
    "thigh": (0.417, 0.154, 0.0, 9.284, 0.12215),
    "shank": (0.422, 0.170, 0.0, 4.08, 0.05153),
    "foot": (0.143, 0.037, -0.023, 1.27, 0.00441),
}

BILATERAL = ("arm", "forearm", "thigh", "shank", "foot")
REFERENCE_MASS = sum(values[3] * (2 if name in BILATERAL else 1) for name, values in SEGMENTS.items())
REFERENCE_MASS = round(REFERENCE_MASS, 9)  # 80.639 kg

# standing posture (heights add up to 1.75 m with the ankle 0.07 m above the ground)
ANKLE_HEIGHT = 0.07


def _positive(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0


def human(body_mass: float = REFERENCE_MASS, height: float = REFERENCE_HEIGHT, fixed_hip: bool = False,
          lengths: dict[str, float] | None = None, residual_actuators: bool = False,
          point_forces: dict[str, tuple[str, object, object]] | None = None) -> Model:
    """Build the 14-DOF human model standing upright, at rest; ``fixed_hip`` adds constant drivers
    holding the hip point where it stands (12 DOF left: the trunk and joint angles).

    ``residual_actuators`` adds, after the 11 joint actuators, ``f_hip_x``, ``f_hip_z`` (forces
    on hip.x, hip.z) and ``tau_trunk`` (torque between ground and trunk on the absolute trunk
    angle), so that all 14 DOF are actuated — OpenSim's residual actuators; the thesis drives the
    model the same way (§4.2, ch. 6).  ``point_forces`` ({name: (point, fx, fz)}) adds known
    forces in the ground frame at basic points, components numbers, expressions or tables of t
    (:class:`cmbs.model.drivers.Table`; e.g. measured ground reaction forces).

    ``lengths`` ({segment: L' [m]}, segments ``trunk, head, arm, forearm, thigh, shank, foot``;
    bilateral ones set both sides) overrides the linearly scaled length L = L_table·H/1.75 of those
    segments.  Each keeps its mass, its COM fractions and its radius-of-gyration fraction:
    x̄' = x̄ L'/L, z̄' = z̄ L'/L, I_G' = I_G (L'/L)² (I = m k², k ∝ L; module docstring).  The
    standing posture stacks the new lengths (the head's top is then not at ``height``).
    """
    from cmbs.errors import ModelError

    for label, value in (("body_mass", body_mass), ("height", height)):
        if not _positive(value):
            raise ModelError(f"{label} must be a positive number, got {value!r}", entry="human")
    km, kl = body_mass / REFERENCE_MASS, height / REFERENCE_HEIGHT
    seg = {name: (l * kl, a * kl, c * kl, m * km, i * km * kl**2) for name, (l, a, c, m, i) in SEGMENTS.items()}
    if lengths is not None:
        if not isinstance(lengths, dict):
            raise ModelError(f"lengths must be a dict {{segment: length}}, got {lengths!r}", entry="human")
        for name, value in lengths.items():
            if name not in SEGMENTS:
                raise ModelError(f"lengths: unknown segment {name!r} (segments: {', '.join(SEGMENTS)})",
                                 entry="human")
            if not _positive(value):
                raise ModelError(f"lengths[{name!r}] must be a positive number, got {value!r}", entry="human")
            length, along, across, mass, inertia = seg[name]
            r = value / length
            seg[name] = (float(value), along * r, across * r, mass, inertia * r**2)
    foot_length = seg["foot"][0]
    ankle = ANKLE_HEIGHT * kl
    if foot_length <= ankle:
        raise ModelError(f"lengths['foot'] = {foot_length!r} m must exceed the standing ankle height "
                         f"{ankle:.4g} m", entry="human")
    toe_x = (foot_length**2 - ankle**2) ** 0.5
    knee = ankle + seg["shank"][0]
    hip = knee + seg["thigh"][0]
    neck = hip + seg["trunk"][0]
    elbow = neck - seg["arm"][0]
    builder = NaturalModelBuilder(
        "human",
        description=f"12-segment 14-DOF planar human body ({body_mass:g} kg, {height:g} m"
                    f"{', subject-specific lengths' if lengths else ''}), standing",
        source="O. Pätkau, UPC thesis §3.2.2, Table 3.2 (80 kg, 1.75 m male; decoded), checked against "
               "de Leva 1996")
    builder.add_point("hip", 0.0, hip)
    builder.add_point("neck", 0.0, neck)
    builder.add_point("head", 0.0, neck + seg["head"][0])
    for side in ("r", "l"):
        builder.add_point(f"{side}_knee", 0.0, knee)
        builder.add_point(f"{side}_ankle", 0.0, ankle)
        builder.add_point(f"{side}_toe", toe_x, 0.0)
        builder.add_point(f"{side}_elbow", 0.0, elbow)
        builder.add_point(f"{side}_wrist", 0.0, elbow - seg["forearm"][0])

    def segment(name: str, kind: str, i: str, j: str) -> None:
        length, along, across, mass, inertia = seg[kind]
        builder.add_segment(name, i, j, mass=mass, com=(along, across), inertia=inertia, length=length)

    segment("trunk", "trunk", "hip", "neck")
    segment("head", "head", "neck", "head")
    for side in ("r", "l"):
        segment(f"{side}_arm", "arm", "neck", f"{side}_elbow")
        segment(f"{side}_forearm", "forearm", f"{side}_elbow", f"{side}_wrist")
        segment(f"{side}_thigh", "thigh", "hip", f"{side}_knee")
        segment(f"{side}_shank", "shank", f"{side}_knee", f"{side}_ankle")
        segment(f"{side}_foot", "foot", f"{side}_ankle", f"{side}_toe")

    builder.add_angle("trunk", segment="trunk")
    builder.add_angle("neck", from_segment="trunk", to_segment="head")
    down = ("neck", "hip")
    for side in ("r", "l"):
        builder.add_angle(f"{side}_hip", from_segment=down, to_segment=f"{side}_thigh")
        builder.add_angle(f"{side}_knee", from_segment=f"{side}_thigh", to_segment=f"{side}_shank")
        builder.add_angle(f"{side}_ankle", from_segment=f"{side}_shank", to_segment=f"{side}_foot")
        builder.add_angle(f"{side}_shoulder", from_segment=down, to_segment=f"{side}_arm")
        builder.add_angle(f"{side}_elbow", from_segment=f"{side}_arm", to_segment=f"{side}_forearm")
    if fixed_hip:
        builder.add_driver("hip.x", 0.0, name="hip x fixed")
        builder.add_driver("hip.z", hip, name="hip z fixed")
    for joint in ("neck", "r_hip", "r_knee", "r_ankle", "r_shoulder", "r_elbow",
                  "l_hip", "l_knee", "l_ankle", "l_shoulder", "l_elbow"):
        builder.add_actuator(f"tau_{joint}", coordinate=joint)
    if residual_actuators:
        builder.add_actuator("f_hip_x", coordinate="hip.x")
        builder.add_actuator("f_hip_z", coordinate="hip.z")
        builder.add_actuator("tau_trunk", coordinate="trunk")
    if point_forces is not None:
        if not isinstance(point_forces, dict):
            raise ModelError(f"point_forces must be a dict {{name: (point, fx, fz)}}, got {point_forces!r}",
                             entry="human")
        for name, spec in point_forces.items():
            if not (isinstance(spec, tuple) and len(spec) == 3):
                raise ModelError(f"point_forces[{name!r}] must be (point, fx, fz), got {spec!r}", entry="human")
            builder.add_force(name, point=spec[0], fx=spec[1], fz=spec[2])
    model = builder.build()
    parameters = {"body_mass": body_mass, "height": height, "fixed_hip": fixed_hip}
    if residual_actuators:
        parameters["residual_actuators"] = True
    if point_forces is not None:
        parameters["point_forces"] = sorted(point_forces)
    if lengths is not None:
        parameters["lengths"] = {name: float(value) for name, value in lengths.items()}
    return model.replace(parameters=parameters)
