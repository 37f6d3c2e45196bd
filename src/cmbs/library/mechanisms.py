"""Builders of the library mechanisms taken from Aghili (2005) and Quasem, Uhlar & Betsch (2009),
a fully actuated two-link arm and the Chaplygin sleigh, in natural or joint coordinates.
Parameter values and their status (read from the source or chosen) are given in each docstring;
docs/models.md collects them."""

from __future__ import annotations

import math

import numpy as np

from cmbs.errors import CmbsError
from cmbs.model.model import Model
from cmbs.model.natural import NaturalModelBuilder


def slider_crank(gravity: float = 0.0, crank_angle: float = 45.0, crank_speed: float = 2.0) -> Model:
    """Aghili's slider-crank with equal crank and rod (§VIII) in natural coordinates.

    Crank O-A and rod A-C: 1 m, 1 kg uniform rods (I_G = m l²/12), slider C massless on the
    ground x axis through O; angle coordinates ``theta1`` (crank, absolute) and ``theta2`` (rod
    relative to crank), the joint coordinates of the joint-coordinate version; actuators on both.
    The constraint Jacobian loses rank at θ1 = ±90° where C passes through O.  Aghili gives no
    numbers that survived extraction: l = 1 m, m = 1 kg are chosen; ``gravity`` (m/s², along -z)
    defaults to 0 (a horizontal mechanism).  Start: crank at ``crank_angle`` degrees turning at
    ``crank_speed`` rad/s (the benchmark state: 45°, 2 rad/s), rod on the branch
    θ2 = -2θ1; without gravity the crank then turns fully, crossing the singular positions.
    """
    theta = math.radians(crank_angle)
    builder = NaturalModelBuilder(
        "slider-crank", gravity=(0.0, -gravity),
        description="slider-crank with equal crank and rod (1 m, 1 kg), slider on the x axis; singular at 90 deg",
        source="F. Aghili, IEEE T-RO 21(5) 2005, §VIII (l = 1 m, m = 1 kg chosen: digits lost)")
    builder.add_point("O", 0.0, 0.0, fixed=True)
    builder.add_point("A", math.cos(theta), math.sin(theta))
    builder.add_point("C", 2.0 * math.cos(theta), 0.0)
    for name, i, j in (("crank", "O", "A"), ("rod", "A", "C")):
        builder.add_segment(name, i, j, mass=1.0, com=(0.5, 0.0), inertia=1.0 / 12.0, length=1.0)
    builder.add_slider("slider", point="C", through=(0.0, 0.0), direction=(1.0, 0.0))
    builder.add_angle("theta1", segment="crank")
    builder.add_angle("theta2", from_segment="crank", to_segment="rod")
    builder.add_actuator("tau1", coordinate="theta1")
    builder.add_actuator("tau2", coordinate="theta2")
    model = builder.build()
    omega, s, c = crank_speed, math.sin(theta), math.cos(theta)
    velocities = {"A.x": -omega * s, "A.z": omega * c, "C.x": -2.0 * omega * s, "C.z": 0.0,
                  "theta1": omega, "theta2": -2.0 * omega}
    qd0 = [velocities[name] for name in model.coordinate_names]
    return model.replace(qd0=qd0, parameters={"gravity": gravity, "crank_angle": crank_angle,
                                              "crank_speed": crank_speed})


