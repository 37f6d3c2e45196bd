"""Spatial mechanisms in natural coordinates (:mod:`cmbs.model.spatial`): the spherical pendulum,
the heavy symmetric top, the library's four-bar built in 3-D, and the IFToMM benchmarks Bricard's
mechanism (A04), the spatial slider-crank and the stiff flyball governor (A05).  Parameter values and their
status (from a source or chosen) are in each docstring; docs/models.md collects them."""

from __future__ import annotations

import math

import numpy as np

from cmbs.model.model import Model
from cmbs.model.spatial import SpatialModelBuilder


def spherical_pendulum(length: float = 1.0, mass: float = 1.0, polar_angle: float = 45.0,
                       azimuth_rate: float = 2.0, gravity: float = 9.81) -> Model:
    """A point mass on a massless rod from a fixed pivot (the spherical pendulum: Landau &
    Lifshitz, *Mechanics*, §14, problem 1): 2 DOF.

    Pivot O at the origin, gravity along -z; the mass starts ``polar_angle`` degrees from the
    downward vertical in the x-z plane, moving about the vertical at ``azimuth_rate`` rad/s.
    Length 1 m, mass 1 kg, 45°, 2 rad/s are chosen.  Its energy and angular momentum about the
    vertical are conserved; tests/test_spatial.py compares it with the solution in spherical
    coordinates."""
    theta = math.radians(polar_angle)
    builder = SpatialModelBuilder("spherical-pendulum", gravity=(0.0, 0.0, -gravity),
                                  description="point mass on a massless rod from a fixed pivot, 2 DOF",
                                  source="Landau & Lifshitz, Mechanics §14 problem 1 (values chosen)")
    builder.add_point("O", (0.0, 0.0, 0.0), fixed=True)
    builder.add_point("P", (length * math.sin(theta), 0.0, -length * math.cos(theta)), mass=mass)
    builder.add_rod("rod", "O", "P", mass=0.0)                  # massless
    model = builder.build()
    return model.replace(qd0=np.array([0.0, length * math.sin(theta) * azimuth_rate, 0.0]),
                         parameters={"length": length, "mass": mass, "polar_angle": polar_angle,
                                     "azimuth_rate": azimuth_rate, "gravity": gravity})


def heavy_top(tilt: float = 20.0, spin: float = 50.0, precession: float = 0.0, mass: float = 1.0,
              com_height: float = 0.1, transverse_inertia: float = 4e-3, axial_inertia: float = 6e-3,
              gravity: float = 9.81) -> Model:
    """The heavy symmetric top: a rigid body of revolution on a spherical joint at its fixed tip
    O (Goldstein, Poole & Safko, *Classical Mechanics*, 3rd ed., §5.7), 3 DOF.

    Body axes: unit vectors u, v and w (w the symmetry axis), tilted ``tilt`` degrees from the
    vertical about x; centre of mass at ``com_height`` along w; inertia about the centre of mass
    ``transverse_inertia`` about u and v, ``axial_inertia`` about w; a point ``tip`` on the axis
    at twice the centre of mass's height, drawn.  It starts spinning at ``spin`` rad/s about w and
    precessing at ``precession`` rad/s about the vertical.  Values chosen (1 kg, 0.1 m, 4e-3 and
    6e-3 kg m², 20°, 50 rad/s: a fast top that nutates slightly about a slow precession).  Energy
    and the angular momenta about the vertical and about w are conserved; tests/test_spatial.py
    compares the axis with the solution in Euler angles."""
    angle = math.radians(tilt)
    rotation = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(angle), -math.sin(angle)],
                         [0.0, math.sin(angle), math.cos(angle)]])
    u, v, w = rotation.T
    builder = SpatialModelBuilder("heavy-top", gravity=(0.0, 0.0, -gravity),
                                  description="heavy symmetric top on a fixed point, 3 DOF",
                                  source="Goldstein, Poole & Safko, Classical Mechanics §5.7 (values chosen)")
    builder.add_point("O", (0.0, 0.0, 0.0), fixed=True)
    builder.add_point("tip", 2.0 * com_height * w)
    for name, direction in (("u", u), ("v", v), ("w", w)):
        builder.add_vector(name, direction)
    builder.add_body("top", origin="O", basis=["u", "v", "w"], mass=mass, com=com_height * w,
                     inertia=rotation @ np.diag([transverse_inertia, transverse_inertia, axial_inertia]) @ rotation.T,
                     points=["tip"])
    model = builder.build()
    omega = precession * np.array([0.0, 0.0, 1.0]) + spin * w
    velocity = {"tip": np.cross(omega, 2.0 * com_height * w), "u": np.cross(omega, u), "v": np.cross(omega, v),
                "w": np.cross(omega, w)}
    qd0 = [velocity[name.split(".")[0]]["xyz".index(name.split(".")[1])] for name in model.coordinate_names]
    return model.replace(qd0=np.array(qd0), parameters={
        "tilt": tilt, "spin": spin, "precession": precession, "mass": mass, "com_height": com_height,
        "transverse_inertia": transverse_inertia, "axial_inertia": axial_inertia, "gravity": gravity})


