"""Loop closures of spatial joint-coordinate trees (robots): the closure rows' Jacobian and γ
against central finite differences, Bricard's mechanism (IFToMM A04; its robot file is
docs/robots.md's example) and a four-bar in joint coordinates against the natural-coordinate
models, robot files (TOML naming a URDF and its closures) and their errors, inverse dynamics of a
driven UR5 against Pinocchio's RNEA.

The closed trees run in the Python loop (compiled=False), which evaluates the same compiled robot
kernel and calls the same compiled solves: the compiled loops' handling of robot models is tested
in tests/test_robot.py and tests/test_robot_dynamics.py, and a compiled loop per formulation for
this model kind would cost the suite minutes of compilation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import cmbs
from cmbs.library.spatial import BRICARD_AXES, BRICARD_POINTS
from cmbs.model.robot import Inertial, JointDriver, TreeJoint, TreeLink, build_robot, frame_placement
from cmbs.model.robot_closures import Closure, rpy_rotation
from test_robot import ROBOTS, URDFS, needs_pinocchio, pinocchio

DOCS = Path(__file__).resolve().parents[1] / "docs" / "robots.md"
#: Bricard's robot file: docs/robots.md's first TOML example (so the documented example loads)
BRICARD_TOML = DOCS.read_text().split("```toml\n")[1].split("```")[0]


def _vector(values) -> str:
    return " ".join(f"{float(v):.17g}" for v in values)


def bricard_urdf() -> str:
    """Bricard's mechanism as a URDF tree: rods 0-4 (1 m, 1 kg, 0.1 m square section) from
    P_k to P_k+1, joint k at P_k about BRICARD_AXES[k]; every link frame is at its joint point
    with the world's axes at q = 0 (the start of ``cmbs.load("bricard")``); inertia of the box
    about its centre m/12 diag(2 r², L² + r², L² + r²) along the rod, across it (the axis at its
    start) and their cross product (as :func:`cmbs.library.spatial.bricard`)."""
    length, side, mass = 1.0, 0.1, 1.0
    moments = mass / 12.0 * np.array([2.0 * side**2, length**2 + side**2, length**2 + side**2])
    parts = ['<?xml version="1.0"?>', '<robot name="bricard">', '  <link name="ground"/>']
    for k in range(5):
        start, end = np.array(BRICARD_POINTS[k]), np.array(BRICARD_POINTS[k + 1])
        along, across = end - start, np.array(BRICARD_AXES[k])
        frame = np.column_stack([along, across, np.cross(along, across)])
        I = frame @ np.diag(moments) @ frame.T
        parent, previous = ("ground", np.zeros(3)) if k == 0 else (f"rod{k - 1}", np.array(BRICARD_POINTS[k - 1]))
        parts += [f'  <link name="rod{k}"><inertial><origin xyz="{_vector(0.5 * along)}"/><mass value="{mass}"/>',
                  f'    <inertia ixx="{I[0, 0]:.17g}" ixy="{I[0, 1]:.17g}" ixz="{I[0, 2]:.17g}" '
                  f'iyy="{I[1, 1]:.17g}" iyz="{I[1, 2]:.17g}" izz="{I[2, 2]:.17g}"/></inertial></link>',
                  f'  <joint name="J{k}" type="continuous"><parent link="{parent}"/><child link="rod{k}"/>',
                  f'    <origin xyz="{_vector(start - previous)}"/><axis xyz="{_vector(across)}"/></joint>']
    parts.append("</robot>")
    return "\n".join(parts) + "\n"


def write_bricard(folder: Path) -> Path:
    """bricard.urdf and its robot file bricard.toml in ``folder``; the robot file's path."""
    (folder / "bricard.urdf").write_text(bricard_urdf())
    path = folder / "bricard.toml"
    path.write_text(BRICARD_TOML)
    return path


# ------------------------------------------------------------------ the rows against finite differences
def _placement(xyz, rpy=(0.0, 0.0, 0.0)) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3] = rpy_rotation(rpy)
    matrix[:3, 3] = xyz
    return matrix