def slider_crank_branch(times: np.ndarray, gravity: float = 0.0, crank_angle: float = 45.0,
                        crank_speed: float = 2.0, rtol: float = 1e-13) -> tuple[np.ndarray, np.ndarray]:
    """Crank angle θ1 and speed θ̇1 at ``times`` of :func:`slider_crank` (same parameters), from
    its motion on the assembly branch θ2 = -2θ1 written as one smooth ODE: a reference that no
    singular position disturbs.

    On that branch the rod's absolute angle is -θ1, so the crank's centre of mass is
    (cos θ1, sin θ1)/2, the rod's (3 cos θ1, sin θ1)/2, both bodies turn at ±θ̇1 and the massless
    slider adds nothing (Lagrange's equations of the reduced system)::

        T = m(θ1) θ̇1² / 2,   m(θ1) = 2/3 + 2 sin²θ1,   V = g sin θ1
        m(θ1) θ̈1 + sin(2θ1) θ̇1² + g cos θ1 = 0

    m never vanishes, so the ODE is regular at θ1 = ±90°, where the constraint Jacobian of the
    mechanism loses rank.  Integrated by DOP853 (scipy) at ``rtol`` and atol = rtol / 10.
    """
    from scipy.integrate import solve_ivp

    def field(_t: float, state: np.ndarray) -> list[float]:
        theta, omega = state
        return [omega, -(math.sin(2.0 * theta) * omega ** 2 + gravity * math.cos(theta))
                / (2.0 / 3.0 + 2.0 * math.sin(theta) ** 2)]

    times = np.asarray(times, dtype=float)
    if times.ndim != 1 or not times.size or not np.all(np.isfinite(times)) or times[0] < 0 \
            or np.any(np.diff(times) < 0):
        raise CmbsError(f"slider-crank branch reference: times must be a non-empty, non-decreasing sequence of "
                        f"finite times >= 0, got {np.array2string(times, threshold=6)}")
    solution = solve_ivp(field, (0.0, float(times[-1])), [math.radians(crank_angle), crank_speed], method="DOP853",
                         t_eval=times, rtol=rtol, atol=rtol / 10.0)
    if not solution.success:
        raise CmbsError(f"slider-crank branch reference: {solution.message}")
    return solution.y[0], solution.y[1]


def passive_manipulator(gravity: float = 0.0) -> Model:
    """3-link planar manipulator with a passive third joint (Quasem, Uhlar & Betsch 2009, after
    De Luca & Oriolo 2002), in natural coordinates.

    Links of 5 m, 10 kg, COM at mid-link (read: l_i = 2 r_i), I_G = m l²/12; the lengths and
    masses are chosen (the source's values were lost).  Horizontal plane (``gravity`` 0 by
    default).  Angle coordinates ``theta1`` (absolute), ``theta2``, ``theta3`` (relative); the
    actuators act on θ1 and θ2 only — joint 3 is free.  Start: θ = (90°, -90°, 0°), at rest.
    """
    builder = NaturalModelBuilder(
        "passive-manipulator", gravity=(0.0, -gravity),
        description="3-link planar arm (5 m, 10 kg links), joint 3 passive; actuators tau1, tau2",
        source="Quasem, Uhlar & Betsch, PAMM 9 (2009); De Luca & Oriolo, IJRR 21 (2002) (values chosen)")
    builder.add_point("O", 0.0, 0.0, fixed=True)
    for name, (x, z) in {"P1": (0.0, 5.0), "P2": (5.0, 5.0), "P3": (10.0, 5.0)}.items():
        builder.add_point(name, x, z)
    for k, (i, j) in enumerate((("O", "P1"), ("P1", "P2"), ("P2", "P3")), start=1):
        builder.add_segment(f"link{k}", i, j, mass=10.0, com=(2.5, 0.0), inertia=10.0 * 25.0 / 12.0, length=5.0)
    builder.add_angle("theta1", segment="link1")
    builder.add_angle("theta2", from_segment="link1", to_segment="link2")
    builder.add_angle("theta3", from_segment="link2", to_segment="link3")
    builder.add_actuator("tau1", coordinate="theta1")
    builder.add_actuator("tau2", coordinate="theta2")
    model = builder.build()
    return model.replace(parameters={"gravity": gravity})


def slider_crank_joint(gravity: float = 0.0, crank_angle: float = 45.0, crank_speed: float = 2.0) -> Model:
    """Aghili's slider-crank (§VIII) in his joint coordinates (θ1, θ2), the same mechanism and
    start as :func:`slider_crank`.  Loop closed at the rod end C: z_C = l sin θ1 + l sin(θ1+θ2) = 0."""
    from cmbs.model.joints import JointModelBuilder

    theta = math.radians(crank_angle)
    builder = JointModelBuilder(
        "slider-crank-joint", gravity=(0.0, -gravity),
        description="slider-crank with equal crank and rod (1 m, 1 kg) in joint angles theta1, theta2",
        source="F. Aghili, IEEE T-RO 21(5) 2005, §VIII, eq. (64) (l = 1 m, m = 1 kg chosen: digits lost)")
    builder.add_link("crank", parent=None, coordinate="theta1", length=1.0, mass=1.0, com=(0.5, 0.0),
                     inertia=1.0 / 12.0, q0=theta, qd0=crank_speed)
    builder.add_link("rod", parent="crank", coordinate="theta2", origin=(1.0, 0.0), length=1.0, mass=1.0,
                     com=(0.5, 0.0), inertia=1.0 / 12.0, q0=-2.0 * theta, qd0=-2.0 * crank_speed)
    builder.add_closure("slider", point="rod.end", to=(0.0, 0.0), directions="z")
    builder.add_actuator("tau1", coordinate="theta1")
    builder.add_actuator("tau2", coordinate="theta2")
    model = builder.build()
    return model.replace(parameters={"gravity": gravity, "crank_angle": crank_angle, "crank_speed": crank_speed})