def four_bar_3d(gravity: float = 9.81) -> Model:
    """The library's four-bar (``four-bar``: the thesis linkage, 2, 10 and 6 m uniform bars of 1, 5
    and 3 kg between ground points A = (0, 0, 0) and B = (10, 0, 0)) built in space, undriven, in
    the plane y = 0 with gravity along -z: 1 DOF.

    The bars are rods (:meth:`~cmbs.model.spatial.SpatialModelBuilder.add_rod`) joined at P1 and
    P2; the crank and the rocker turn about the ground axis y, (P1 - A)·y = 0 and (P2 - B)·y = 0.
    Released at rest from the planar model's start (crank at -45°, assembled), it moves exactly
    as ``cmbs.load("four-bar").without_drivers()`` (tests/test_spatial.py)."""
    from cmbs.library import load_library_model

    planar = load_library_model("four-bar")
    start = dict(zip(planar.point_names, planar.point_positions(planar.q0)))
    builder = SpatialModelBuilder("four-bar-3d", gravity=(0.0, 0.0, -gravity),
                                  description="the thesis four-bar in space (plane y = 0), undriven, 1 DOF",
                                  source="O. Pätkau, UPC thesis §3.2.1 (the library four-bar, built in 3-D)")
    for name in ("A", "B", "P1", "P2"):
        x, z = start[name]
        builder.add_point(name, (x, 0.0, z), fixed=name in ("A", "B"))
    builder.add_vector("y", (0.0, 1.0, 0.0), fixed=True)
    for name, i, j, mass in (("crank", "A", "P1", 1.0), ("coupler", "P1", "P2", 5.0), ("rocker", "P2", "B", 3.0)):
        builder.add_rod(name, i, j, mass=mass)
    builder.add_dot("crank axis", ("P1", "A"), "y")
    builder.add_dot("rocker axis", ("P2", "B"), "y")
    return builder.build().replace(parameters={"gravity": gravity})


#: Bricard's mechanism (IFToMM A04): its six joint points (m) and the axis of the revolute joint at
#: each, in ground axes at the start; the ground link is P5-P0.
BRICARD_POINTS = ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, -1.0, 0.0), (1.0, -1.0, 1.0), (0.0, -1.0, 1.0),
                  (0.0, 0.0, 1.0))
BRICARD_AXES = ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0),
                (1.0, 0.0, 0.0))