def _made_up_tree(closures, drivers=()):
    """Two branches from the ground (revolute and prismatic joints about oblique axes, turned joint
    frames, a fixed joint between movable ones, turned inertial frames) closed by ``closures`` and
    driven by ``drivers``."""
    def inertial(mass):
        return Inertial(mass, _placement((0.1, 0.05, -0.02), (0.3, 0.1, 0.2)), np.diag([0.02, 0.03, 0.04]))

    links = [TreeLink("base")] + [TreeLink(f"l{i}", inertial(1.0 + i)) for i in range(5)] + [TreeLink("tip")]
    joints = [TreeJoint("j0", "revolute", "base", "l0", _placement((0, 0, 0.2), (0.1, 0.2, 0.3)), (0.3, 0.5, 1.0)),
              TreeJoint("j1", "prismatic", "l0", "l1", _placement((0.3, 0, 0.1), (0.2, -0.1, 0.4)), (1.0, 0.2, -0.3)),
              TreeJoint("j2", "revolute", "l1", "l2", _placement((0.2, 0.1, 0), (0, 0.5, 0)), (0, 1, 0)),
              TreeJoint("j3", "revolute", "base", "l3", _placement((0.5, 0.2, 0), (0.3, 0, 0)), (1, 0, 0.2)),
              TreeJoint("tip", "fixed", "l3", "tip", _placement((0.1, 0.2, 0.3), (0.4, 0.5, 0.6))),
              TreeJoint("j4", "revolute", "tip", "l4", _placement((0.2, 0, 0.1)), (0, 0.3, 1))]
    return build_robot("made-up", links, joints, closures=closures, drivers=drivers, gravity=(0.3, -0.5, -9.81))


CLOSURES = {
    "point": Closure("c", "point", "l2", "l4", (0.1, 0.2, 0.3), (0.3, -0.1, 0.2)),
    "point-ground": Closure("c", "point", "tip", "ground", (0.1, 0.2, 0.3), (0.4, 0.2, 0.1)),
    "axis": Closure("c", "axis", "l2", "tip", axis_a=(0.2, 0.3, 1.0), axis_b=(1.0, -0.4, 0.1)),
    "revolute-ground": Closure("c", "revolute", "ground", "l1", (0.4, 0.2, 0.1), (0.1, 0, 0), axis_a=(0.5, 0.5, 0.1),
                               axis_b=(0, 1, 0)),
    "weld": Closure("c", "weld", "l4", "l0", (0.2, 0.1, 0), (0, 0.3, 0.1), rpy_a=(0.1, 0.2, 0.3),
                    rpy_b=(0.5, -0.2, 0.1)),
    "line": Closure("c", "line", "l2", "tip", (0.1, 0.2, 0.3), (0.3, -0.1, 0.2), axis_b=(0.2, 1.0, -0.3)),
    "line-ground": Closure("c", "line", "ground", "l4", (0.1, 0.2, 0.3), (0.3, -0.1, 0.2), axis_b=(0.2, 1.0, -0.3)),
    "prismatic": Closure("c", "prismatic", "l2", "tip", (0.1, 0.2, 0.3), (0.3, -0.1, 0.2), axis_b=(0.2, 1.0, -0.3),
                         rpy_a=(0.1, 0.2, 0.3), rpy_b=(0.5, -0.2, 0.1)),
}


@pytest.mark.parametrize("kind", CLOSURES)
def test_closure_rows_against_finite_differences(kind):
    """A = ∂Φ/∂q and γ = -(∂(A q̇)/∂q) q̇ against central differences (step 1e-6) of Φ and of
    A q̇ at 10 random states, Φ_t = 0; Φ itself is the points' and frames' geometry."""
    model = _made_up_tree([CLOSURES[kind]])
    rng = np.random.default_rng(7)
    step, worst_A, worst_gamma = 1e-6, 0.0, 0.0
    for _ in range(10):
        q, qd = rng.uniform(-1.5, 1.5, model.n), rng.uniform(-2.0, 2.0, model.n)
        columns = np.eye(model.n) * step
        A_fd = np.column_stack([(model.constraints(q + e) - model.constraints(q - e)) / (2 * step) for e in columns])
        Aqd_fd = np.column_stack([(model.jacobian(q + e) @ qd - model.jacobian(q - e) @ qd) / (2 * step)
                                  for e in columns])
        worst_A = max(worst_A, np.abs(model.jacobian(q) - A_fd).max())
        worst_gamma = max(worst_gamma, np.abs(model.gamma(q, qd) + Aqd_fd @ qd).max())
        assert np.all(model.constraints_t(q) == 0.0)
    assert worst_A < 1e-8 and worst_gamma < 1e-7, (worst_A, worst_gamma)     # measured 2.6e-10, 1.3e-9