def arm_on_slider(gravity: float = 0.0) -> Model:
    """Aghili's experiment (§IX): a 3-link planar arm whose endpoint is pinned by a hinge to a
    slider running along a horizontal line z = 0.5 m, in joint angles θ1, θ2, θ3; three
    actuated joints, 2 DOF (redundantly actuated).

    The Canadian Space Agency arm's dimensions did not survive extraction; chosen: links 0.5,
    0.5, 0.25 m of 3.0, 2.0, 0.8 kg (uniform rods, I_G = m l²/12), a horizontal table
    (``gravity`` 0).  Start: endpoint at (0.45, 0.5) with link 3 pointing down (φ = -90°), elbow
    down, at rest.
    """
    from cmbs.model.joints import JointModelBuilder

    lengths, masses = (0.5, 0.5, 0.25), (3.0, 2.0, 0.8)
    wrist = np.array([0.45, 0.5 + lengths[2]])
    distance = float(np.hypot(*wrist))
    elbow = math.acos((distance**2 - lengths[0] ** 2 - lengths[1] ** 2) / (2 * lengths[0] * lengths[1]))
    shoulder = math.atan2(wrist[1], wrist[0]) + math.atan2(lengths[1] * math.sin(elbow),
                                                            lengths[0] + lengths[1] * math.cos(elbow))
    angles = (shoulder, -elbow, -math.pi / 2 - shoulder + elbow)
    builder = JointModelBuilder(
        "arm-on-slider", gravity=(0.0, -gravity),
        description="3-link arm (0.5, 0.5, 0.25 m) with its endpoint on a horizontal slider z = 0.5 m; 2 DOF, 3 motors",
        source="F. Aghili, IEEE T-RO 21(5) 2005, §IX experiment (dimensions chosen: digits lost)")
    parent = None
    for k, (length, mass, angle) in enumerate(zip(lengths, masses, angles), start=1):
        builder.add_link(f"link{k}", parent=parent, coordinate=f"theta{k}",
                         origin=(0.0, 0.0) if parent is None else (lengths[k - 2], 0.0), length=length, mass=mass,
                         com=(length / 2, 0.0), inertia=mass * length**2 / 12.0, q0=angle)
        builder.add_actuator(f"tau{k}", coordinate=f"theta{k}")
        parent = f"link{k}"
    builder.add_closure("slider", point="link3.end", to=(0.0, 0.5), directions="z")
    model = builder.build()
    return model.replace(parameters={"gravity": gravity})


def passive_manipulator_joint(gravity: float = 0.0) -> Model:
    """The 3-link manipulator with passive third joint of :func:`passive_manipulator` in joint
    angles θ1, θ2, θ3 (same links, start and actuators τ1, τ2)."""
    from cmbs.model.joints import JointModelBuilder

    builder = JointModelBuilder(
        "passive-manipulator-joint", gravity=(0.0, -gravity),
        description="3-link planar arm (5 m, 10 kg links) in joint angles, joint 3 passive; actuators tau1, tau2",
        source="Quasem, Uhlar & Betsch, PAMM 9 (2009); De Luca & Oriolo, IJRR 21 (2002) (values chosen)")
    parent = None
    for k, angle in enumerate((math.pi / 2, -math.pi / 2, 0.0), start=1):
        builder.add_link(f"link{k}", parent=parent, coordinate=f"theta{k}",
                         origin=(0.0, 0.0) if parent is None else (5.0, 0.0), length=5.0, mass=10.0,
                         com=(2.5, 0.0), inertia=10.0 * 25.0 / 12.0, q0=angle)
        parent = f"link{k}"
    builder.add_actuator("tau1", coordinate="theta1")
    builder.add_actuator("tau2", coordinate="theta2")
    model = builder.build()
    return model.replace(parameters={"gravity": gravity})