def bricard(gravity: float = 9.81) -> Model:
    """Bricard's mechanism, IFToMM benchmark A04 (González, Dopico, Lugrís & Cuadrado, *Multibody
    Syst. Dyn.* 16:179-190, 2006): five rods of 1 m and 1 kg with a 0.1 m square section, joined
    end to end by revolute joints and closing on the ground through a sixth one; gravity along -y;
    10 s from rest.  Grübler counts 0 DOF, it has 1: the constraints are redundant.

    Geometry (as in Exudyn's ``TestModels/bricardMechanism.py``, which follows the benchmark):
    joint points P0 = (0, 0, 0), P1 = (1, 0, 0), P2 = (1, -1, 0), P3 = (1, -1, 1), P4 = (0, -1, 1),
    P5 = (0, 0, 1) (P0, P5 fixed), rod k from P_k to P_k+1, joint axes y, z, x, y, z, x at P0 to P5.
    Each rod is a body located by its first joint point, its second (point - first), and the unit
    vectors of the axes at its two ends; a joint is the shared point and axis.  Inertia of a
    uniform 1 x 0.1 x 0.1 m box about its centre: m/12 diag(2 r², L² + r², L² + r²) along, across,
    across.  24 coordinates (P1-P4 and the moving axes a1-a4), 24 rows of rank 23
    (a shared axis's unit length is one row).  The
    benchmark's reference quantities are the trajectory of P3 and the energy."""
    builder = SpatialModelBuilder("bricard", gravity=(0.0, -gravity, 0.0),
                                  description="Bricard's mechanism (IFToMM A04): five 1 m, 1 kg rods, six revolute "
                                              "joints, 1 DOF with redundant constraints",
                                  source="IFToMM benchmark A04 (González et al., Multibody Syst. Dyn. 16, 2006); "
                                         "geometry as Exudyn TestModels/bricardMechanism.py")
    for k, point in enumerate(BRICARD_POINTS):
        builder.add_point(f"P{k}", point, fixed=k in (0, 5))
    for k, axis in enumerate(BRICARD_AXES):
        builder.add_vector(f"a{k}", axis, fixed=k in (0, 5))
    length, side, mass = 1.0, 0.1, 1.0
    moments = mass / 12.0 * np.array([2.0 * side**2, length**2 + side**2, length**2 + side**2])
    for k in range(5):
        start, end = np.array(BRICARD_POINTS[k]), np.array(BRICARD_POINTS[k + 1])
        along = end - start
        across = np.array(BRICARD_AXES[k])
        frame = np.column_stack([along, across, np.cross(along, across)])
        builder.add_body(f"rod{k}", origin=f"P{k}", basis=[f"P{k + 1}", f"a{k}", f"a{k + 1}"], mass=mass,
                         com=0.5 * (start + end), inertia=frame @ np.diag(moments) @ frame.T)
    return builder.build().replace(parameters={"gravity": gravity})


def _with_velocities(model: Model, given: dict[str, float]) -> Model:
    """``model`` with the start velocities ``given`` ({coordinate: value}) held and the others
    consistent with them (:func:`cmbs.kinematics.velocities`)."""
    from cmbs.kinematics import velocities

    qd = np.zeros(model.n)
    for name, value in given.items():
        qd[model.coordinate_index(name)] = value
    return model.replace(qd0=velocities(model, model.q0, 0.0, qd=qd, fixed=tuple(given)))