def test_line_rows_are_the_point_across_the_line():
    """Φ of a line closure is p_a - p_b across the line: its two rows are the components of p_a -
    p_b along an orthonormal pair perpendicular to the line's direction in link b's frame, so
    their squares sum to the squared distance of p_a from the line."""
    model = _made_up_tree([CLOSURES["line"]])
    q = np.array([0.3, -0.2, 0.5, 0.7, -0.4])
    (Ra, oa), (Rb, ob) = frame_placement(model, q, "l2"), frame_placement(model, q, "tip")
    d = (oa + Ra @ [0.1, 0.2, 0.3]) - (ob + Rb @ [0.3, -0.1, 0.2])
    u = Rb @ np.array([0.2, 1.0, -0.3]) / np.linalg.norm([0.2, 1.0, -0.3])
    phi = model.constraints(q)
    assert phi.shape == (2,) and model.constraint_names == ("c.line1", "c.line2")
    np.testing.assert_allclose(phi @ phi, d @ d - (d @ u) ** 2, rtol=1e-14)


def test_prismatic_rows_are_the_line_and_the_frames_alignment():
    """Φ of a prismatic closure: the two rows of the line closure (p_a across link b's line) and
    the three of the weld's alignment of the frames F_a = R_a Rot(rpy_a), F_b = R_b Rot(rpy_b):
    y_a·z_b, z_a·x_b, x_a·y_b, from the links' placements."""
    closure = CLOSURES["prismatic"]
    model = _made_up_tree([closure])
    q = np.array([0.3, -0.2, 0.5, 0.7, -0.4])
    (Ra, oa), (Rb, ob) = frame_placement(model, q, "l2"), frame_placement(model, q, "tip")
    Fa, Fb = Ra @ rpy_rotation(closure.rpy_a), Rb @ rpy_rotation(closure.rpy_b)
    phi = model.constraints(q)
    assert model.constraint_names == ("c.line1", "c.line2", "c.rx", "c.ry", "c.rz")
    np.testing.assert_allclose(phi[2:], [Fa[:, 1] @ Fb[:, 2], Fa[:, 2] @ Fb[:, 0], Fa[:, 0] @ Fb[:, 1]], atol=1e-15)
    line = _made_up_tree([CLOSURES["line"]])
    np.testing.assert_allclose(phi[:2], line.constraints(q), atol=1e-15)


SLIDER_CRANK = {"r": 0.08, "l": 0.3}


def _slider_crank_file(folder: Path) -> Path:
    """A planar slider-crank in the plane x-z as a robot: crank (r) from the ground, rod (l),
    slider block, revolute joints about y, the block closed to the ground by a prismatic closure
    along x (the block's frame kept aligned with the world's)."""
    r, l = SLIDER_CRANK["r"], SLIDER_CRANK["l"]

    def link(name, mass, com, inertia):
        return (f'<link name="{name}"><inertial><origin xyz="{com} 0 0"/><mass value="{mass}"/>'
                f'<inertia ixx="{inertia}" ixy="0" ixz="0" iyy="{inertia}" iyz="0" izz="{inertia}"/></inertial></link>')

    def joint(name, parent, child, x):
        return (f'<joint name="{name}" type="continuous"><parent link="{parent}"/><child link="{child}"/>'
                f'<origin xyz="{x} 0 0"/><axis xyz="0 1 0"/></joint>')

    (folder / "slider-crank.urdf").write_text(
        '<robot name="slider-crank"><link name="base"/>' + link("crank", 0.12, r / 2, 1e-4)
        + link("rod", 0.5, l / 2, 4e-3) + link("block", 2.0, 0.0, 2e-3) + joint("crank_joint", "base", "crank", 0.0)
        + joint("rod_joint", "crank", "rod", r) + joint("block_joint", "rod", "block", l) + "</robot>")
    path = folder / "slider-crank.toml"
    path.write_text('[model]\nurdf = "slider-crank.urdf"\n\n[closures.slide]\nkind = "prismatic"\nlink_a = "block"\n'
                    'link_b = "ground"\naxis_b = [1.0, 0.0, 0.0]\n\n[initial_positions]\ncrank_joint = 0.7\n'
                    'rod_joint = -0.9\nblock_joint = 0.2\n\n[initial_velocities]\ncrank_joint = 6.0\n')
    return path


