"""Spring-dampers between two points of robots (cmbs.model.robot_loads.PointSpring, robot files'
``[point_springs.NAME]``): the tension f = k (ℓ - ℓ0) + c ℓ̇ pulling the points together.

Against Pinocchio loaded from the same URDF (the UR5 and test_robot.py's branching tree): the
springs' two point forces computed here from Pinocchio's kinematics (the points' positions
``oMf.act(l)`` and velocities from ``getFrameVelocity``, LOCAL_WORLD_ALIGNED) and given to ``aba``
as external forces (test_robot_loads.py's conversion), the accelerations to 1e-10 relative, the
joint reactions equal to ``data.f`` of ``rnea`` with the same forces.  Closed forms: a block on a
horizontal prismatic rail tied to a ground point along the rail oscillates as A cos(√(k/m) t),
damped decays as e^(-c t / 2m), tied by a zero-length spring to a point of its path passes through
ℓ = 0 as (v0/ω) sin ωt; a pendulum's torque from a spring at its tip by hand and its small
oscillations at ω = r √(k/I).  Energy: T + V kept without dampers (V by hand), the loss equal to
∫ Σ c ℓ̇² dt with them.  The default rest length (the distance at the model's start: ``model.q0``
as built, a robot file's assembled start), a mass fault on a sprung robot, the robot files'
entries and every mistake as a one-line error."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import cmbs
from cmbs.control.faults import mass_fault
from cmbs.inverse.robot_reactions import robot_reactions
from cmbs.model.robot import LinkForce, PointSpring, frame_jacobian, frame_placement
from cmbs.model.urdf import load_urdf
from test_robot import ROBOTS, URDFS, _pinocchio_state, _velocity_indices, needs_pinocchio, pinocchio
from test_robot_loads import DOCS, PENDULUM, PENDULUM_INERTIA, _fext, _pinocchio_acceleration, _relative, _robot

#: a 2 kg block on a horizontal rail along x at height 0.5 m (gravity -z does no work on it)
SLIDER = """<?xml version="1.0"?>
<robot name="slider">
  <link name="base"/>
  <link name="block"><inertial><mass value="2"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="rail" type="prismatic"><parent link="base"/><child link="block"/>
    <origin xyz="0 0 0.5"/><axis xyz="1 0 0"/><limit lower="-1" upper="1" effort="10" velocity="5"/></joint>