def spatial_slider_crank(crank_rate: float = 6.0, gravity: float = 9.81) -> Model:
    """The spatial slider-crank of the IFToMM Library of Computational Benchmark Problems (from
    Haug, *Computer-Aided Kinematics and Dynamics of Mechanical Systems*, 1989, §12.2): a crank
    turning about the ground axis x at A = (0, 0.1, 0.12), a connecting rod from its end B by a
    spherical joint to a slider C on the ground x axis, joined to it by a universal joint; gravity
    along -z; 5 s, the crank starting at ``crank_rate`` rad/s (not driven).

    Crank AB: 0.08 m along z at the start, 0.12 kg, centre of mass at its middle, 1e-4 kg m²
    about x through it (a rod turning about x; the dot product (B - A)·x = 0 keeps it across the
    axis).  Rod BC: 0.3 m (C = (0.2, 0, 0)), 0.5 kg, centre of mass at its middle, inertia
    diag(4e-4, 4e-3, 4e-3) along and across it; a body located by B, C - B and two unit vectors
    e1, e2 across it, e1 = (0, 2, -1)/√5 across both the rod and x.  Slider: 2 kg at C, on the
    line through the origin along x (its position, the slide ``x_slider``).  Universal joint: the
    rod's e1 stays across the slider's axis x, e1·x = 0.  ``crank_angle``: the crank's angle
    about x from the ground's z axis.  These are the values of the library
    problem as its submitted solutions use them (its data: F. González's solution, the slider's x
    every 0.01 s; tests/test_spatial_library.py)."""
    A, B, C = np.array([0.0, 0.1, 0.12]), np.array([0.0, 0.1, 0.20]), np.array([0.2, 0.0, 0.0])
    along = (C - B) / np.linalg.norm(C - B)
    e1 = np.array([0.0, 2.0, -1.0]) / math.sqrt(5.0)
    e2 = np.cross(along, e1)
    builder = SpatialModelBuilder("spatial-slider-crank", gravity=(0.0, 0.0, -gravity),
                                  description="spatial slider-crank: revolute, spherical, universal and prismatic "
                                              "joints, 1 DOF",
                                  source="IFToMM Library of Computational Benchmark Problems, spatial rigid "
                                         "slider-crank (Haug 1989, §12.2)")
    builder.add_point("O", (0.0, 0.0, 0.0), fixed=True)
    builder.add_point("A", A, fixed=True)
    builder.add_vector("x", (1.0, 0.0, 0.0), fixed=True)
    builder.add_vector("z", (0.0, 0.0, 1.0), fixed=True)
    builder.add_point("B", B)
    builder.add_point("C", C, mass=2.0)
    builder.add_vector("e1", e1)
    builder.add_vector("e2", e2)
    builder.add_rod("crank", "A", "B", mass=0.12, com=0.5, inertia=1e-4)
    builder.add_dot("crank axis", ("B", "A"), "x", value=0.0)
    rod_frame = np.column_stack([along, e1, e2])
    builder.add_body("rod", origin="B", basis=["C", "e1", "e2"], mass=0.5, com=0.5 * (B + C),
                     inertia=rod_frame @ np.diag([4e-4, 4e-3, 4e-3]) @ rod_frame.T)
    builder.add_slider("x_slider", point="C", origin="O", axis="x")
    builder.add_dot("universal", "e1", "x", value=0.0)
    builder.add_angle("crank_angle", reference="z", vector=("B", "A"), axis="x")
    model = _with_velocities(builder.build(), {"B.x": 0.0, "B.y": -crank_rate * (B - A)[2], "B.z": 0.0})
    return model.replace(parameters={"crank_rate": crank_rate, "gravity": gravity})