def test_slider_crank_closed_by_a_prismatic_closure_follows_the_closed_form(tmp_path):
    """The slider-crank whose block slides on the ground's x axis (a prismatic closure: 5 rows of
    rank 2 in the plane, the out-of-plane rows redundant; DOF 1) swings under gravity from the
    crank at 6 rad/s: over 1 s (projection, DOP853 at rtol 1e-11) the block stays on the axis,
    unturned, at x = r cos θ + √(l² - r² sin² θ) for the crank angle θ (a turn about y carries x
    towards -z) to 1e-9 m, and T + V holds to 1e-8 J."""
    model = cmbs.load(_slider_crank_file(tmp_path))
    report = cmbs.constraint_report(model, model.q0)
    assert (model.n, model.m, report.rank, report.dof, len(report.redundant)) == (3, 5, 2, 1, 3)
    run = cmbs.simulate(model, t_end=1.0, dt=0.02, formulation="projection", integrator="dop853", rtol=1e-11,
                        atol=1e-12, compiled=False)
    assert run.info["status"] == "success"
    r, l = SLIDER_CRANK["r"], SLIDER_CRANK["l"]
    theta = run.q[:, model.coordinate_index("crank_joint")]
    for q, angle in zip(run.q, theta):
        rotation, origin = frame_placement(model, q, "block")
        np.testing.assert_allclose(origin, [r * np.cos(angle) + np.sqrt(l**2 - (r * np.sin(angle)) ** 2), 0.0, 0.0],
                                   atol=1e-9)
        np.testing.assert_allclose(rotation, np.eye(3), atol=1e-9)
    assert np.ptp(theta) > 3.0
    energy = model.energy_history(run.q, run.qd)
    assert np.abs(energy - energy[0]).max() < 1e-8


def test_point_rows_are_the_frames_points():
    """Φ of a point closure is p_a - p_b with the points placed by frame_placement (link frames)."""
    model = _made_up_tree([CLOSURES["point"]])
    q = np.array([0.3, -0.2, 0.5, 0.7, -0.4])
    (Ra, oa), (Rb, ob) = frame_placement(model, q, "l2"), frame_placement(model, q, "l4")
    expected = (oa + Ra @ [0.1, 0.2, 0.3]) - (ob + Rb @ [0.3, -0.1, 0.2])
    np.testing.assert_allclose(model.constraints(q), expected, atol=1e-15)



@pytest.mark.parametrize("kind, dof", [("point", 2), ("axis", 3)])
def test_closed_made_up_tree_keeps_its_energy(kind, dof):
    """The made-up tree closed by a point coincidence between its branches, or by an axis
    alignment, assembled from q = 0.2 and released at rest: 1 s with the projection formulation
    and DOP853 (rtol 1e-11) keeps T + V to 1e-8 J (measured 4e-11 and 1e-10) and Φ to 1e-10,
    while the joints swing by radians."""
    model = _made_up_tree([CLOSURES[kind]])
    model = model.replace(q0=cmbs.assemble(model, np.full(model.n, 0.2)))
    assert cmbs.constraint_report(model, model.q0).dof == dof
    run = cmbs.simulate(model, t_end=1.0, dt=0.05, formulation="projection", integrator="dop853", rtol=1e-11,
                        atol=1e-12, compiled=False)
    assert run.info["status"] == "success"
    energy = model.energy_history(run.q, run.qd)
    assert np.abs(energy - energy[0]).max() < 1e-8
    assert np.abs([model.constraints(q) for q in run.q]).max() < 1e-10
    assert np.ptp(run.q, axis=0).max() > 1.0

# ------------------------------------------------------------------ Bricard's mechanism
@pytest.fixture(scope="module")
def bricard(tmp_path_factory):
    return cmbs.load(write_bricard(tmp_path_factory.mktemp("bricard")))