</robot>
"""
BLOCK_MASS = 2.0

#: per robot: springs (link a, point a, link b, point b, k, c, rest length or None); "ground" is the
#: world, the UR5's "base" and the tree's "pedestal" are fixed to the root with turned placements,
#: the tree's "hand" and "marker" are fixed to movable links, "left" hangs from the prismatic joint
SPRINGS = {
    "ur5": [("forearm_link", (0.05, 0.02, 0.15), "ground", (0.4, 0.3, 0.6), 120.0, 3.0, None),
            ("wrist_3_link", (0.0, 0.08, 0.02), "upper_arm_link", (0.02, 0.0, 0.25), 80.0, 1.5, 0.3),
            ("tool0", (0.01, 0.0, 0.05), "base", (0.2, -0.1, 0.05), 40.0, 0.0, 0.5)],
    "tree": [("hand", (0.03, -0.02, 0.05), "left", (0.1, 0.0, 0.0), 60.0, 2.0, None),
             ("marker", (0.01, 0.0, 0.02), "pedestal", (0.05, 0.05, 0.1), 30.0, 1.0, 0.2),
             ("plate", (0.0, 0.0, 0.05), "ground", (0.3, 0.1, 0.5), 50.0, 0.0, None)],
}


def _point_springs(specs) -> list[PointSpring]:
    return [PointSpring(f"s{i}", link_a, point_a, link_b, point_b, k, c, rest)
            for i, (link_a, point_a, link_b, point_b, k, c, rest) in enumerate(specs)]


def _pinocchio_points(pm, pd, q_pin, v_pin, ends) -> list[tuple[np.ndarray, np.ndarray]]:
    """World position and velocity of each (link, point in the link frame) by Pinocchio (the
    ground's points are world points at rest)."""
    pinocchio.forwardKinematics(pm, pd, q_pin, v_pin)
    pinocchio.updateFramePlacements(pm, pd)
    result = []
    for link, local in ends:
        if link == "ground":
            result.append((np.asarray(local, dtype=float), np.zeros(3)))
            continue
        frame = pm.getFrameId(link)
        placement = pd.oMf[frame]
        point = placement.act(np.asarray(local, dtype=float))
        motion = pinocchio.getFrameVelocity(pm, pd, frame, pinocchio.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        result.append((point, motion.linear + np.cross(motion.angular, point - placement.translation)))
    return result


def _pinocchio_spring_loads(pm, pd, q_pin, v_pin, specs, rests) -> list[tuple]:
    """The springs' point forces (link, world force, point in the link frame, False) for
    test_robot_loads._fext: -f u at a, f u at b, u = (p_a - p_b)/ℓ, f = k (ℓ - ℓ0) + c u·(ṗ_a - ṗ_b);
    none on the ground or on links fixed to it (Pinocchio's universe)."""
    loads = []
    for (link_a, point_a, link_b, point_b, k, c, _), rest in zip(specs, rests):
        (pa, va), (pb, vb) = _pinocchio_points(pm, pd, q_pin, v_pin, [(link_a, point_a), (link_b, point_b)])
        length = np.linalg.norm(pa - pb)
        u = (pa - pb) / length
        tension = k * (length - rest) + c * u @ (va - vb)
        for link, point, force in ((link_a, point_a, -tension * u), (link_b, point_b, tension * u)):
            if link != "ground" and pm.frames[pm.getFrameId(link)].parentJoint > 0:
                loads.append((link, force, point, False))
    return loads


# ------------------------------------------------------------------ against Pinocchio
@needs_pinocchio
@pytest.mark.parametrize("robot", ["ur5", "tree"])
def test_point_springs_are_aba_with_their_two_point_forces(robot, tmp_path):
    """Springs between a link point and a world point, between two links and to a link fixed to
    the ground (the tree's: links fixed to movable ones, a prismatic joint), some given their rest
    length, the others measured at model.q0 (by Pinocchio's positions there to 1e-14 m): at 10
    random (q, q̇, τ), q̈ = aba(q, q̇, τ, fext) with the springs' forces by Pinocchio's kinematics
    to 1e-10 relative (without fext Pinocchio's q̈ differs by more than 1e-6), and the joint
    reactions at (q, q̇, q̈, τ) equal ``data.f`` after rnea(q, q̇, q̈, fext) to 1e-10 of the
    largest; the dampers are the work sources ``damper 'NAME'``."""
    from test_robot_reactions import _pinocchio_joint_forces

    path = _robot(robot, tmp_path)
    specs = SPRINGS[robot]
    model = load_urdf(path, springs=_point_springs(specs))
    assert model.work_sources == tuple(f"damper 's{i}'" for i, spec in enumerate(specs) if spec[5] > 0)
    pm = pinocchio.buildModelFromUrdf(path)
    pd = pm.createData()
    q_start, v_start = _pinocchio_state(model, pm, model.q0, np.zeros(model.n))
    rests = []
    for spec, recorded in zip(specs, model.parameters["springs"]):
        (pa, _), (pb, _) = _pinocchio_points(pm, pd, q_start, v_start, [spec[0:2], spec[2:4]])
        rests.append(np.linalg.norm(pa - pb) if spec[6] is None else spec[6])
        assert recorded["rest_length"] == pytest.approx(rests[-1], abs=1e-14)
    rng = np.random.default_rng(17)
    index = _velocity_indices(model, pm)
    for _ in range(10):
        q, v, tau = rng.uniform(-2.0, 2.0, model.n), rng.normal(0.0, 2.0, model.n), rng.normal(0.0, 10.0, model.n)
        terms = model.evaluate(q, v, 0.0, tau)
        qdd = np.linalg.solve(terms.M, terms.Q)
        q_pin, v_pin = _pinocchio_state(model, pm, q, v)
        fext = _fext(pm, pd, q_pin, _pinocchio_spring_loads(pm, pd, q_pin, v_pin, specs, rests))
        expected = _pinocchio_acceleration(model, pm, pd, q, v, tau, fext)
        assert _relative(qdd, expected) < 1e-10
        assert _relative(_pinocchio_acceleration(model, pm, pd, q, v, tau), expected) > 1e-6

        a_pin = np.zeros(pm.nv)
        a_pin[index] = qdd
        torques, transmitted = _pinocchio_joint_forces(pm, pd, q_pin, v_pin, a_pin, fext)
        np.testing.assert_allclose(torques[index], tau, rtol=0, atol=1e-10 * np.abs(tau).max())
        result = robot_reactions(model, q, v, qdd, np.zeros(0), tau)
        scale = max(np.abs(force).max() for force, _ in transmitted.values())
        for name, (force, moment) in transmitted.items():
            np.testing.assert_allclose(result["forces"][name], force, rtol=0, atol=1e-10 * scale)
            np.testing.assert_allclose(result["moments"][name], moment, rtol=0, atol=1e-10 * scale)


@needs_pinocchio
def test_a_mass_fault_leaves_the_point_springs_once(tmp_path):
    """A sprung UR5 whose forearm is 1.3 times heavier from t0 = 1 s: after t0 its terms are
    those of the sprung UR5 read from the edited URDF (the fault adds the inertia only, not the
    springs a second time), to 1e-12 relative at 5 random states."""
    from test_robot_faults import _heavier_urdf

    springs = _point_springs(SPRINGS["ur5"])
    nominal = load_urdf(ROBOTS / URDFS["ur5"], springs=springs)
    faulty = mass_fault(nominal, "forearm_link", factor=1.3, t0=1.0)
    heavier = load_urdf(_heavier_urdf(tmp_path, "forearm_link", 1.3), springs=springs)
    rng = np.random.default_rng(4)
    for _ in range(5):
        q, qd, u = rng.uniform(-2, 2, 6), rng.normal(size=6), rng.normal(size=6)
        got, expected = faulty.evaluate(q, qd, 1.5, u), heavier.evaluate(q, qd, 1.5, u)
        np.testing.assert_allclose(got.M, expected.M, rtol=0, atol=1e-12 * np.abs(expected.M).max())
        np.testing.assert_allclose(got.Q, expected.Q, rtol=0, atol=1e-12 * np.abs(expected.Q).max())


# ------------------------------------------------------------------ closed forms
@pytest.fixture
def slider(tmp_path: Path) -> Path:
    path = tmp_path / "slider.urdf"
    path.write_text(SLIDER)
    return path


def _run(model: cmbs.Model, q0: float, qd0: float, t_end: float = 3.0) -> cmbs.Trajectory:
    return cmbs.simulate(model, t_end=t_end, dt=0.01, q0=np.array([q0]), qd0=np.array([qd0]), integrator="dop853",
                         rtol=1e-11, atol=1e-13)


def test_a_block_on_a_rail_tied_to_the_ground_oscillates_at_its_natural_frequency(slider):
    """The block's origin (x = q on the rail at height 0.5) tied to the ground point (-0.5, 0,
    0.5) on the rail's line, k = 50 N/m, ℓ0 by default the distance at q0 = 0, 0.5 m: m q̈ =
    -k q, so from 0.2 m at rest q = 0.2 cos(ω t), ω = √(k/m), period 2π√(m/k), over 3 s (2.4
    periods) to 1e-8 m; T + V = ½ k 0.2² + m g 0.5 throughout (V = ½ k (ℓ - ℓ0)² + gravity's)."""
    k = 50.0
    model = load_urdf(slider, springs=[PointSpring("s", "block", (0.0, 0.0, 0.0), "ground", (-0.5, 0.0, 0.5), k)])
    assert model.parameters["springs"][0]["rest_length"] == 0.5 and model.work_sources == ()
    run = _run(model, 0.2, 0.0)
    omega = np.sqrt(k / BLOCK_MASS)
    np.testing.assert_allclose(run.q[:, 0], 0.2 * np.cos(omega * run.t), rtol=0, atol=1e-8)
    gravity = BLOCK_MASS * 9.81 * 0.5
    np.testing.assert_allclose(model.energy_history(run.q, run.qd), 0.5 * k * 0.2**2 + gravity, rtol=1e-9)
    assert model.potential_energy(np.array([0.2])) == pytest.approx(0.5 * k * 0.2**2 + gravity, rel=1e-14)


def test_a_damped_block_decays_as_the_closed_form(slider):
    """k = 50 N/m, c = 0.8 N s/m, the spring compressed (ℓ0 = 0.7 m, ℓ = 0.5 + q): m q̈ = -k (q -
    0.2) - c q̇, so from q = 0 at rest q = 0.2 - 0.2 e^(-σ t) (cos ω_d t + (σ/ω_d) sin ω_d t),
    σ = c/(2m), ω_d = √(k/m - σ²), over 3 s to 1e-8 m."""
    k, c = 50.0, 0.8
    model = load_urdf(slider, springs=[PointSpring("s", "block", (0.0, 0.0, 0.0), "ground", (-0.5, 0.0, 0.5), k,
                                                   damping=c, rest_length=0.7)])
    assert model.work_sources == ("damper 's'",)
    run = _run(model, 0.0, 0.0)
    sigma = c / (2.0 * BLOCK_MASS)
    omega = np.sqrt(k / BLOCK_MASS - sigma**2)
    expected = 0.2 - 0.2 * np.exp(-sigma * run.t) * (np.cos(omega * run.t) + sigma / omega * np.sin(omega * run.t))
    np.testing.assert_allclose(run.q[:, 0], expected, rtol=0, atol=1e-8)
    assert "energy_drift" not in run.info and "note" not in run.info


def test_a_zero_length_spring_passes_through_its_anchor(slider):
    """A spring of rest length 0 from the block's origin to the ground point (0, 0, 0.5) of its
    path, the points coincident at the start (allowed: the rest length is given): its force -k q
    along the rail is linear through ℓ = 0, so from q = 0 at 1 m/s q = (1/ω) sin ω t over 3 s
    (ℓ passes through 0 every half period) to 1e-8 m, no NaN.  With ℓ0 = 0.3 at ℓ = 0 the spring
    exerts no force (no direction) while V = ½ k ℓ0²."""
    k = 50.0
    anchor = (0.0, 0.0, 0.5)
    model = load_urdf(slider, springs=[PointSpring("s", "block", (0.0, 0.0, 0.0), "ground", anchor, k,
                                                   rest_length=0.0)])
    run = _run(model, 0.0, 1.0)
    omega = np.sqrt(k / BLOCK_MASS)
    assert np.all(np.isfinite(run.q)) and np.sum(np.diff(np.sign(run.q[1:, 0])) != 0) >= 4
    np.testing.assert_allclose(run.q[:, 0], np.sin(omega * run.t) / omega, rtol=0, atol=1e-8)

    compressed = load_urdf(slider, springs=[PointSpring("s", "block", (0.0, 0.0, 0.0), "ground", anchor, k,
                                                        damping=1.0, rest_length=0.3)])
    free = load_urdf(slider)
    assert compressed.forces(np.zeros(1), np.array([0.7]), 0.0)[0] == free.forces(np.zeros(1), np.array([0.7]), 0.0)[0]
    assert compressed.potential_energy(np.zeros(1)) == pytest.approx(free.potential_energy(np.zeros(1))
                                                                     + 0.5 * k * 0.3**2, rel=1e-14)
    assert compressed.forces(np.array([1e-200]), np.zeros(1), 0.0)[0] == pytest.approx(k * 0.3, rel=1e-14)


#: the pendulum of test_robot_loads.py (about the vertical axis z through (0, 0, 0.5), its tip
#: 0.6 m along the arm's x axis) with a spring from its tip to the ground point (0.6, -0.4, 0.5)
TIP_RADIUS, ANCHOR = 0.6, np.array([0.6, -0.4, 0.5])


def _tip_spring(k: float, c: float = 0.0) -> PointSpring:
    return PointSpring("s", "tip", (0.0, 0.0, 0.0), "ground", tuple(ANCHOR), k, damping=c)


def _pendulum_torque(q: float, qd: float, k: float, c: float, rest: float) -> float:
    """-f u·∂p/∂q by hand: the tip p = (r cos q, r sin q, 0.5), ∂p/∂q = (-r sin q, r cos q, 0)."""
    tip = np.array([TIP_RADIUS * np.cos(q), TIP_RADIUS * np.sin(q), 0.5])
    lever = np.array([-TIP_RADIUS * np.sin(q), TIP_RADIUS * np.cos(q), 0.0])
    length = np.linalg.norm(tip - ANCHOR)
    u = (tip - ANCHOR) / length
    return -(k * (length - rest) + c * (u @ lever) * qd) * (u @ lever)


def test_a_pendulum_s_tip_spring_gives_the_torque_by_hand(tmp_path):
    """The tip spring-damper (k = 20 N/m, c = 0.7 N s/m, ℓ0 the distance at q0 = 0, 0.4 m): Q at
    six (q, q̇) equals the torque by hand to 1e-13 relative; the URDF's limit lower = 0.4 moves
    q0, and the default rest length with it, to the distance at q = 0.4."""
    path = tmp_path / "pendulum.urdf"
    path.write_text(PENDULUM)
    model = load_urdf(path, gravity=(0.0, 0.0, 0.0), springs=[_tip_spring(20.0, 0.7)])
    assert model.parameters["springs"][0]["rest_length"] == pytest.approx(0.4, abs=1e-15)
    for q, qd in ((0.3, 0.5), (-1.2, -2.0), (2.5, 1.0), (0.0, 3.0), (-0.1, 0.0), (1.6, -0.4)):
        expected = _pendulum_torque(q, qd, 20.0, 0.7, 0.4)
        assert model.forces(np.array([q]), np.array([qd]), 0.0)[0] == pytest.approx(expected, rel=1e-13)
    limited = tmp_path / "limited.urdf"
    limited.write_text(PENDULUM.replace('lower="-3"', 'lower="0.4"'))
    moved = load_urdf(limited, springs=[_tip_spring(20.0)])
    tip = np.array([TIP_RADIUS * np.cos(0.4), TIP_RADIUS * np.sin(0.4), 0.5])
    assert moved.q0[0] == 0.4
    assert moved.parameters["springs"][0]["rest_length"] == pytest.approx(np.linalg.norm(tip - ANCHOR), abs=1e-15)


def test_a_pendulum_on_a_tip_spring_swings_at_the_linearised_frequency(tmp_path):
    """The tip spring (k = 20 N/m, ℓ0 = 0.4 m) perpendicular to the arm at q = 0: ℓ'(0) = r, so
    the linearised torque is -k r² q and small swings go as A cos(ω t), ω = r √(k/I); from
    A = 1e-3 rad over 2 s to 1e-8 rad (the nonlinear terms O(A²)), while the frequency of the
    torsional spring k (no lever) would leave that by far more."""
    path = tmp_path / "pendulum.urdf"
    path.write_text(PENDULUM)
    k, amplitude = 20.0, 1e-3
    model = load_urdf(path, gravity=(0.0, 0.0, 0.0), springs=[_tip_spring(k)])
    run = _run(model, amplitude, 0.0, t_end=2.0)
    omega = TIP_RADIUS * np.sqrt(k / PENDULUM_INERTIA)
    error = np.abs(run.q[:, 0] - amplitude * np.cos(omega * run.t)).max()
    assert error < 1e-8
    assert np.abs(run.q[:, 0] - amplitude * np.cos(np.sqrt(k / PENDULUM_INERTIA) * run.t)).max() > 1e-4


# ------------------------------------------------------------------ energy
UR5_SPRINGS = [("forearm_link", (0.05, 0.02, 0.15), "ground", (0.4, 0.3, 0.6), 150.0, 4.0, 0.4),
               ("wrist_3_link", (0.0, 0.08, 0.02), "upper_arm_link", (0.02, 0.0, 0.25), 90.0, 2.0, 0.3)]


def _ends(model: cmbs.Model, q: np.ndarray, qd: np.ndarray, link: str, point) -> tuple[np.ndarray, np.ndarray]:
    """A point's world position and velocity from the link frame's placement and Jacobian."""
    if link == "ground":
        return np.asarray(point, dtype=float), np.zeros(3)
    rotation, origin = frame_placement(model, q, link)
    position = origin + rotation @ np.asarray(point, dtype=float)
    twist = frame_jacobian(model, q, link) @ qd
    return position, twist[:3] + np.cross(twist[3:], position - origin)


@needs_pinocchio
@pytest.mark.parametrize("damped", [False, True])
def test_ur5_energy_with_point_springs(damped):
    """A UR5 under gravity on a spring to the ground and one between two links, 2 s (DOP853 at
    rtol 1e-10): E = T + V with V the spring-less robot's plus ½ Σ k (ℓ - ℓ0)² by hand (ℓ from
    ``frame_placement``) equals the model's to 1e-12; without dampers it is kept to 1e-8 of the
    largest T and judged by the run; with them the energy lost equals ∫ Σ c ℓ̇² dt (ℓ̇ = u·(ṗ_a -
    ṗ_b) from ``frame_jacobian``, a cubic spline through the outputs) to 1e-7 of it."""
    path = str(ROBOTS / URDFS["ur5"])
    specs = [spec[:5] + ((spec[5] if damped else 0.0),) + spec[6:] for spec in UR5_SPRINGS]
    model = load_urdf(path, springs=_point_springs(specs))
    plain = load_urdf(path)
    run = cmbs.simulate(model, t_end=2.0, dt=0.005, q0=np.array([0.3, -1.0, 1.2, -0.5, 0.8, 0.1]),
                        qd0=np.array([0.5, -0.3, 0.8, 1.0, -0.6, 0.4]), integrator="dop853", rtol=1e-10, atol=1e-12)
    springs_energy, dissipation = np.zeros(run.t.size), np.zeros(run.t.size)
    for i, (q, qd) in enumerate(zip(run.q, run.qd)):
        for link_a, point_a, link_b, point_b, k, c, rest in specs:
            (pa, va), (pb, vb) = _ends(model, q, qd, link_a, point_a), _ends(model, q, qd, link_b, point_b)
            length = np.linalg.norm(pa - pb)
            springs_energy[i] += 0.5 * k * (length - rest)**2
            dissipation[i] += c * ((pa - pb) @ (va - vb) / length)**2
    kinetic = np.array([plain.kinetic_energy(q, qd) for q, qd in zip(run.q, run.qd)])
    energy = kinetic + np.array([plain.potential_energy(q) for q in run.q]) + springs_energy
    np.testing.assert_allclose(model.energy_history(run.q, run.qd), energy, rtol=1e-12, atol=1e-12)
    assert np.ptp(springs_energy) > 0.1 * kinetic.max()
    if not damped:
        assert model.work_sources == ()
        assert np.abs(energy - energy[0]).max() < 1e-8 * kinetic.max()
        assert run.info["energy_drift"] < 1e-8
        return
    from scipy.interpolate import CubicSpline

    assert model.work_sources == ("damper 's0'", "damper 's1'")
    work = CubicSpline(run.t, dissipation).antiderivative()(run.t)
    assert work[-1] > 0.1 * kinetic.max()
    np.testing.assert_allclose(energy[0] - energy, work, rtol=0, atol=1e-7 * work[-1])


# ------------------------------------------------------------------ robot files
DOC_EXAMPLE = DOCS.read_text().split("### Joint springs, dampers, forces and moments")[1].split("```toml\n")[2] \
    .split("```")[0]


@needs_pinocchio
def test_the_documented_point_springs_are_aba_with_their_forces(tmp_path):
    """docs/robots.md's example of ``[point_springs]`` on the UR5: the one given no rest length
    takes the distance at the start (q = 0, by Pinocchio), and q̈ = aba(q, q̇, τ, fext) with the
    springs' forces at 5 random states to 1e-10 relative."""
    path = ROBOTS / URDFS["ur5"]
    robot_file = tmp_path / "ur5-point-springs.toml"
    robot_file.write_text(DOC_EXAMPLE.replace('urdf = "ur5_robot.urdf"', f'urdf = "{path}"'))
    model = cmbs.load(robot_file)
    specs = [(s["link_a"], s["point_a"], s["link_b"], s["point_b"], s["stiffness"], s["damping"], None)
             for s in model.parameters["springs"]]
    assert len(specs) == 2 and model.work_sources == ("damper 'strut'",)
    pm = pinocchio.buildModelFromUrdf(str(path))
    pd = pm.createData()
    (pa, _), (pb, _) = _pinocchio_points(pm, pd, np.zeros(6), np.zeros(6), [specs[1][0:2], specs[1][2:4]])
    rests = [0.25, np.linalg.norm(pa - pb)]
    assert [s["rest_length"] for s in model.parameters["springs"]] == pytest.approx(rests, abs=1e-14)
    rng = np.random.default_rng(6)
    for _ in range(5):
        q, v, tau = rng.uniform(-2.0, 2.0, 6), rng.normal(0.0, 2.0, 6), rng.normal(0.0, 10.0, 6)
        terms = model.evaluate(q, v, 0.0, tau)
        fext = _fext(pm, pd, q, _pinocchio_spring_loads(pm, pd, q, v, specs, rests))
        assert _relative(np.linalg.solve(terms.M, terms.Q), pinocchio.aba(pm, pd, q, v, tau, fext)) < 1e-10


ROBOT_FILE = """[model]
urdf = "pendulum.urdf"
gravity = [0.0, 0.0, 0.0]

[point_springs.s]
link_a = "tip"
point_a = [0.0, 0.0, 0.0]
link_b = "ground"
point_b = [0.6, -0.4, 0.5]
stiffness = 20.0
damping = 0.7
"""


@pytest.fixture
def pendulum_folder(tmp_path: Path) -> Path:
    (tmp_path / "pendulum.urdf").write_text(PENDULUM)
    return tmp_path


def _load(folder: Path, text: str) -> cmbs.Model:
    robot_file = folder / "pendulum.toml"
    robot_file.write_text(text)
    return cmbs.load(robot_file)


def test_a_robot_file_s_point_spring_rests_at_its_assembled_start(pendulum_folder):
    """The default rest length of a robot file's spring is the distance at the file's start: the
    URDF's q0 (0.4 m at q = 0) without ``[initial_positions]``, the joint value given there (q =
    0.3), the assembled one when a driver holds the joint at 0.7 (from the guess 0.3): each time
    V(q0) = 0 and Q the torque by hand; a given ``rest_length`` is kept.  Points that coincide at
    the URDF's q0 but not at the file's start are not refused (refused from Python, where the
    start is the URDF's q0)."""
    def tip_distance(q: float) -> float:
        return float(np.linalg.norm([TIP_RADIUS * np.cos(q), TIP_RADIUS * np.sin(q), 0.5] - ANCHOR))

    cases = [("", 0.0, 0.4), ("\n[initial_positions]\nhinge = 0.3\n", 0.3, tip_distance(0.3)),
             ('\n[initial_positions]\nhinge = 0.3\n\n[drivers.hold]\ncoordinate = "hinge"\nexpression = "0.7"\n',
              0.7, tip_distance(0.7)),
             ("rest_length = 0.55\n\n[initial_positions]\nhinge = 0.3\n", 0.3, 0.55)]
    apart_at_start = ROBOT_FILE.replace("point_b = [0.6, -0.4, 0.5]", "point_b = [0.6, 0.0, 0.5]")
    with pytest.raises(cmbs.ModelError, match="coincide at the start q0"):
        load_urdf(pendulum_folder / "pendulum.urdf", springs=[PointSpring("s", "tip", (0.0, 0.0, 0.0), "ground",
                                                                          (0.6, 0.0, 0.5), 20.0)])
    model = _load(pendulum_folder, apart_at_start + "\n[initial_positions]\nhinge = 0.3\n")
    assert model.parameters["springs"][0]["rest_length"] == pytest.approx(2 * TIP_RADIUS * np.sin(0.15), abs=1e-14)
    for extra, start, rest in cases:
        model = _load(pendulum_folder, ROBOT_FILE + extra)
        assert model.q0[0] == pytest.approx(start, abs=1e-12)
        assert model.parameters["springs"][0]["rest_length"] == pytest.approx(rest, abs=1e-14)
        assert "damper 's'" in model.work_sources
        if "rest_length" not in extra:
            assert model.potential_energy(model.q0) == pytest.approx(0.0, abs=1e-28)
        q, qd = np.array([1.1]), np.array([-0.6])
        terms = model.evaluate(q, qd, 0.0)
        assert terms.Q[0] == pytest.approx(_pendulum_torque(1.1, -0.6, 20.0, 0.7, rest), rel=1e-13)


@pytest.mark.parametrize("replace, replacement, expected", [
    ('link_a = "tip"', 'link_a = "tpi"', "point_springs.s: link_a: unknown link 'tpi' (did you mean 'tip'?); links: "
                                         "ground, base, arm, tip"),
    ('link_b = "ground"', 'link_b = "grund"', "point_springs.s: link_b: unknown link 'grund' (did you mean 'ground'?)"),
    ('link_a = "tip"', 'link_a = "base"', "point_springs.s: both ends are on the ground (the world, the root link or "
                                          "links fixed to it): the spring would act on nothing"),
    ('link_b = "ground"', 'link_b = "arm"', "point_springs.s: link_a 'tip' and link_b 'arm' are one rigid body: the "
                                            "spring's two forces on it cancel"),
    ("stiffness = 20.0", "stiffness = -20.0", "point_springs.s: stiffness must be a finite number >= 0, got -20.0"),
    ("stiffness = 20.0", "stiffness = inf", "point_springs.s: stiffness must be a finite number >= 0, got inf"),
    ("damping = 0.7", "damping = -0.7", "point_springs.s: damping must be a finite number >= 0, got -0.7"),
    ("damping = 0.7", "damping = 0.7\nrest_length = -0.1",
     "point_springs.s: rest_length must be a finite number >= 0, got -0.1"),
    ("stiffness = 20.0\ndamping = 0.7", "stiffness = 0.0", "point_springs.s: stiffness and damping are both 0"),
    ("stiffness = 20.0", 'stiffness = "stiff"', "point_springs.s: stiffness must be a number, got 'stiff'"),
    ("point_a = [0.0, 0.0, 0.0]", "point_a = [0.0, 0.0]",
     "point_springs.s: point_a must be a list of 3 finite numbers, got [0.0, 0.0]"),
    ("point_b = [0.6, -0.4, 0.5]", 'point_b = [0.6, "y", 0.5]',
     "point_springs.s: point_b must be a list of 3 finite numbers, got [0.6, 'y', 0.5]"),
    ('link_a = "tip"', "link_a = 3", "point_springs.s: link_a must be a string (a name), got 3"),
    ("stiffness = 20.0", "stifness = 20.0", "point_springs.s: unknown key(s) 'stifness' (did you mean 'stiffness'?)"),
    ('link_b = "ground"\n', "", "point_springs.s: missing key(s) 'link_b'"),
    ("stiffness = 20.0\n", "", "point_springs.s: missing key(s) 'stiffness'"),
    ("point_b = [0.6, -0.4, 0.5]", "point_b = [0.6, 0.0, 0.5]",
     "point_springs.s: point_a and point_b coincide at the start q0: the spring has no direction there and no rest "
     "length to take from it; move a point or give rest_length"),
    ("[point_springs.s]", '[springs.s]\njoint = "hinge"\nstiffness = 1.0\n\n[point_springs.s]',
     "point_springs.s: duplicate spring name (joint and point springs share one namespace)"),
    ("[point_springs.s]", "[point_springs]\nt = 3\n\n[point_springs.s]",
     "point_springs.t: expected a table of keys, got 3"),
])
def test_robot_file_point_spring_mistakes_are_one_line_errors(pendulum_folder, replace, replacement, expected):
    """Each mistake in a ``[point_springs.NAME]`` entry: one line naming the file, the entry and
    the field; points that coincide at the file's start with no rest length given are refused."""
    assert ROBOT_FILE.count(replace) == 1
    with pytest.raises(cmbs.ModelError) as error:
        _load(pendulum_folder, ROBOT_FILE.replace(replace, replacement))
    message = str(error.value)
    assert "\n" not in message and message.startswith(str(pendulum_folder / "pendulum.toml"))
    assert expected in message


def test_python_point_spring_mistakes_name_the_spring(pendulum_folder):
    """The same checks from Python (``load_urdf(..., springs=[...])``): a point that is not 3
    finite numbers, a repeated name, an element that is no spring, points coinciding at model.q0
    with no rest length (with one given, the spring is built)."""
    path = pendulum_folder / "pendulum.urdf"

    def error(*springs) -> str:
        with pytest.raises(cmbs.ModelError) as raised:
            load_urdf(path, springs=springs)
        return str(raised.value)

    spring = _tip_spring(20.0)
    assert "point spring 's': point_a must be 3 finite numbers, got (0.0, nan, 0.0)" in error(
        PointSpring("s", "tip", (0.0, np.nan, 0.0), "ground", (0.0, 0.0, 0.0), 1.0))
    assert "point spring 's': duplicate spring name" in error(spring, spring)
    assert "a spring is a JointSpring or a PointSpring, got LinkForce" in error(LinkForce("f", "tip", (1, 0, 0)))
    coincident = PointSpring("s", "tip", (0.0, 0.0, 0.0), "ground", (0.6, 0.0, 0.5), 20.0)
    assert "point spring 's': point_a and point_b coincide at the start q0" in error(coincident)
    given = load_urdf(path, gravity=(0.0, 0.0, 0.0), springs=[dataclasses.replace(coincident, rest_length=0.1)])
    assert given.potential_energy(given.q0) == pytest.approx(0.5 * 20.0 * 0.1**2, rel=1e-14)