def two_link_arm(theta1: float = -math.pi / 4, theta2: float = math.pi / 4, gravity: float = 9.81) -> Model:
    """Fully actuated two-link planar arm in natural coordinates: the ``double-pendulum`` library
    model with torque actuators ``tau1``, ``tau2`` on its angle coordinates (the arm of the
    Udwadia-Kalaba tracking example, control through constraints after Nicoara 2016 §5).

    Links ``upper`` O-P1 and ``lower`` P1-P2: uniform rods of 1 m and 1 kg, I_G = m l²/12
    (chosen, as in the double pendulum); O fixed.  Coordinates (P1.x, P1.z, P2.x, P2.z, theta1,
    theta2): ``theta1`` absolute, ``theta2`` relative (upper to lower); 4 constraints, 2 DOF; M is
    singular (the angle coordinates carry no mass).  ``gravity`` m/s² along -z (default 9.81).
    Start at rest at ``theta1``, ``theta2`` in radians, the start values of the coordinates of
    the same names (default -45°, +45°: the lower link horizontal, tip at (1 + √½, -√½)).
    """
    p1 = np.array([math.cos(theta1), math.sin(theta1)])
    p2 = p1 + [math.cos(theta1 + theta2), math.sin(theta1 + theta2)]
    builder = NaturalModelBuilder(
        "two-link-arm", gravity=(0.0, -gravity),
        description="fully actuated two-link arm: two uniform rods (1 m, 1 kg), torques tau1, tau2 on theta1, theta2",
        source="textbook compound double pendulum (uniform rods, I_G = m l^2/12) with joint torques "
               "(values chosen; Nicoara 2016 §5 for its use in control through constraints)")
    builder.add_point("O", 0.0, 0.0, fixed=True)
    builder.add_point("P1", *p1)
    builder.add_point("P2", *p2)
    for name, i, j in (("upper", "O", "P1"), ("lower", "P1", "P2")):
        builder.add_segment(name, i, j, mass=1.0, com=(0.5, 0.0), inertia=1.0 / 12.0, length=1.0)
    builder.add_angle("theta1", segment="upper", initial=theta1)
    builder.add_angle("theta2", from_segment="upper", to_segment="lower", initial=theta2)
    builder.add_actuator("tau1", coordinate="theta1")
    builder.add_actuator("tau2", coordinate="theta2")
    model = builder.build()
    return model.replace(parameters={"theta1": theta1, "theta2": theta2, "gravity": gravity})


def two_link_arm_joint(theta1: float = -math.pi / 4, theta2: float = math.pi / 4, gravity: float = 9.81,
                       tool: tuple[float, float] | None = None) -> Model:
    """The two-link arm of :func:`two_link_arm` in joint angles θ1 (absolute), θ2 (relative): the
    same links ``upper``, ``lower``, actuators, gravity and start, no constraints.  ``tool``
    (ξ, η) in the lower link's frame, m, adds a named point ``tool`` there (none by default)."""
    from cmbs.model.joints import JointModelBuilder

    builder = JointModelBuilder(
        "two-link-arm-joint", gravity=(0.0, -gravity),
        description="fully actuated two-link arm (1 m, 1 kg rods) in joint angles theta1, theta2; torques tau1, tau2",
        source="textbook compound double pendulum (uniform rods, I_G = m l^2/12) with joint torques "
               "(values chosen; Nicoara 2016 §5 for its use in control through constraints)")
    builder.add_link("upper", parent=None, coordinate="theta1", length=1.0, mass=1.0, com=(0.5, 0.0),
                     inertia=1.0 / 12.0, q0=theta1)
    builder.add_link("lower", parent="upper", coordinate="theta2", origin=(1.0, 0.0), length=1.0, mass=1.0,
                     com=(0.5, 0.0), inertia=1.0 / 12.0, q0=theta2)
    if tool is not None:
        builder.add_point("tool", link="lower", local=tool)
    builder.add_actuator("tau1", coordinate="theta1")
    builder.add_actuator("tau2", coordinate="theta2")
    model = builder.build()
    return model.replace(parameters={"theta1": theta1, "theta2": theta2, "gravity": gravity, "tool": tool})


