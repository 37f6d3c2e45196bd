"""Builders of the library mechanisms taken from Aghili (2005) and Quasem, Uhlar & Betsch (2009),
in natural coordinates.  Parameter values and their status (read from the source or chosen) are
given in each docstring; docs/models.md collects them."""

from __future__ import annotations

import math

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
    ``crank_speed`` rad/s (the benchmark state of shared/anchors: 45°, 2 rad/s), rod on the branch
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