def test_bricard_has_one_degree_of_freedom_and_one_redundant_row(bricard):
    """Five joint angles, five closure rows of rank 4: DOF 1 and one redundant row named, as the
    natural-coordinate Bricard (24 coordinates, 24 rows of rank 23); the start closes (Φ = 0)."""
    report = cmbs.constraint_report(bricard, bricard.q0)
    natural = cmbs.constraint_report(cmbs.load("bricard"), cmbs.load("bricard").q0)
    assert (bricard.n, bricard.m, report.rank, report.dof) == (5, 5, 4, 1)
    assert report.dof == natural.dof and len(report.redundant) == len(natural.redundant) == 1
    assert report.redundant[0] in bricard.constraint_names
    np.testing.assert_allclose(bricard.constraints(bricard.q0), 0.0, atol=1e-15)


def test_bricard_moves_as_the_natural_coordinate_model(bricard):
    """Released at rest, 2 s with the projection formulation and DOP853 (rtol 1e-11): point P3
    (rod 3's frame origin) follows the natural-coordinate model's P3 to 1e-8 m, and T + V is
    kept to 1e-8 J."""
    natural = cmbs.load("bricard")
    options = dict(t_end=2.0, dt=0.05, formulation="projection", integrator="dop853", rtol=1e-11, atol=1e-12)
    run, reference = cmbs.simulate(bricard, compiled=False, **options), cmbs.simulate(natural, **options)
    assert run.info["status"] == reference.info["status"] == "success"
    P3 = np.array([frame_placement(bricard, q, "rod3")[1] for q in run.q])
    P3_natural = reference.q[:, [natural.coordinate_index(f"P3.{c}") for c in "xyz"]]
    assert np.abs(P3 - P3_natural).max() < 1e-8                     # measured 2.0e-10
    assert np.ptp(P3_natural[:, 1]) > 0.5                             # it falls and swings
    energy = bricard.energy_history(run.q, run.qd)
    assert np.abs(energy - energy[0]).max() < 1e-8                   # measured 3.4e-11
    np.testing.assert_allclose([bricard.constraints(q) for q in run.q], 0.0, atol=1e-9)


# ------------------------------------------------------------------ a four-bar in joint coordinates
def four_bar_urdf() -> tuple[str, dict[str, np.ndarray]]:
    """The library four-bar (crank A-P1 1 kg, coupler P1-P2 5 kg, rocker B-P2 3 kg, uniform
    bars) as a URDF tree in the plane y = 0 at ``four-bar-3d``'s start, joints about y: the crank
    and the coupler from A, the rocker from B (the coupler-rocker joint is the closure); link
    frames at their joints with the world's axes at q = 0.  Its start points by name."""
    natural = cmbs.load("four-bar-3d")
    start = {name: natural.point_positions(natural.q0)[natural.point_names.index(name)] for name in
             ("A", "B", "P1", "P2")}
    parts = ['<?xml version="1.0"?>', '<robot name="four-bar">', '  <link name="ground"/>']
    for link, parent, origin, i, j, mass in (("crank", "ground", start["A"], "A", "P1", 1.0),
                                             ("coupler", "crank", start["P1"] - start["A"], "P1", "P2", 5.0),
                                             ("rocker", "ground", start["B"], "B", "P2", 3.0)):
        along = start[j] - start[i]
        length = np.linalg.norm(along)
        I = mass * length**2 / 12.0 * (np.eye(3) - np.outer(along, along) / length**2)
        parts += [f'  <link name="{link}"><inertial><origin xyz="{_vector(0.5 * along)}"/><mass value="{mass}"/>',
                  f'    <inertia ixx="{I[0, 0]:.17g}" ixy="{I[0, 1]:.17g}" ixz="{I[0, 2]:.17g}" '
                  f'iyy="{I[1, 1]:.17g}" iyz="{I[1, 2]:.17g}" izz="{I[2, 2]:.17g}"/></inertial></link>',
                  f'  <joint name="{link}-joint" type="continuous"><parent link="{parent}"/><child link="{link}"/>',
                  f'    <origin xyz="{_vector(origin)}"/><axis xyz="0 1 0"/></joint>']
    parts.append("</robot>")
    return "\n".join(parts) + "\n", start