def flyball_governor(stiffness: float = 8e5, damping: float = 4e4, spin: float = 2.0 * math.pi,
                     gravity: float = 9.81) -> Model:
    """The stiff flyball governor, IFToMM benchmark A05 (González, Dopico, Lugrís & Cuadrado,
    *Multibody Syst. Dyn.* 16:179-190, 2006; topology and values as in the MBSbenchmarksInOpenSim
    A05 model): a vertical shaft free to turn about the ground axis z at O; a slider on it by a
    prismatic joint at height ``s``; two rods hinged to the shaft's top at (±0.05, 0, 1) about the
    shaft's y axis, 30° below the horizontal, each with a 5 kg ball at its end; a spring-damper
    from each side of the slider, (±0.05, 0, s), to its rod's middle (K = 8e5 N/m, C = 4e4 N s/m,
    rest length 0.5 m: unloaded at the start).  Gravity along -z; everything starts turning at
    ``spin`` = 2π rad/s about z (not driven); 10 s; the reference quantity is s(t).

    Density 3000 kg/m³: shaft and rods 1 × 0.01 × 0.01 m bars (0.3 kg; inertia about the centre
    of mass 0.3 (1 + 0.01²)/12 across, 0.3 · 2e-4/12 along), the slider a 0.1 m cube (3 kg,
    0.005 kg m²).  Natural coordinates: the shaft is a body on O with the fixed z and its unit
    vectors u, v; the slider shares z, u, v with it (prismatic) and its centre S slides along z
    (the slide ``s``); each rod is a body on its hinge point with its ball, the shared axis v and
    a unit vector across it."""
    bar_across = 0.3 * (1.0 + 0.01**2) / 12.0
    bar_along = 0.3 * 2.0 * 0.01**2 / 12.0
    angle = math.radians(30.0)
    builder = SpatialModelBuilder("flyball-governor", gravity=(0.0, 0.0, -gravity),
                                  description="IFToMM A05 stiff flyball governor: shaft, slider, two rods with balls, "
                                              "two stiff spring-dampers, 4 DOF",
                                  source="IFToMM benchmark A05 (González et al., Multibody Syst. Dyn. 16, 2006); "
                                         "topology as MBSbenchmarksInOpenSim A05")
    builder.add_point("O", (0.0, 0.0, 0.0), fixed=True)
    builder.add_vector("z", (0.0, 0.0, 1.0), fixed=True)
    builder.add_vector("u", (1.0, 0.0, 0.0))
    builder.add_vector("v", (0.0, 1.0, 0.0))
    builder.add_point("top", (0.0, 0.0, 1.0))
    builder.add_point("S", (0.0, 0.0, 0.5))
    rods = []
    for side, sign in (("right", 1.0), ("left", -1.0)):
        hinge = np.array([0.05 * sign, 0.0, 1.0])
        along = np.array([sign * math.cos(angle), 0.0, -math.sin(angle)])
        builder.add_point(f"hinge_{side}", hinge)
        builder.add_point(f"ball_{side}", hinge + along, mass=5.0)
        builder.add_point(f"middle_{side}", hinge + 0.5 * along)
        builder.add_point(f"seat_{side}", (0.05 * sign, 0.0, 0.5))
        builder.add_vector(f"n_{side}", np.cross(along, (0.0, 1.0, 0.0)))
        rods.append((side, hinge, along))
    builder.add_body("shaft", origin="O", basis=["z", "u", "v"], mass=0.3, com=(0.0, 0.0, 0.5),
                     inertia=np.diag([bar_across, bar_across, bar_along]), points=["top", "hinge_right", "hinge_left"])
    builder.add_body("slider", origin="S", basis=["z", "u", "v"], mass=3.0, com=(0.0, 0.0, 0.5),
                     inertia=np.diag([0.005, 0.005, 0.005]), points=["seat_right", "seat_left"])
    builder.add_slider("s", point="S", origin="O", axis="z")
    for side, hinge, along in rods:
        across = np.cross(along, (0.0, 1.0, 0.0))
        frame = np.column_stack([along, (0.0, 1.0, 0.0), across])
        builder.add_body(f"rod_{side}", origin=f"hinge_{side}", basis=[f"ball_{side}", "v", f"n_{side}"], mass=0.3,
                         com=hinge + 0.5 * along, inertia=frame @ np.diag([bar_along, bar_across, bar_across]) @ frame.T,
                         points=[f"middle_{side}"])
        builder.add_spring(f"spring_{side}", f"seat_{side}", f"middle_{side}", stiffness=stiffness, damping=damping,
                           rest_length=0.5)
    model = builder.build()
    omega = np.array([0.0, 0.0, spin])
    given = {}
    for k, name in enumerate(model.coordinate_names):
        element, _, axis = name.partition(".")
        if axis:
            value = model.q0[k - "xyz".index(axis):][:3]
            given[name] = float(np.cross(omega, value)["xyz".index(axis)])
    return model.replace(qd0=_with_velocities(model, given).qd0,
                         parameters={"stiffness": stiffness, "damping": damping, "spin": spin, "gravity": gravity})
