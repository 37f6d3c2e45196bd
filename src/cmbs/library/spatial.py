"""Spatial mechanisms in natural coordinates (:mod:`cmbs.model.spatial`): the spherical pendulum,
the heavy symmetric top and the library's four-bar built in 3-D.  Parameter values and their
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
    across.  24 coordinates (P1-P4 and the moving axes a1-a4), 28 rows of rank 23.  The
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