def write_four_bar(folder: Path, kind: str) -> tuple[Path, dict[str, np.ndarray]]:
    """:func:`four_bar_urdf` and its robot file in ``folder``, closed at P2 between the coupler's
    end and the rocker's by a closure of ``kind`` (``revolute``: about y; ``line``: P2 on the
    rocker's line along y); the robot file's path and the start points."""
    text, start = four_bar_urdf()
    (folder / "four-bar.urdf").write_text(text)
    axes = ('axis_a = [0.0, 1.0, 0.0]\n' if kind == "revolute" else "") + 'axis_b = [0.0, 1.0, 0.0]\n'
    path = folder / "four-bar.toml"
    path.write_text(f"""\
[model]
urdf = "four-bar.urdf"

[closures.P2]
kind = "{kind}"
link_a = "coupler"
point_a = [{', '.join(map(repr, (start['P2'] - start['P1']).tolist()))}]
link_b = "rocker"
point_b = [{', '.join(map(repr, (start['P2'] - start['B']).tolist()))}]
""" + axes)
    return path, start


@pytest.mark.parametrize("formulation", ["projection", "udwadia-kalaba"])
def test_four_bar_in_joint_coordinates_moves_as_four_bar_3d(tmp_path, formulation):
    """Three joint angles closed by a revolute joint between the coupler's end and the rocker's
    (5 rows of rank 2: the out-of-plane rows are identically zero) move as the natural-coordinate
    ``four-bar-3d`` from rest: P1 and P2 to 1e-8 m over 2 s (DOP853, rtol 1e-11)."""
    path, start = write_four_bar(tmp_path, "revolute")
    model, natural = cmbs.load(path), cmbs.load("four-bar-3d")
    report = cmbs.constraint_report(model, model.q0)
    assert (model.n, model.m, report.rank, report.dof) == (3, 5, 2, 1)
    options = dict(t_end=2.0, dt=0.05, integrator="dop853", rtol=1e-11, atol=1e-12)
    run = cmbs.simulate(model, formulation=formulation, compiled=False, **options)
    reference = cmbs.simulate(natural, formulation="lagrange", **options)
    assert run.info["status"] == reference.info["status"] == "success"
    for point, link, local in (("P1", "coupler", np.zeros(3)), ("P2", "rocker", start["P2"] - start["B"])):
        placed = np.array([frame_placement(model, q, link)[0] @ local + frame_placement(model, q, link)[1]
                           for q in run.q])
        expected = reference.q[:, [natural.coordinate_index(f"{point}.{c}") for c in "xyz"]]
        assert np.abs(placed - expected).max() < 1e-8, point            # measured 2.3e-11
    assert np.ptp(reference.q[:, natural.coordinate_index("P1.x")]) > 0.5


# ------------------------------------------------------------------ robot files: assembly and errors
def test_assembly_closes_the_loop_from_a_start_guess(tmp_path):
    """``[initial_positions]`` is the guess: loading assembles from it (Φ(q0) = 0 to 1e-12) to
    another configuration of Bricard's one-parameter set than the start (q = 0)."""
    path = write_bricard(tmp_path)
    path.write_text(BRICARD_TOML + "\n[initial_positions]\nJ0 = 0.3\nJ1 = -0.1\n")
    model = cmbs.load(path)
    assert np.abs(model.constraints(model.q0)).max() < 1e-12
    assert 0.05 < np.abs(model.q0).max() < 1.0


def _bad(tmp_path, replace: tuple[str, str] = ("", ""), extra: str = "") -> str:
    path = write_bricard(tmp_path)
    text = BRICARD_TOML.replace(*replace) if replace[0] else BRICARD_TOML
    path.write_text(text + extra)
    with pytest.raises(cmbs.ModelError) as error:
        cmbs.load(path)
    message = str(error.value)
    assert "\n" not in message and message.startswith(str(path))
    return message