def chaplygin_sleigh(mass: float = 1.0, inertia: float = 0.1, distance: float = 0.2, speed: float = 1.0,
                     angular_velocity: float = 1.0) -> Model:
    """The Chaplygin sleigh: a planar rigid body on a horizontal plane with a knife edge that
    allows no sideways sliding — the classic nonholonomic system (Chaplygin 1911; Bloch,
    *Nonholonomic Mechanics and Control*, §1.7).

    Coordinates (x, z, θ): the centre of mass G in the plane (x-z seen from above, so gravity
    does no work and is left out) and the heading θ of the body axis e₁ = (cos θ, sin θ).  The
    knife edge touches the plane at P = G - a e₁, a distance ``distance`` = a behind G; its
    velocity Ṗ = (ẋ + a sin θ θ̇, ż - a cos θ θ̇) must have no component along the normal
    e₂ = (-sin θ, cos θ)::

        -sin θ (ẋ + a sin θ θ̇) + cos θ (ż - a cos θ θ̇) = -sin θ ẋ + cos θ ż - a θ̇ = 0

    (a velocity constraint that is not integrable: 3 coordinates, 3 configuration DOF, 2 velocity
    DOF).  M = diag(m, m, I_G), no applied forces.  In the body-frame forward speed
    v = cos θ ẋ + sin θ ż and angular velocity ω = θ̇ the motion obeys m v̇ = m a ω²,
    (I_G + m a²) ω̇ = -m a v ω; E = ½ m v² + ½ (I_G + m a²) ω² is conserved and ω → 0,
    v → sqrt(2E/m).

    Values chosen (no source gives numbers): ``mass`` m = 1 kg, ``inertia`` I_G = 0.1 kg m²
    about G, ``distance`` a = 0.2 m.  Start: G at the origin heading along x (θ = 0), forward
    speed ``speed`` v = 1 m/s and ``angular_velocity`` ω = 1 rad/s, so q̇0 = (v, a ω, ω) (G
    moves sideways at a ω because it is ahead of the knife edge).  Drawn: G, the contact point P
    and a nose point 0.3 m ahead of G.
    """
    import sympy

    from cmbs.model.equations import from_sympy

    x, z, theta = sympy.symbols("x z theta")
    x_d, z_d, theta_d = sympy.symbols("x_d z_d theta_d")
    m, inertia_g, a, nose = (sympy.Float(value) for value in (mass, inertia, distance, 0.3))
    c, s = sympy.cos(theta), sympy.sin(theta)
    knife_edge = -s * (x_d + a * s * theta_d) + c * (z_d - a * c * theta_d)
    model = from_sympy(
        "chaplygin-sleigh", coordinates=[x, z, theta], velocities=[x_d, z_d, theta_d],
        mass_matrix=sympy.diag(m, m, inertia_g), forces=[0, 0, 0],
        velocity_constraints=[knife_edge], velocity_constraint_names=["knife-edge"],
        points={"G": (x, z), "P": (x - a * c, z - a * s), "nose": (x + nose * c, z + nose * s)},
        lines=[("P", "G"), ("G", "nose")], q0=[0.0, 0.0, 0.0],
        qd0=[speed, distance * angular_velocity, angular_velocity],
        description=f"Chaplygin sleigh: rigid body (m = {mass:g} kg, I_G = {inertia:g} kg m^2) on a horizontal "
                    f"plane, knife edge {distance:g} m behind the COM; nonholonomic, 3 DOF, 2 velocity DOF",
        source="S. A. Chaplygin 1911; A. M. Bloch, Nonholonomic Mechanics and Control (2003) §1.7 "
               "(m, I_G, a and the start chosen)")
    return model.replace(parameters={**model.parameters, "mass": mass, "inertia": inertia, "distance": distance,
                                     "speed": speed, "angular_velocity": angular_velocity})