@pytest.mark.parametrize("replace, extra, expected", [
    (('link_a = "rod4"', 'link_a = "rod9"'), "",
     "closures.J5: link_a: unknown link 'rod9'"),
    (('link_b = "ground"', 'link_b = "grund"'), "",
     "closures.J5: link_b: unknown link 'grund' (did you mean 'ground'?)"),
    (('point_a = [0.0, 1.0, 0.0]', 'point_a = [0.0, 1.0]'), "",
     "closures.J5: point_a must be a list of 3 finite numbers, got [0.0, 1.0]"),
    (('axis_b = [1.0, 0.0, 0.0]', 'axis_b = [0.0, 0.0, 0.0]'), "",
     "closures.J5: axis_b must be nonzero, got (0.0, 0.0, 0.0)"),
    (('kind = "revolute"', 'kind = "hinge"'), "",
     "closures.J5: kind: unknown kind 'hinge'"),
    (('axis_b = [1.0, 0.0, 0.0]\n', ''), "",
     "closures.J5: axis_b is required by kind 'revolute'"),
    (('kind = "revolute"', 'kind = "line"'), "",
     "closures.J5: axis_a is not used by kind 'line'"),
    (('point_b =', 'pont_b ='), "",
     "closures.J5: unknown key(s) 'pont_b' (did you mean 'point_b'?)"),
    (('urdf = "bricard.urdf"', 'urdf = "bricard2.urdf"'), "",
     "model: urdf: no such file"),
    (("", ""), '\n[drivers.d]\ncoordinate = "J9"\nexpression = "t"\n',
     "drivers.d: unknown joint 'J9'"),
    (("", ""), '\n[initial_positions]\nJ7 = 0.1\n',
     "initial_positions.J7: unknown joint 'J7'"),
    (("", ""), '\n[links]\n', "unknown section(s) 'links' for a robot file"),
    (('point_b = [0.0, 0.0, 1.0]', 'point_b = [0.0, 0.0, 6.0]'), "",
     "closures.J5: cannot be assembled"),
])
def test_robot_file_mistakes_are_one_line_errors_naming_the_entry(tmp_path, replace, extra, expected):
    assert expected in _bad(tmp_path, replace, extra)


# ------------------------------------------------------------------ inverse dynamics of a driven robot
UR5_JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
              "wrist_3_joint")
#: q_i(t) = a_i + b_i sin(w_i t)
UR5_MOTION = (np.array([0.1, -0.8, 1.2, -0.5, 0.7, 0.2]), np.array([0.5, 0.3, -0.4, 0.6, -0.2, 0.9]),
              np.array([1.0, 1.5, 2.0, 2.5, 3.0, 3.5]))


def _ur5_file(folder: Path) -> Path:
    """A robot file driving every joint of example-robot-data's UR5 by UR5_MOTION."""
    a, b, w = UR5_MOTION
    path = folder / "ur5-driven.toml"
    path.write_text(f'[model]\nurdf = "{ROBOTS / URDFS["ur5"]}"\n' + "".join(
        f'\n[drivers.{name}]\ncoordinate = "{name}"\nexpression = "{a[i]} + {b[i]} * sin({w[i]} * t)"\n'
        for i, name in enumerate(UR5_JOINTS)))
    return path


def _rnea_along_ur5_motion(times: np.ndarray) -> np.ndarray:
    """Pinocchio's τ = rnea(q, q̇, q̈) along UR5_MOTION (derivatives by hand)."""
    a, b, w = UR5_MOTION
    model = pinocchio.buildModelFromUrdf(str(ROBOTS / URDFS["ur5"]))
    data = model.createData()
    return np.array([pinocchio.rnea(model, data, a + b * np.sin(w * t), b * w * np.cos(w * t),
                                    -b * w * w * np.sin(w * t)) for t in times])


@needs_pinocchio
@pytest.mark.parametrize("method", ["lagrange", "matrix-r"])
def test_inverse_dynamics_of_a_driven_ur5_is_pinocchios_rnea(tmp_path, method):
    """Every joint driven by a function of time: the driver forces (-λ, or Rᵀ(M q̈ - Q)) are the
    joint torques of Pinocchio's RNEA along the motion, to 1e-9 relative (measured 1.2e-15)."""
    model = cmbs.load(_ur5_file(tmp_path))
    times = np.linspace(0.0, 2.0, 21)
    result = cmbs.inverse_dynamics(model, times, method=method)
    assert result.driven_coordinates == UR5_JOINTS
    expected = _rnea_along_ur5_motion(times)
    assert np.abs(result.forces - expected).max() < 1e-9 * np.abs(expected).max()


@needs_pinocchio
def test_cmbs_inverse_command_on_a_driven_ur5(tmp_path, capsys):
    """``cmbs inverse FILE --out x.npz`` writes the same torques."""
    from cmbs.cli import main

    out = tmp_path / "torques.npz"
    assert main(["inverse", str(_ur5_file(tmp_path)), "--t-end", "1", "--dt", "0.25", "--out", str(out)]) == 0
    assert "force on shoulder_lift_joint" in capsys.readouterr().out
    with np.load(out) as saved:
        expected = _rnea_along_ur5_motion(saved["t"])
        assert np.abs(saved["driver_forces"] - expected).max() < 1e-9 * np.abs(expected).max()


def test_a_python_function_driver_gives_the_expressions_rows():
    """A driver given as a Python callable (evaluated before the kernel call; the model then has
    no compiled kernel) writes the same Φ, Φ_t and γ as the same function as an expression."""
    def driven(function):
        return build_robot("driven", [TreeLink("base"), TreeLink("arm", Inertial(1.0, np.eye(4), np.eye(3)))],
                           [TreeJoint("hinge", "revolute", "base", "arm", np.eye(4), (0.0, 0.0, 1.0))],
                           drivers=[JointDriver("turn", "hinge", function)])

    expression = driven("0.5 * sin(2 * t)")
    python = driven(cmbs.PythonFunction(lambda t: 0.5 * np.sin(2 * t), first=lambda t: np.cos(2 * t),
                                        second=lambda t: -2.0 * np.sin(2 * t)))
    assert python.equations.compiled_kernel() is None and expression.equations.compiled_kernel() is not None
    q, qd = np.array([0.3]), np.array([0.2])
    for model in (expression, python):
        terms = model.evaluate(q, qd, 0.7)
        np.testing.assert_allclose([terms.phi[0], terms.phi_t[0], terms.gamma[0]],
                                   [0.3 - 0.5 * np.sin(1.4), -np.cos(1.4), -2.0 * np.sin(1.4)], rtol=1e-14)
        assert terms.A.tolist() == [[1.0]]


def test_welded_twin_pendulums_swing_as_one_pendulum_of_both_bodies():
    """Two pendulums hinged about the same ground axis y, the second's joint frame turned by 0.3
    rad about y, welded at a point off the axis (rpy_b undoing the turn): six rows of rank 1
    (DOF 1), and from 0.5 rad at rest they swing as one pendulum carrying both bodies (a fixed
    joint) for 2 s, to 1e-9 rad (projection, DOP853 at rtol 1e-11)."""
    turn = _placement((0.0, 0.0, 0.0), (0.0, 0.3, 0.0))
    body = Inertial(1.5, _placement((0.4, 0.1, -0.2), (0.2, 0.1, 0.3)), np.diag([0.02, 0.05, 0.04]))
    turned = Inertial(1.5, np.linalg.inv(turn) @ body.origin, body.inertia)      # the same body in b's frame
    weld = Closure("weld", "weld", "a", "b", (0.5, 0.0, -0.1), tuple(turn[:3, :3].T @ [0.5, 0.0, -0.1]),
                   rpy_b=(0.0, -0.3, 0.0))
    welded = build_robot("welded", [TreeLink("base"), TreeLink("a", body), TreeLink("b", turned)],
                         [TreeJoint("qa", "revolute", "base", "a", np.eye(4), (0.0, 1.0, 0.0)),
                          TreeJoint("qb", "revolute", "base", "b", turn, (0.0, 1.0, 0.0))], closures=[weld])
    single = build_robot("single", [TreeLink("base"), TreeLink("a", body), TreeLink("copy", body)],
                         [TreeJoint("qa", "revolute", "base", "a", np.eye(4), (0.0, 1.0, 0.0)),
                          TreeJoint("glued", "fixed", "a", "copy", np.eye(4))])
    welded = welded.replace(q0=np.array([0.5, 0.5]))
    np.testing.assert_allclose(welded.constraints(welded.q0), 0.0, atol=1e-15)
    report = cmbs.constraint_report(welded, welded.q0)
    assert (welded.m, report.rank, report.dof) == (6, 1, 1)
    options = dict(t_end=2.0, dt=0.05, integrator="dop853", rtol=1e-11, atol=1e-12)
    run = cmbs.simulate(welded, formulation="projection", compiled=False, **options)
    reference = cmbs.simulate(single.replace(q0=np.array([0.5])), compiled=False, **options)
    assert np.ptp(reference.q[:, 0]) > 0.5
    assert np.abs(run.q - reference.q[:, [0, 0]]).max() < 1e-9         # measured 1.1e-13
